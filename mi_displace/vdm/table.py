"""The zero-curvature VDM: ray casting the flat mesostructure (paper §3.1, Fig. 2).

Texture-tile units
------------------
Everything here is measured in *tile units*: one period of the height texture is the unit
square ``T in [0, 1)^2``; the mesostructure lies *below* the reference surface (z = 0) at
``z(T) = -D (1 - H(T))`` with ``H`` in ``[0, 1]`` (H = 1 touches the reference surface) and
``D = depth / tile_size`` (world depth over the world size of one tile, NOTES "Units").

Sampling grids (shared by the whole package)
--------------------------------------------
* texels: ``res x res`` centres ``T = ((i + 0.5) / res, (j + 0.5) / res)``;
* view azimuth ``phi_k = 2 pi k / n_phi`` measured from the texture's x (u) axis;
* view polar angle, centred: ``theta_m = (m + 0.5) / n_theta * pi / 2`` (no sample at the
  degenerate grazing 90 deg; this maps one to one onto texture coordinates).

The flat table stores, per (texel, phi, theta), the distance ``t`` along the viewing ray
``-V`` from the reference point ``P = (T, 0)`` to the first mesostructure hit ``P'``; then
``l = t sin(theta)`` (tangential, texture space) and ``h = t cos(theta)`` (depth of P').
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

#: Horizontal travel (tile units) after which a flat ray is declared a miss; a ray at a
#: centred theta grid angle below 90 deg reaches the floor z = -D long before.
MAX_WRAPS = 4096
#: Sub-texel offset of the ray origins (texels), see :func:`flat_distances`.
NUDGE = (0.0123, 0.0371)


def theta_grid(n_theta: int) -> np.ndarray:
    """Centred view polar angles [rad], shape (n_theta,)."""
    return (np.arange(n_theta) + 0.5) / n_theta * (math.pi / 2)


def phi_grid(n_phi: int) -> np.ndarray:
    """View azimuths [rad] from the texture u axis, shape (n_phi,)."""
    return np.arange(n_phi) * (2 * math.pi / n_phi)


HEIGHT_TOLERANCE = 1e-3   # filtering may overshoot [0, 1] by this much (then clipped)


def check_heights(heights: np.ndarray, name: str = "height", plugin: str = "vdm") -> np.ndarray:
    """A finite float32 (res_y, res_x) height grid in [0, 1], else ValueError naming ``plugin``
    (values within :data:`HEIGHT_TOLERANCE` outside are clipped: filtering overshoot)."""
    heights = np.asarray(heights, dtype=np.float32)
    if heights.ndim != 2 or min(heights.shape) < 1:
        raise ValueError(f"{plugin}: '{name}' grid must be a non-empty 2-D array, "
                         f"got shape {heights.shape}")
    bad = ~np.isfinite(heights)
    if bad.any():
        raise ValueError(f"{plugin}: '{name}' holds {int(bad.sum())} NaN/Inf height value(s); "
                         "clean the height map first")
    lo, hi = float(heights.min()), float(heights.max())
    if lo < -HEIGHT_TOLERANCE or hi > 1 + HEIGHT_TOLERANCE:
        raise ValueError(f"{plugin}: '{name}' values must lie in [0, 1] (1 = the reference surface), "
                         f"got {lo:.4g}..{hi:.4g}; rescale the height map (or use 'depth')")
    return np.clip(heights, 0.0, 1.0)


def sample_heights(texture: mi.Texture, res: int, tiling=(1.0, 1.0),
                   plugin: str = "vdm") -> np.ndarray:
    """Heights H at the texel centres of one tile, shape (res, res) float32 (row = y).

    The texture is evaluated at ``uv = T / tiling`` (its own ``to_uv`` applies), so one tile
    is one period of the texture as it appears on the surface.  Errors name ``plugin``.
    """
    i = dr.arange(mi.UInt32, res * res)
    tu, tv = (mi.Float(i % res) + 0.5) / res, (mi.Float(i // res) + 0.5) / res
    si = dr.zeros(mi.SurfaceInteraction3f, res * res)
    si.uv = mi.Point2f(tu / float(tiling[0]), tv / float(tiling[1]))
    h = np.asarray(texture.eval_1(si), dtype=np.float32).reshape(res, res)
    return check_heights(h, plugin=plugin)


#: Wrap-around / interior difference ratio above which a tile is not one period.
PERIODIC_RATIO = 4.0


def periodicity_warning(heights: np.ndarray, plugin: str, tiling) -> str | None:
    """A warning (or None) when ``heights`` (one tile) is not periodic.

    Compares the mean absolute difference across the tile's wrap-around edges with the mean
    difference between interior neighbours (both directions): a ratio above
    :data:`PERIODIC_RATIO` means one tile is not one period of the texture — typically the
    texture's ``to_uv`` scale and ``tiling_u``/``tiling_v`` disagree, so the table holds a
    fraction (or several periods) of the pattern the surface shows.
    """
    h = np.asarray(heights, np.float64)
    if min(h.shape) < 4:
        return None
    ratios = []
    for axis in (0, 1):
        inner = np.abs(np.diff(h, axis=axis)).mean()
        wrap = np.abs(np.take(h, 0, axis) - np.take(h, -1, axis)).mean()
        if wrap > 1e-6:
            ratios.append(wrap / max(inner, 1e-12))
    worst = max(ratios, default=0.0)
    if worst <= PERIODIC_RATIO:
        return None
    return (f"{plugin}: the height texture is not periodic over one tile (edge jump "
            f"{worst:.1f}x the neighbour difference): one tile must be one period of the "
            f"texture as it appears on the surface; check its to_uv scale against "
            f"tiling_u/tiling_v = {tiling[0]:g}/{tiling[1]:g}")


def heightfield_mesh(heights: np.ndarray, D: float) -> mi.Mesh:
    """The zero-curvature mesostructure of one tile as a Mitsuba mesh (tile units).

    Vertices sit at the texel centres, ``(res + 1)^2`` of them covering
    ``[0.5 / res, 1 + 0.5 / res]^2`` (heights wrap periodically), two triangles per cell.
    """
    ry, rx = heights.shape
    jj, ii = np.meshgrid(np.arange(ry + 1), np.arange(rx + 1), indexing="ij")
    z = -D * (1.0 - heights[jj % ry, ii % rx])
    pos = np.stack([(ii + 0.5) / rx, (jj + 0.5) / ry, z], -1).reshape(-1, 3).astype(np.float32)
    a = (jj[:-1, :-1] * (rx + 1) + ii[:-1, :-1]).ravel()
    b, c, d = a + 1, a + rx + 2, a + rx + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.uint32)
    mesh = mi.Mesh("vdm_mesostructure", len(pos), len(faces), has_vertex_normals=False,
                   has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(pos.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    params.update()
    return mesh


def flat_distances(heights: np.ndarray, D: float, n_theta: int, n_phi: int) -> np.ndarray:
    """Ray-cast zero-curvature VDM distances t [tile units] (§3.1).

    For each texel centre P, azimuth phi_k and polar angle theta_m, the ray from P along
    ``-V = -(sin t cos p, sin t sin p, cos t)`` is traced through the periodic height field
    (the tile mesh, with the ray wrapped back into the tile whenever it leaves it).

    Args:
        heights: (res_y, res_x) in [0, 1].
        D: depth in tile units (>= 0).

    Returns:
        float32 array (n_phi, res_y, res_x, n_theta) of distances t >= 0; ``-1`` marks a
        miss (only possible through numerical leaks; counted by the caller).
    """
    ry, rx = heights.shape
    if D == 0.0:
        return np.zeros((n_phi, ry, rx, n_theta), np.float32)
    scene = mi.load_dict({"type": "scene", "meso": heightfield_mesh(heights, D)})
    n = n_phi * ry * rx * n_theta
    idx = dr.arange(mi.UInt32, n)
    m = idx % n_theta
    x = (idx // n_theta) % rx
    y = (idx // (n_theta * rx)) % ry
    k = idx // (n_theta * rx * ry)
    theta = (mi.Float(m) + 0.5) * (math.pi / 2 / n_theta)
    phi = mi.Float(k) * (2 * math.pi / n_phi)
    st, ct = dr.sincos(theta)
    sp, cp = dr.sincos(phi)
    d = mi.Vector3f(-st * cp, -st * sp, -ct)
    lo = mi.Point2f(0.5 / rx, 0.5 / ry)
    # Origins nudged off the vertex rows, columns and diagonals of the mesh (a ray running
    # exactly along an edge can slip between its two triangles); 4e-2 texel at most.
    o = mi.Point3f((mi.Float(x) + 0.5 + NUDGE[0]) / rx, (mi.Float(y) + 0.5 + NUDGE[1]) / ry, 0.0)

    def exit_distances(o: mi.Point3f):
        tx = dr.select(d.x > 0, (lo.x + 1 - o.x) / d.x,
                       dr.select(d.x < 0, (lo.x - o.x) / d.x, dr.inf))
        ty = dr.select(d.y > 0, (lo.y + 1 - o.y) / d.y,
                       dr.select(d.y < 0, (lo.y - o.y) / d.y, dr.inf))
        # below the floor nothing remains: stop there too
        tz = (D * 1.001 + o.z) / -d.z
        return dr.maximum(tx, 0.0), dr.maximum(ty, 0.0), dr.maximum(tz, 0.0)

    def cond(o, t_total, t_hit, wraps, going):
        return going

    def body(o, t_total, t_hit, wraps, going):
        tx, ty, tz = exit_distances(o)
        t_exit = dr.minimum(dr.minimum(tx, ty), tz)
        ray = mi.Ray3f(o, d, t_exit * 1.0001 + 1e-6)
        si = scene.ray_intersect_preliminary(ray, going)
        hit = going & si.is_valid()
        t_hit = dr.select(hit, t_total + si.t, t_hit)
        moved = o + d * t_exit
        # wrap back into the tile through the side it left (periodic height field)
        x = dr.select(tx <= t_exit, dr.select(d.x > 0, lo.x, lo.x + 1), moved.x)
        y = dr.select(ty <= t_exit, dr.select(d.y > 0, lo.y, lo.y + 1), moved.y)
        step = going & ~hit
        o = dr.select(step, mi.Point3f(x, y, moved.z), o)
        t_total = dr.select(step, t_total + t_exit, t_total)
        wraps += 1
        going = step & (wraps < MAX_WRAPS) & (tz > t_exit)
        return o, t_total, t_hit, wraps, going

    _, _, t_hit, _, _ = dr.while_loop(
        state=(o, mi.Float(0.0), mi.Float(-1.0), mi.UInt32(0), dr.full(mi.Bool, True, n)),
        cond=cond, body=body, labels=("o", "t_total", "t_hit", "wraps", "going"),
        label="vdm_flat_cast")
    return np.asarray(t_hit, dtype=np.float32).reshape(n_phi, ry, rx, n_theta)
