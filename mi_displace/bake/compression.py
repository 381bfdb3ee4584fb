"""Compression (§1.1, Fig. 21): low-poly + compressed map against the compressed original.

Meshes are measured as raw binary buffers (float32 positions [+ float32 UVs], uint32 faces)
compressed with LZMA at its strongest preset (the paper used RAR "Best"; both are general
lossless compressors).  Maps are measured in the codec's own file:

* ``png16`` — the 16-bit displacement PNG (deflate, lossless up to the 16-bit quantisation);
* ``exr_zip`` — float32 displacement in a ZIP-compressed OpenEXR (lossless);
* ``jpeg2k`` — the 16-bit quantised displacement in JPEG 2000 (wavelet, imagecodecs/OpenJPEG)
  at ``jpeg2k_level`` (PSNR-style quality target; lossy — the paper recommends wavelets
  for their smooth, blur-like artefacts).

The validity mask (PNG, 1 bit of information per texel) is counted with every map.
"""
from __future__ import annotations

import lzma
import tempfile
from pathlib import Path

import numpy as np

from mi_displace.bake import formats
from mi_displace.bake.meshdata import MeshData


def mesh_bytes(mesh: MeshData, with_uvs: bool) -> int:
    """LZMA-compressed size of the mesh's binary buffers [bytes]."""
    parts = [mesh.positions.astype(np.float32).tobytes()]
    if with_uvs and mesh.uvs is not None:
        parts.append(mesh.uvs.astype(np.float32).tobytes())
    parts.append(mesh.faces.astype(np.uint32).tobytes())
    return len(lzma.compress(b"".join(parts), preset=9 | lzma.PRESET_EXTREME))


def encode_map(displacement: np.ndarray, codec: str, jpeg2k_level: float = 60.0) -> tuple[int, np.ndarray]:
    """Compress a displacement map; returns (bytes, the decoded map [object units])."""
    d = displacement.astype(np.float32)
    lo, hi = float(d.min()), float(d.max())
    scale = (hi - lo) / 65535 if hi > lo else 1.0
    q = np.clip(np.round((d - lo) / scale), 0, 65535).astype(np.uint16)
    if codec == "png16":
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "d.png"
            formats.write_png_raw(path, q)
            size = path.stat().st_size
            back = formats.read_png_raw(path)[..., 0]
        return size, (lo + scale * back.astype(np.float64)).astype(np.float32)
    if codec == "exr_zip":
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "d.exr"
            formats.write_exr_channels(path, {"D": d})
            return path.stat().st_size, formats.read_exr_channels(path)["D"]
    if codec == "jpeg2k":
        import imagecodecs

        data = imagecodecs.jpeg2k_encode(q, level=jpeg2k_level)
        back = imagecodecs.jpeg2k_decode(data)
        return len(data), (lo + scale * back.astype(np.float64)).astype(np.float32)
    raise ValueError(f"codec: unknown {codec!r}; choose png16, exr_zip or jpeg2k")


def mask_bytes(valid: np.ndarray) -> int:
    """Size of the validity mask as a PNG [bytes]."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "v.png"
        formats.write_png_raw(path, (valid > 0.5).astype(np.uint8) * 255)
        return path.stat().st_size
