"""The code version that on-disk caches are keyed by.

A cache entry computed by older code must never be trusted after an upgrade or a local
edit, so caches key their entries by :func:`code_version`: a digest of the package version,
the Mitsuba and Dr.Jit versions, the variant and the *source text* of every Python module of
``mi_displace`` and its plugins.  Any edit of any module changes it (coarse, but never
stale).
"""
from __future__ import annotations

import hashlib
from functools import lru_cache
from pathlib import Path

_PACKAGE_DIR = Path(__file__).resolve().parents[1]


def _source_files() -> list[Path]:
    """Every ``.py`` file of the ``mi_displace`` package and of ``mi_displace.plugins``."""
    import mi_displace.plugins as plugins

    roots = {_PACKAGE_DIR, Path(plugins.__file__).resolve().parent}
    return sorted({p for root in roots for p in root.rglob("*.py")})


@lru_cache(maxsize=None)
def _source_digest() -> str:
    h = hashlib.sha256()
    for path in _source_files():
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def code_version() -> str:
    """A 16-hex-digit digest of everything that decides what our code computes.

    Returns:
        ``sha256(mi_displace version, mitsuba version, drjit version, variant, sources)``,
        truncated; stable within a process and across processes running the same code.
    """
    import drjit as dr
    import mitsuba as mi

    import mi_displace

    h = hashlib.sha256()
    for part in (mi_displace.__version__, mi.__version__, dr.__version__, str(mi.variant()),
                 _source_digest()):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:16]
