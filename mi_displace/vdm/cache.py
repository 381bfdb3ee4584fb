"""On-disk cache of built VDM tables, keyed by everything that determines them.

Folder: ``$MI_DISPLACE_CACHE/vdm`` if set, else ``~/.cache/mi_displace/vdm``.  The key is
a SHA-256 over the height grid's bytes, the depth, the grid sizes, the curvature samples,
:data:`FORMAT_VERSION` and :func:`code_version` (a digest of the source of every module
that builds a table, so a fix to the builder never reads tables built before it); each
entry is one ``.npz``.  A corrupt or unreadable entry is
rebuilt (never trusted).
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

FORMAT_VERSION = 5
#: The modules whose code determines a table's contents (:func:`code_version`).
BUILDER_MODULES = ("table.py", "curvature.py", "mvm.py", "compression.py", "build.py")


def code_version(files=None) -> str:
    """Hex digest of the source of the table builder (``files``: paths, default the
    :data:`BUILDER_MODULES` beside this file)."""
    folder = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in files or [folder / name for name in BUILDER_MODULES]:
        h.update(Path(path).read_bytes())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """The cache folder (created on first write)."""
    root = os.environ.get("MI_DISPLACE_CACHE")
    base = Path(root) if root else Path.home() / ".cache" / "mi_displace"
    return base / "vdm"


def key(heights: np.ndarray, **params) -> str:
    """Hex digest over the height grid and the JSON of ``params`` (floats rounded to 1e-9)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(heights, np.float32).tobytes())
    h.update(str(heights.shape).encode())

    def norm(v):
        if isinstance(v, (np.ndarray, list, tuple)):
            return [norm(x) for x in np.asarray(v).ravel().tolist()]
        if isinstance(v, float):
            return round(v, 9)
        return v

    h.update(json.dumps({k: norm(v) for k, v in sorted(params.items())}).encode())
    h.update(str(FORMAT_VERSION).encode())
    h.update(code_version().encode())
    return h.hexdigest()[:32]


def load(digest: str) -> dict | None:
    """The arrays stored under ``digest``, or None (missing or unreadable)."""
    path = cache_dir() / f"{digest}.npz"
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except Exception:  # a truncated/corrupt file: rebuild
        return None


def save(digest: str, arrays: dict) -> Path | None:
    """Write atomically (temp file + rename); returns the path, or None if not writable."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        path = folder / f"{digest}.npz"
        os.replace(tmp, path)
        return path
    except OSError:
        return None
