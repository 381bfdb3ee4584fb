"""``map_resolution="auto"`` from the base's screen footprint (issue: model only what a
scene requires).

The pair (P, N) of geometry images is a uniform tessellation of S (§3.1): texel edges are
the micro-edges of the mapped surface.  Cycles dices a displaced surface so that a
micro-edge spans ``dicing_rate`` pixels; we choose the map resolution the same way: R
such that, over 99 % of the uv area of the base that some sensor sees, one texel step
along u or along v (S_u / (R - 1), S_v / (R - 1), projected to first order) spans at most
``dicing_rate`` pixels — rounded up to a power of two.  The rule reads only the exact
base (positions and derivatives), never a map lookup, so it holds on mesh bases whose
lookups straddle UV charts.  What no sensor sees needs nothing; a base entirely off
screen gets the coarsest resolution.
"""
from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

from mi_displace.ddm.base_maps import AUTO_MAX_RESOLUTION, texel_coordinates

#: coarsest resolution ``auto`` picks (a base off screen, or tiny on it)
AUTO_MIN_RESOLUTION = 8
#: frustum margin: points just outside the view still count (tiles reach over the edge)
MARGIN = 1.1
#: share of the visible uv area (texels) whose steps must meet the dicing rate
QUANTILE = 0.99


def _matrix(transform) -> np.ndarray:
    return np.array(transform.matrix, np.float64).reshape(4, 4)


def base_samples(base, n: int = 65):
    """Points of the base with their derivatives (object space) and the share of the uv
    domain (of the texels) each stands for: ``(p, S_u, S_v, weight)`` — face centroids,
    per-face gradients and UV areas of a mesh base, an n x n uv grid (equal weights) else."""
    from mi_displace.ddm.mesh_base import MeshBase

    if isinstance(base, MeshBase):
        p = base.positions_np[base.faces_np].mean(1)
        t = base.uvs_np[base.faces_np]
        e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        return p, *base.gradients_np, area
    u, v = texel_coordinates(n, n, False, False)
    s = base.sample(u, v)
    p, du, dv = (np.stack([np.broadcast_to(np.asarray(c, np.float64), (n * n,)) for c in x], 1)
                 for x in (s.p, s.dp_du, s.dp_dv))     # (literal components broadcast)
    return p, du, dv, np.ones(n * n)


def pixels_per_uv(sensor, points, du, dv):
    """Pixels spanned by a unit step in u and in v at each world point (first order), and
    whether the sensor sees the point (in front, inside the frustum with :data:`MARGIN`).

    Args:
        sensor: a Mitsuba ``perspective``, ``thinlens`` or ``orthographic`` sensor.
        points, du, dv: (N, 3) world positions and derivatives.

    Returns:
        ``(pixels (N,), visible (N,) bool)``.
    """
    params = mi.traverse(sensor)
    if sensor.class_name() not in ("PerspectiveCamera", "OrthographicCamera", "ThinLensCamera"):
        raise ValueError(f"ddm: map_resolution 'auto' reads perspective, thin-lens or "
                         f"orthographic sensors, not {sensor.class_name()}")
    width, height = (int(x) for x in sensor.film().size())
    inv = np.linalg.inv(_matrix(sensor.world_transform()))
    q = points @ inv[:3, :3].T + inv[:3, 3]
    a, b = du @ inv[:3, :3].T, dv @ inv[:3, :3].T
    z = q[:, 2]
    near = float(np.ravel(params["near_clip"])[0])
    aspect = height / width
    if "x_fov" in params.keys():
        t = math.tan(math.radians(float(np.ravel(params["x_fov"])[0])) / 2)
        zs = np.maximum(z, 1e-30)
        visible = (z > near) & (np.abs(q[:, 0]) <= MARGIN * t * zs) & \
            (np.abs(q[:, 1]) <= MARGIN * t * aspect * zs)

        def project(d):   # d/ds of the pixel position (x/z, y/z) * width / (2 t)
            return width / (2 * t) * np.hypot(d[:, 0] * zs - q[:, 0] * d[:, 2],
                                               d[:, 1] * zs - q[:, 1] * d[:, 2]) / zs ** 2
    else:   # orthographic: camera space [-1, 1] across the film width
        visible = (z > near) & (np.abs(q[:, 0]) <= MARGIN) & (np.abs(q[:, 1]) <= MARGIN * aspect)

        def project(d):
            return width / 2 * np.hypot(d[:, 0], d[:, 1])
    return np.maximum(project(a), project(b)), visible


def _weighted_quantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    order = np.argsort(x)
    c = np.cumsum(w[order])
    if c[-1] <= 0:
        return float(x.max())
    return float(x[order][min(np.searchsorted(c, q * c[-1]), len(x) - 1)])


def resolution(base, sensors, to_world, dicing_rate: float = 1.0) -> tuple[int, dict]:
    """The power-of-two map resolution at which the visible texel steps stay within
    ``dicing_rate`` pixels in every sensor (the finest need), in
    [:data:`AUTO_MIN_RESOLUTION`, ``AUTO_MAX_RESOLUTION``].  "Visible texel steps": those
    of :data:`QUANTILE` of the visible uv area — a sliver triangle of a mesh's UV layout
    (near-zero UV area, so a huge S_u) holds almost no texels and must not decide R.

    Returns:
        ``(resolution, info)``; info: ``footprint_px_per_uv`` (pixels per unit uv at that
        quantile, the largest over the sensors), ``footprint_visible`` (fraction of the
        samples some sensor sees).
    """
    if not sensors:
        raise ValueError("ddm: map_resolution 'auto' from the screen footprint needs a sensor")
    p, du, dv, weight = base_samples(base)
    m = _matrix(to_world)
    pw, duw, dvw = p @ m[:3, :3].T + m[:3, 3], du @ m[:3, :3].T, dv @ m[:3, :3].T
    need, seen = 0.0, np.zeros(len(p), bool)
    for sensor in sensors:
        px, visible = pixels_per_uv(sensor, pw, duw, dvw)
        if visible.any():
            need = max(need, _weighted_quantile(px[visible], weight[visible], QUANTILE))
        seen |= visible
    r = 2 ** math.ceil(math.log2(max(1.0 + need / dicing_rate, 2.0)))
    r = int(min(max(r, AUTO_MIN_RESOLUTION), AUTO_MAX_RESOLUTION))
    return r, {"footprint_px_per_uv": need, "footprint_visible": float(seen.mean())}
