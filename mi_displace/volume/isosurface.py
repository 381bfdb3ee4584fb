"""The surface reference: the iso-surface of the *exactly* displaced field as a triangle mesh.

The paper shades volumes as surfaces, so the normal methods of §4.3 are judged against the
geometry they approximate: the field f(p') = τ(O(G(p'))) · [α(p') = 1] with the procedural
maps (reference mode, whatever the volume's own mode), sampled on a grid over the proxy box
and triangulated by marching cubes (scikit-image) at the level ``iso``.
"""
from __future__ import annotations

import numpy as np
import mitsuba as mi

from mi_displace.volume.field import DisplacedVolume

MAX_NODES = 400 ** 3


def exact_field(vol: DisplacedVolume, res: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f on ``res`` nodes along the longest side of the proxy box: (field (nz, ny, nx), lo, spacing)."""
    lo, hi = vol.proxy_box()
    h = float((hi - lo).max()) / (res - 1)
    n = np.maximum(np.ceil((hi - lo) / h).astype(int) + 1, 2)
    if int(np.prod(n)) > MAX_NODES:
        raise ValueError(f"iso-surface resolution {res}: {n} nodes, more than {MAX_NODES:,}")
    axes = [lo[i] + h * np.arange(n[i]) for i in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    p = mi.Point3f(mi.Float(x.ravel()), mi.Float(y.ravel()), mi.Float(z.ravel()))
    r = vol.chain.exact(p)
    f = np.where(np.array(r.alpha) >= 0.5, np.array(vol.transfer(vol.obj.density(r.p))), 0.0)
    return f.reshape(n[2], n[1], n[0]).astype(np.float32), lo, np.full(3, h)


def isosurface(vol: DisplacedVolume, iso: float = 0.5, res: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Marching-cubes mesh of the exactly displaced field: (vertices (V, 3) world, faces (F, 3))."""
    from skimage.measure import marching_cubes

    if not 0 < iso < 1:
        raise ValueError(f"iso: must lie in (0, 1), got {iso}")
    if not isinstance(res, (int, np.integer)) or res < 8:
        raise ValueError(f"iso-surface resolution: must be an integer >= 8, got {res!r}")
    f, lo, h = exact_field(vol, int(res))
    if not (f.max() > iso > f.min()):
        raise ValueError(f"iso {iso}: the displaced field never crosses it (range {f.min()}..{f.max()})")
    # pad with empty space so that the surface is closed where matter touches the grid's faces
    f = np.pad(f, 1)
    verts, faces, _, _ = marching_cubes(f, level=iso, spacing=(h[2], h[1], h[0]))
    verts = verts[:, ::-1] - h + lo                   # (z, y, x) -> (x, y, z), undo the pad
    # swapping the axes to (x, y, z) mirrors the winding: faces now turn outwards (to low f)
    return verts.astype(np.float32), faces.astype(np.uint32)
