"""Screen-adaptive dicing of true displacement (issue 13), Cycles' meaning of a dicing rate.

A *dicing rate* r is the length of one micro-edge in pixels, measured through the scene's
sensors: an edge of world length l at a point where one pixel spans w world units gets
ceil(K max_i(l_i / w_i) / r) segments (K = :data:`TEST_STEPS` test segments along the edge,
Cycles' ``DiagSplit::T``).  w is Cycles' ``world_to_raster_size``: distance x pixel angle for
perspective sensors, a constant for orthographic ones; outside the view frustum it grows
to ``offscreen_dicing_scale`` times that, linearly over one half field of view (Cycles ramps
by world distance; an angle keeps it independent of the scene's scale); behind the camera it
is the full off-screen scale.  With several sensors the finest need (smallest w) wins.
Distances and the frustum test use the *displaced bound* (base +- the largest displacement),
so tall relief at a silhouette is not under-diced (NOTES "Crack-free adaptive dicing"); a
camera closer to the surface than that bound dices as if it were ``bound`` away (else the
need is unbounded), and one patch edge takes at most :data:`MAX_EDGE_SEGMENTS` segments.

Crack-free by construction: the surface is cut into patches (quads of a parametric grid, or
the triangles of a mesh base); each patch *edge* gets its segment count from the edge alone,
so the two patches that share it place the same vertices on it (same canonical parameters,
one position class); a patch's interior is a uniform grid at its own rate, stitched to its
edges by strips (the merge of two uniformly split polylines, as Cycles' ``EdgeDice`` and
hardware tessellators do).  Nothing here loops over elements in Python: topology is built
with vectorised NumPy (ragged index arithmetic), positions by the Dr.Jit kernels of
:mod:`mi_displace.core.tessellate`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import tessellate
from mi_displace.core.surfaces import BaseSurface

TEST_STEPS = 4            # test segments per edge (Cycles' test_steps)
PATCH_EDGES = 8           # target micro-edges along a parametric patch side at the finest need
MAX_PATCHES = 128 * 128   # most patches of a parametric base
MAX_EDGE_SEGMENTS = 256   # most segments on one patch edge
MAX_FACES = 40_000_000    # refuse (before allocating) tessellations with more triangles


@dataclass
class SensorView:
    """What dicing needs of one sensor (world space, float64).

    Attributes:
        origin: (3,) camera position (orthographic: centre of the view rectangle).
        axes: (3, 3) rows: unit camera x, y and viewing direction z.
        orthographic: whether rays are parallel.
        pixel: radians per pixel (perspective) or world units per pixel (orthographic).
        half: (tan of the half angles) or (half extents [world units]) along x, y.
        near: near clip distance [world units].
    """

    origin: np.ndarray
    axes: np.ndarray
    orthographic: bool
    pixel: float
    half: tuple[float, float]
    near: float

    def key(self) -> tuple:
        """Hashable state (re-dice only when it changes)."""
        return (tuple(np.round(self.origin, 9)), tuple(np.round(self.axes.ravel(), 9)),
                self.orthographic, round(self.pixel, 12), tuple(np.round(self.half, 9)),
                round(self.near, 9))


def sensor_view(sensor: mi.Sensor) -> SensorView:
    """Measure a sensor by sampling rays through its film (any projective Mitsuba sensor)."""
    w, h = (int(c) for c in sensor.film().crop_size())
    xs = np.array([w / 2, w / 2 + 1, w / 2, 0.0, w, 0.0, w]) / w
    ys = np.array([h / 2, h / 2, h / 2 + 1, 0.0, h, h, 0.0]) / h
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(mi.Float(xs), mi.Float(ys)),
                               mi.Point2f(0.5, 0.5))
    n = len(xs)  # a constant field (e.g. parallel directions) comes back with width 1
    o = np.broadcast_to(np.asarray(ray.o, np.float64).reshape(3, -1).T, (n, 3)).copy()
    d = np.broadcast_to(np.asarray(ray.d, np.float64).reshape(3, -1).T, (n, 3)).copy()
    d /= np.linalg.norm(d, axis=1)[:, None]
    z = d[0]
    # parallel rays: orthographic (perspective rays start on the near plane, so their
    # origins differ too: test the directions)
    ortho = float(np.linalg.norm(d[1] - d[0])) < 1e-7
    origin = o[0] if ortho else np.array(
        sensor.world_transform().matrix, np.float64).reshape(4, 4)[:3, 3]
    if ortho:
        x = o[1] - o[0]
        pixel = float(np.linalg.norm(x))
    else:
        x = d[1] - d[0]
        pixel = float(np.arccos(np.clip(np.dot(d[0], d[1]), -1, 1)))
    x = x - np.dot(x, z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    axes = np.stack([x, y, z])
    if ortho:
        corner = (o[3:] - o[0]) @ axes.T
        half = (float(np.abs(corner[:, 0]).max()), float(np.abs(corner[:, 1]).max()))
    else:
        corner = d[3:] @ axes.T
        half = (float(np.abs(corner[:, 0] / corner[:, 2]).max()),
                float(np.abs(corner[:, 1] / corner[:, 2]).max()))
    near = float(sensor.near_clip()) if hasattr(sensor, "near_clip") else 1e-2
    if not (pixel > 0 and math.isfinite(pixel) and all(math.isfinite(v) and v > 0 for v in half)):
        raise ValueError(f"displaced: cannot measure the pixel size of sensor {sensor.id()!r}")
    return SensorView(origin=origin, axes=axes, orthographic=ortho, pixel=pixel, half=half,
                      near=max(near, 1e-6))


def pixel_size(views: list[SensorView], points: np.ndarray, bound: float,
               offscreen_scale: float) -> np.ndarray:
    """World length of one pixel at ``points`` (N, 3), finest over ``views``.

    ``bound`` [world units] widens every point to the displaced bound: distances shrink by
    it and the frustum grows by it.  Off-screen points get up to ``offscreen_scale`` x.
    """
    best = np.full(len(points), np.inf)
    for view in views:
        q = (points - view.origin) @ view.axes.T
        hx, hy = view.half
        if view.orthographic:
            size = np.full(len(points), view.pixel)
            out = np.maximum((np.abs(q[:, 0]) - bound - hx) / hx,
                             (np.abs(q[:, 1]) - bound - hy) / hy)
            out = np.where(q[:, 2] + bound < 0, np.inf, out)
        else:
            dist = np.linalg.norm(q, axis=1)
            # a camera inside the displaced bound dices as if it were `bound` away
            size = view.pixel * np.maximum(dist - bound, max(view.near, bound))
            slack = np.arcsin(np.clip(bound / np.maximum(dist, 1e-30), 0, 1))
            ax, ay = math.atan(hx), math.atan(hy)
            out = np.maximum(
                (np.arctan2(np.abs(q[:, 0]), q[:, 2]) - slack - ax) / ax,
                (np.arctan2(np.abs(q[:, 1]), q[:, 2]) - slack - ay) / ay)
        factor = 1 + (offscreen_scale - 1) * np.clip(out, 0, 1)
        best = np.minimum(best, size * factor)
    return best


def check_rates(dicing_rate, offscreen_dicing_scale) -> tuple[float, float]:
    """Validated (dicing_rate > 0, offscreen_dicing_scale >= 1), both finite."""
    rate, off = float(dicing_rate), float(offscreen_dicing_scale)
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"displaced: 'dicing_rate' must be a finite number of pixels > 0, got {dicing_rate}")
    if not (math.isfinite(off) and off >= 1):
        raise ValueError(f"displaced: 'offscreen_dicing_scale' must be finite and >= 1, got "
                         f"{offscreen_dicing_scale}")
    return rate, off


def edge_segments(samples: np.ndarray, views, bound: float, rate: float,
                  offscreen_scale: float) -> np.ndarray:
    """Segments of each edge from its world-space test points.

    Args:
        samples: (E, TEST_STEPS + 1, 3) world points along each edge.
    Returns:
        (E,) int64 in [1, MAX_EDGE_SEGMENTS].
    """
    seg = samples[:, 1:] - samples[:, :-1]
    mid = 0.5 * (samples[:, 1:] + samples[:, :-1])
    px = pixel_size(views, mid.reshape(-1, 3), bound, offscreen_scale).reshape(mid.shape[:2])
    need = TEST_STEPS * np.max(np.linalg.norm(seg, axis=2) / px, axis=1) / rate
    return np.clip(np.ceil(np.nan_to_num(need, nan=1.0, posinf=MAX_EDGE_SEGMENTS)), 1,
                   MAX_EDGE_SEGMENTS).astype(np.int64)


# ---------------------------------------------------------------------------------------
# Patch topology (vectorised NumPy)


def ragged(counts: np.ndarray):
    """(owner, local) index pairs enumerating ``counts[i]`` items of every owner i."""
    counts = np.asarray(counts, np.int64)
    owner = np.repeat(np.arange(len(counts)), counts)
    start = np.cumsum(counts) - counts
    return owner, np.arange(int(counts.sum())) - start[owner]


def stitch(e, m, outer, inner):
    """Triangles of the strip between an outer polyline (e segments) and an inner one (m).

    Outer segment s makes (O_s, O_s+1, I_c) with c the inner segments whose midpoints come
    before its midpoint; inner segment q makes (I_q, O_c, I_q+1) likewise (ties: outer
    first).  ``outer(strip, s)`` and ``inner(strip, q)`` give vertex indices.

    Args:
        e, m: (S,) int segment counts per strip (e >= 1, m >= 0).
    Returns:
        (sum(e + m), 3) int64 triangles, counter-clockwise when the inner polyline lies to
        the left of the outer one's direction.
    """
    st, s = ragged(e)
    es, ms = e[st], m[st]
    c_in = np.clip(-((es - (2 * s + 1) * ms) // (2 * es)), 0, ms)
    outer_tris = np.stack([outer(st, s), outer(st, s + 1), inner(st, c_in)], 1)
    st, q = ragged(m)
    es, ms = e[st], m[st]
    c_out = np.clip(((2 * q + 1) * es - ms) // (2 * ms) + 1, 0, es)
    inner_tris = np.stack([inner(st, q), outer(st, c_out), inner(st, q + 1)], 1)
    return np.concatenate([outer_tris, inner_tris])


def quad_faces(e: np.ndarray, nu: np.ndarray, nv: np.ndarray):
    """Local topology of quad patches with edge segments ``e`` (P, 4) and interior (nu, nv).

    Sides run counter-clockwise in the patch's (x, y) square: 0 bottom (+x), 1 right (+y),
    2 top (-x), 3 left (-y).  Local vertices of a patch: boundary first (side k, s =
    0..e_k - 1, s = 0 its start corner), then interior (i, j), 1 <= i < nu, 1 <= j < nv.

    Returns:
        dict with ``nu``, ``nv`` (as used), ``count`` (P,) vertices per patch, ``boundary``
        (patch, side, s) and ``interior`` (patch, i, j) records, and ``faces`` (F, 3) of
        global (patch-offset) indices.
    """
    simple = (e.max(1) == 1) & (nu <= 1) & (nv <= 1)
    nu = np.where(simple, 1, np.maximum(nu, 2))
    nv = np.where(simple, 1, np.maximum(nv, 2))
    n_b = e.sum(1)
    n_i = np.where(simple, 0, (nu - 1) * (nv - 1))
    count = n_b + n_i
    voff = np.cumsum(count) - count
    soff = np.cumsum(e, 1) - e                       # (P, 4) start of each side

    bp, bl = ragged(n_b)
    side = sum((bl >= soff[bp, k]).astype(np.int64) for k in (1, 2, 3))
    boundary = (bp, side, bl - soff[bp, side])
    ip, il = ragged(n_i)
    interior = (ip, 1 + il % (nu[ip] - 1), 1 + il // (nu[ip] - 1))

    def inner_index(p, i, j):
        return voff[p] + n_b[p] + (j - 1) * (nu[p] - 1) + (i - 1)

    faces = []
    sp = np.flatnonzero(simple)
    if len(sp):
        o = voff[sp][:, None]
        faces += [o + [0, 1, 2], o + [0, 2, 3]]
    qp, ql = ragged(np.where(simple, 0, (nu - 2) * (nv - 2)))
    i, j = 1 + ql % (nu[qp] - 2), 1 + ql // np.maximum(nu[qp] - 2, 1)
    a, b = inner_index(qp, i, j), inner_index(qp, i + 1, j)
    c, d = inner_index(qp, i + 1, j + 1), inner_index(qp, i, j + 1)
    faces += [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    full = np.flatnonzero(~simple)
    inner_side = [  # (i, j) of inner polyline point q along side k
        lambda p, q: (1 + q, np.ones_like(q)),
        lambda p, q: (nu[p] - 1, 1 + q),
        lambda p, q: (nu[p] - 1 - q, nv[p] - 1),
        lambda p, q: (np.ones_like(q), nv[p] - 1 - q)]
    for k in range(4):
        ek = e[full, k]
        mk = (nu[full] if k % 2 == 0 else nv[full]) - 2

        def outer(st, s, k=k):
            p = full[st]
            nxt = soff[p, (k + 1) % 4]
            return voff[p] + np.where(s < e[p, k], soff[p, k] + s, nxt)

        def inner(st, q, k=k):
            p = full[st]
            return inner_index(p, *inner_side[k](p, q))

        faces.append(stitch(ek, mk, outer, inner))
    return {"nu": nu, "nv": nv, "count": count, "boundary": boundary, "interior": interior,
            "faces": np.concatenate(faces)}


def triangular_rows(index: np.ndarray, length: np.ndarray):
    """(row, column) of ``index`` in rows of lengths length, length - 1, ..., 1 (row-major)."""
    length = np.asarray(length, np.int64)
    lf = length.astype(np.float64)
    r = np.floor(((2 * lf + 1) - np.sqrt(np.maximum((2 * lf + 1) ** 2 - 8 * index, 0))) / 2)
    r = r.astype(np.int64)
    start = lambda k: k * length - k * (k - 1) // 2
    r -= (start(r) > index).astype(np.int64)
    r += (start(r + 1) <= index).astype(np.int64)
    return r, index - start(r)


def triangle_faces(e: np.ndarray, n: np.ndarray):
    """Local topology of triangle patches with edge segments ``e`` (P, 3) and interior ``n``.

    Side k runs from corner k to corner k+1.  Interior points (a, b, c) / n with
    a, b, c >= 1 (weights of corners 0, 1, 2), stored row by row in c.  A patch whose edges
    all have 1 segment and n <= 1 is its own triangle; otherwise n >= 3.

    Returns:
        dict like :func:`quad_faces` with ``n`` and ``interior`` = (patch, b, c).
    """
    simple = (e.max(1) == 1) & (n <= 1)
    n = np.where(simple, 1, np.maximum(n, 3))
    n_b = e.sum(1)
    n_i = np.where(simple, 0, (n - 1) * (n - 2) // 2)
    count = n_b + n_i
    voff = np.cumsum(count) - count
    soff = np.cumsum(e, 1) - e
    bp, bl = ragged(n_b)
    side = sum((bl >= soff[bp, k]).astype(np.int64) for k in (1, 2))
    boundary = (bp, side, bl - soff[bp, side])

    def row_start(p, c):
        return (c - 1) * (n[p] - 1) - (c - 1) * c // 2

    def inner_index(p, b, c):
        return voff[p] + n_b[p] + row_start(p, c) + (b - 1)

    ip, il = ragged(n_i)
    r, col = triangular_rows(il, n[ip] - 2)
    interior = (ip, col + 1, r + 1)

    faces = []
    sp = np.flatnonzero(simple)
    if len(sp):
        faces.append(voff[sp][:, None] + [0, 1, 2])
    # inner triangles: level-(n - 3) grid over (b', c') = (b - 1, c - 1)
    m = np.where(simple, 0, n - 3)
    up_p, up_l = ragged(m * (m + 1) // 2)
    down_p, down_l = ragged(np.maximum(m - 1, 0) * m // 2)
    for tp, tl, level, up in ((up_p, up_l, m, True), (down_p, down_l, m - 1, False)):
        if not len(tp):
            continue
        cc, bb = triangular_rows(tl, level[tp])
        b1, c1 = bb + 1, cc + 1
        if up:
            tri = [inner_index(tp, b1, c1), inner_index(tp, b1 + 1, c1), inner_index(tp, b1, c1 + 1)]
        else:
            tri = [inner_index(tp, b1 + 1, c1), inner_index(tp, b1 + 1, c1 + 1),
                   inner_index(tp, b1, c1 + 1)]
        faces.append(np.stack(tri, 1))
    full = np.flatnonzero(~simple)
    inner_side = [lambda p, q: (1 + q, np.ones_like(q)),
                  lambda p, q: (n[p] - 2 - q, 1 + q),
                  lambda p, q: (np.ones_like(q), n[p] - 2 - q)]
    for k in range(3):
        def outer(st, s, k=k):
            p = full[st]
            return voff[p] + np.where(s < e[p, k], soff[p, k] + s, soff[p, (k + 1) % 3])

        def inner(st, q, k=k):
            p = full[st]
            return inner_index(p, *inner_side[k](p, q))

        faces.append(stitch(e[full, k], n[full] - 3, outer, inner))
    return {"n": n, "count": count, "boundary": boundary, "interior": interior,
            "faces": np.concatenate(faces)}


def merge_vertices(keys: np.ndarray, faces: np.ndarray, groups: np.ndarray):
    """Merge vertices with equal ``keys``; drop faces that then repeat a position class.

    Returns:
        (first, groups, faces): index of each kept vertex in the input, its group
        (compacted to 0..G-1) and the remapped faces.
    """
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    faces = inverse.ravel()[faces]
    _, g = np.unique(groups[first], return_inverse=True)
    g = g.ravel()
    fg = g[faces]
    keep = (fg[:, 0] != fg[:, 1]) & (fg[:, 1] != fg[:, 2]) & (fg[:, 0] != fg[:, 2])
    return first, g, faces[keep]


def check_face_budget(faces: int, rate: float, owner: str) -> None:
    """ValueError before allocating more than :data:`MAX_FACES` triangles."""
    if faces > MAX_FACES:
        raise ValueError(
            f"{owner}: dicing_rate {rate:g} px would dice {faces:,} triangles, more than the "
            f"limit of {MAX_FACES:,} (about {MAX_FACES * 48 / 2**30:.1f} GiB); raise "
            "'dicing_rate' or 'offscreen_dicing_scale'")


# ---------------------------------------------------------------------------------------
# Parametric bases


@dataclass
class ParametricDicing:
    """A diced parametric base: uv of every vertex, position classes and triangles.

    Attributes:
        uv: (V, 2) float64 (texture coordinates; seam twins keep u = 1 / v = 1).
        eval_uv: (V, 2) float64, wrapped onto the periodic domain (where to evaluate).
        groups: (V,) int position classes (seam twins and pole points share one).
        at_pole: (V,) bool.
        faces: (F, 3) int, wound along the base's outward normal.
        grid: (nu, nv) patches; edges: per-edge segment counts (dict of arrays).
    """

    uv: np.ndarray
    eval_uv: np.ndarray
    groups: np.ndarray
    at_pole: np.ndarray
    faces: np.ndarray
    grid: tuple[int, int]
    edges: dict


def world_points(base: BaseSurface, to_world: np.ndarray, u: np.ndarray, v: np.ndarray):
    """(N, 3) float64 world positions of the base at (u, v) (wrapped by the caller)."""
    s = base.sample(mi.Float(u.astype(np.float32)), mi.Float(v.astype(np.float32)))
    p = np.asarray(s.p, np.float64).T
    return p @ to_world[:3, :3].T + to_world[:3, 3]


def wrap(base: BaseSurface, u: np.ndarray, v: np.ndarray):
    """(u, v) reduced onto [0, 1) along periodic directions."""
    return (u - np.floor(u) if base.periodic_u else u, v - np.floor(v) if base.periodic_v else v)


def linear_scale(to_world: np.ndarray) -> float:
    """Largest stretch of the linear part of a 4x4 transform."""
    return float(np.linalg.svd(to_world[:3, :3], compute_uv=False).max())


def world_extent(base: BaseSurface, to_world: np.ndarray) -> tuple[float, float]:
    """World lengths of the longest u- and v-isoparametric curves (polylines of 64 steps
    along 9 curves each), so an anisotropic ``to_world`` gets patches of even size."""
    t = np.linspace(0, 1, 65)
    c = np.linspace(0, 1, 9)
    out = []
    for along_u in (True, False):
        a, b = np.meshgrid(t, c)   # a along the curve, b across curves
        u, v = (a, b) if along_u else (b, a)
        pts = world_points(base, to_world, *wrap(base, u.ravel(), v.ravel())).reshape(9, 65, 3)
        out.append(float(np.linalg.norm(np.diff(pts, axis=1), axis=2).sum(1).max()))
    return out[0], out[1]


def parametric_grid(base: BaseSurface, to_world: np.ndarray, views, bound: float, rate: float,
                    offscreen_scale: float) -> tuple[int, int]:
    """Patch grid (nu, nv) so a patch side spans about :data:`PATCH_EDGES` micro-edges where
    the need is finest (probed on a 64 x 64 grid), capped at :data:`MAX_PATCHES` patches."""
    g = (np.arange(64) + 0.5) / 64
    u, v = np.meshgrid(g, g)
    pts = world_points(base, to_world, *wrap(base, u.ravel(), v.ravel()))
    micro = rate * float(pixel_size(views, pts, bound, offscreen_scale).min())
    ext_u, ext_v = world_extent(base, to_world)
    nu = max(1, math.ceil(ext_u / (PATCH_EDGES * micro)))
    nv = max(1, math.ceil(ext_v / (PATCH_EDGES * micro)))
    if nu * nv > MAX_PATCHES:
        shrink = math.sqrt(MAX_PATCHES / (nu * nv))
        nu, nv = max(1, int(nu * shrink)), max(1, int(nv * shrink))
    nu = max(nu, 3 if base.periodic_u else 1)
    nv = max(nv, 2 if base.poles else (3 if base.periodic_v else 1))
    return nu, nv


def parametric_edge_segments(base: BaseSurface, to_world: np.ndarray, grid, views, bound,
                             rate, offscreen_scale) -> dict:
    """Segments of every patch edge and mid-line of a (nu, nv) patch grid.

    Returns:
        dict of int arrays: ``h`` (nv + 1, nu) edges along u, ``v`` (nv, nu + 1) along v,
        ``mid_u`` (nv, nu) and ``mid_v`` (nv, nu) patch mid-lines.
    """
    nu, nv = grid
    t = np.arange(TEST_STEPS + 1) / TEST_STEPS
    lines = {  # (start u, start v, du, dv) per edge, shape (rows, cols)
        "h": [*np.meshgrid(np.arange(nu) / nu, np.arange(nv + 1) / nv), 1 / nu, 0.0],
        "v": [*np.meshgrid(np.arange(nu + 1) / nu, np.arange(nv) / nv), 0.0, 1 / nv],
        "mid_u": [*np.meshgrid(np.arange(nu) / nu, (np.arange(nv) + 0.5) / nv), 1 / nu, 0.0],
        "mid_v": [*np.meshgrid((np.arange(nu) + 0.5) / nu, np.arange(nv) / nv), 0.0, 1 / nv],
    }
    out = {}
    for name, (u0, v0, du, dv) in lines.items():
        u = u0[..., None] + du * t
        v = v0[..., None] + dv * t
        pts = world_points(base, to_world, *wrap(base, u.ravel(), v.ravel()))
        out[name] = edge_segments(pts.reshape(-1, TEST_STEPS + 1, 3), views, bound, rate,
                                  offscreen_scale).reshape(u0.shape)
    return out


def estimate_quad_faces(e: np.ndarray, nu: np.ndarray, nv: np.ndarray) -> int:
    """Triangles :func:`quad_faces` will make (without building them)."""
    simple = (e.max(1) == 1) & (nu <= 1) & (nv <= 1)
    nu, nv = np.maximum(nu, 2), np.maximum(nv, 2)
    full = 2 * (nu - 2) * (nv - 2) + e.sum(1) + 2 * (nu - 2) + 2 * (nv - 2)
    return int(np.where(simple, 2, full).sum())


def dice_parametric(base: BaseSurface, grid, edges: dict, rate: float,
                    owner: str = "displaced") -> ParametricDicing:
    """Crack-free topology of a parametric base from per-edge segment counts."""
    nu_p, nv_p = grid
    pj, pi = np.divmod(np.arange(nu_p * nv_p), nu_p)
    h, v = edges["h"], edges["v"]
    e = np.stack([h[pj, pi], v[pj, pi + 1], h[pj + 1, pi], v[pj, pi]], 1)
    nu = np.maximum(np.maximum(e[:, 0], e[:, 2]), edges["mid_u"][pj, pi])
    nv = np.maximum(np.maximum(e[:, 1], e[:, 3]), edges["mid_v"][pj, pi])
    check_face_budget(estimate_quad_faces(e, nu, nv), rate, owner)
    topo = quad_faces(e, nu, nv)
    emax = int(e.max()) + 1

    # boundary vertices: corners (s = 0) and canonical edge points
    bp, side, s = topo["boundary"]
    ek = e[bp, side]
    ci = pi[bp] + np.array([0, 1, 1, 0])[side]
    cj = pj[bp] + np.array([0, 0, 1, 1])[side]
    along_u = side % 2 == 0                           # sides 0, 2 lie on h-edges
    ei = np.where(side == 1, pi[bp] + 1, pi[bp])     # edge column
    ej = np.where(side == 2, pj[bp] + 1, pj[bp])     # edge row
    canon = np.where(side >= 2, ek - s, s)           # parameter index along +u / +v
    corner = s == 0
    u = np.where(corner, ci / nu_p, np.where(along_u, (ei * ek + canon) / (ek * nu_p), ei / nu_p))
    vv = np.where(corner, cj / nv_p, np.where(along_u, ej / nv_p, (ej * ek + canon) / (ek * nv_p)))
    wi = lambda i, n: i % n if base.periodic_u else i
    wj = lambda j, n: j % n if base.periodic_v else j
    n_corner = (nu_p + 1) * (nv_p + 1)
    cgi, cgj = wi(ci, nu_p), wj(cj, nv_p)
    corner_group = cgj * (nu_p + 1) + cgi
    if base.poles:
        corner_group = np.where(cj == 0, 0, np.where(cj == nv_p, 1, corner_group + 2))
    edge_id = np.where(along_u, wj(ej, nv_p) * nu_p + ei,
                       (nv_p + 1) * nu_p + ej * (nu_p + 1) + wi(ei, nu_p))
    group_b = np.where(corner, corner_group, n_corner + 2 + edge_id * emax + canon)
    ip, ii, jj = topo["interior"]
    u_i = (pi[ip] + ii / topo["nu"][ip]) / nu_p
    v_i = (pj[ip] + jj / topo["nv"][ip]) / nv_p
    n_edge_groups = ((nv_p + 1) * nu_p + nv_p * (nu_p + 1)) * emax
    group_i = n_corner + 2 + n_edge_groups + np.arange(len(ip))

    # local -> global vertex order: the patch's boundary then its interior
    count = topo["count"]
    voff = np.cumsum(count) - count
    nb = e.sum(1)
    order_b = voff[bp] + (np.arange(len(bp)) - (np.cumsum(nb) - nb)[bp])
    order_i = voff[ip] + nb[ip] + (np.arange(len(ip)) - (np.cumsum(count - nb) - (count - nb))[ip])
    total = int(count.sum())
    uv = np.empty((total, 2))
    groups = np.empty(total, np.int64)
    uv[order_b] = np.stack([u, vv], 1)
    uv[order_i] = np.stack([u_i, v_i], 1)
    groups[order_b] = group_b
    groups[order_i] = group_i
    twin = ((uv[:, 0] == 1.0) & base.periodic_u).astype(np.int64) + 2 * (
        (uv[:, 1] == 1.0) & base.periodic_v).astype(np.int64)
    first, g, faces = merge_vertices(groups * 4 + twin, topo["faces"], groups)
    uv = uv[first]
    at_pole = base.poles & ((uv[:, 1] == 0) | (uv[:, 1] == 1))
    if tessellate._winding_is_inward(base):
        faces = faces[:, ::-1]
    return ParametricDicing(uv=uv, eval_uv=np.stack(wrap(base, uv[:, 0], uv[:, 1]), 1),
                            groups=g, at_pole=at_pole, faces=np.ascontiguousarray(faces),
                            grid=grid, edges=edges)


def displace_diced_parametric(base: BaseSurface, d: ParametricDicing, height, scale: float,
                              midlevel: float) -> tessellate.Tessellation:
    """Positions and shading normals of a diced parametric base (Dr.Jit)."""
    groups = mi.UInt32(d.groups.astype(np.uint32))
    n_groups = int(d.groups.max()) + 1 if len(d.groups) else 0
    pole = mi.Bool(d.at_pole)

    def adjust(h, grad):  # one height per position class (the pole's ring mean)
        return (tessellate.group_mean(h, groups, n_groups), dr.select(pole, 0.0, grad))

    u = mi.Float(d.eval_uv[:, 0].astype(np.float32))
    v = mi.Float(d.eval_uv[:, 1].astype(np.float32))
    s, p, p_u, p_v, disp = tessellate.displaced_partials(base, height, scale, midlevel, u, v,
                                                         adjust)
    p = mi.Point3f(tessellate.group_mean(mi.Vector3f(p), groups, n_groups))
    normal = dr.normalize(tessellate.group_mean(tessellate.partials_normal(s, p_u, p_v),
                                                groups, n_groups))
    f = mi.Vector3u(*[mi.UInt32(np.ascontiguousarray(d.faces[:, k], np.uint32)) for k in range(3)])
    return tessellate.Tessellation(
        positions=p, normals=normal,
        texcoords=mi.Point2f(mi.Float(d.uv[:, 0].astype(np.float32)),
                             mi.Float(d.uv[:, 1].astype(np.float32))),
        faces=f, base_positions=mi.Point3f(s.p), base_normals=mi.Vector3f(s.n),
        displacement=disp)


# ---------------------------------------------------------------------------------------
# Mesh bases


@dataclass
class MeshDicing:
    """A diced mesh base: per new vertex 3 base vertex ids + weights, classes, triangles."""

    src: np.ndarray
    bary: np.ndarray
    groups: np.ndarray
    faces: np.ndarray
    edges: np.ndarray


def mesh_edges(faces: np.ndarray, weld: np.ndarray):
    """Unique weld-class edges of a mesh: (E, 2) sorted class pairs and (F, 3) edge ids."""
    a = weld[faces]
    b = weld[np.roll(faces, -1, 1)]
    pairs = np.stack([np.minimum(a, b), np.maximum(a, b)], -1).reshape(-1, 2)
    uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1, 3)


def mesh_edge_segments(positions, faces, weld, to_world, views, bound, rate, offscreen_scale):
    """(E,) segments of every unique (weld) edge and the (F, 3) edge id of each side."""
    uniq, side_edge = mesh_edges(faces, weld)
    rep = np.zeros(int(weld.max()) + 1, np.int64)
    rep[weld] = np.arange(len(weld))
    t = np.arange(TEST_STEPS + 1)[None, :, None] / TEST_STEPS
    pw = np.asarray(positions, np.float64) @ to_world[:3, :3].T + to_world[:3, 3]
    pa, pb = pw[rep[uniq[:, 0]]][:, None], pw[rep[uniq[:, 1]]][:, None]
    return edge_segments(pa + t * (pb - pa), views, bound, rate, offscreen_scale), side_edge


def dice_mesh(faces: np.ndarray, weld: np.ndarray, edge_seg: np.ndarray, side_edge: np.ndarray,
              rate: float, owner: str = "displaced") -> MeshDicing:
    """Crack-free topology of a mesh base (base triangles as patches)."""
    faces = np.asarray(faces, np.int64)
    e = edge_seg[side_edge]
    n = e.max(1)
    nn = np.where(n <= 1, 1, np.maximum(n, 3))
    estimate = int(np.where(n <= 1, 1, (nn - 3) ** 2 + e.sum(1) + 3 * (nn - 3)).sum())
    check_face_budget(estimate, rate, owner)
    topo = triangle_faces(e, n)
    count = topo["count"]
    voff = np.cumsum(count) - count
    nb = e.sum(1)
    total = int(count.sum())
    src = np.empty((total, 3), np.int64)
    bary = np.empty((total, 3))
    key = np.empty(total, np.int64)
    group = np.empty(total, np.int64)
    n_v, n_w, emax = int(faces.max()) + 1, int(weld.max()) + 1, int(e.max()) + 1

    bp, side, s = topo["boundary"]
    va, vb = faces[bp, side], faces[bp, (side + 1) % 3]
    ek = e[bp, side]
    swap = weld[va] > weld[vb]
    lo, hi = np.where(swap, vb, va), np.where(swap, va, vb)
    canon = np.where(swap, ek - s, s)                  # segments from lo
    corner = s == 0
    t = canon / ek
    src_b = np.where(corner[:, None], va[:, None], np.stack([lo, hi, lo], 1))
    bary_b = np.where(corner[:, None], [1.0, 0.0, 0.0], np.stack([1 - t, t, 0 * t], 1))
    edge_key = (np.minimum(lo, hi) * n_v + np.maximum(lo, hi)) * emax + np.where(lo < hi, canon, ek - canon)
    key_b = np.where(corner, va, n_v + edge_key)
    group_b = np.where(corner, weld[va], n_w + side_edge[bp, side] * emax + canon)
    order_b = voff[bp] + (np.arange(len(bp)) - (np.cumsum(nb) - nb)[bp])
    src[order_b], bary[order_b], key[order_b], group[order_b] = src_b, bary_b, key_b, group_b

    ip, bb, cc = topo["interior"]
    nni = topo["n"][ip]
    order_i = voff[ip] + nb[ip] + (np.arange(len(ip)) - (np.cumsum(count - nb) - (count - nb))[ip])
    src[order_i] = faces[ip]
    bary[order_i] = np.stack([nni - bb - cc, bb, cc], 1) / nni[:, None]
    big = n_v + n_v * n_v * emax + 1
    key[order_i] = big + np.arange(len(ip))
    group[order_i] = n_w + len(edge_seg) * emax + np.arange(len(ip))
    first, g, new_faces = merge_vertices(key, topo["faces"], group)
    return MeshDicing(src=src[first].astype(np.uint32), bary=bary[first].astype(np.float32),
                      groups=g.astype(np.uint32), faces=np.ascontiguousarray(new_faces, np.uint32),
                      edges=edge_seg)


def fit_to_sensors(scene) -> list[str]:
    """Size every shape of ``scene`` that sizes itself from sensors for the scene's sensors.

    The one way to fit a scene: each such shape (``displaced`` with ``dicing_rate``,
    ``restored`` with ``levels="auto"``, ``ddm`` with ``map_resolution="auto"``) implements
    ``fit_to_sensors(sensors) -> bool`` (True when it rebuilt); shapes that reference
    sensors of their own (``<ref id="camera"/>``) keep them.  The CLI's loader
    (:func:`mi_displace.render.scene.load`) calls this after ``mi.load_file``, so
    ``mi.load_file`` + ``mi_displace.fit_to_sensors(scene)`` gives the same build.  Call it
    again after editing a sensor through ``mi.traverse``: Mitsuba notifies only the sensor
    and the scene of such an edit, not the shapes sized for it.  Rebuilds the scene's
    acceleration structure when a shape changed.

    Returns:
        ids of the shapes that were rebuilt.
    """
    changed = []
    for shape in scene.shapes():
        method = getattr(shape, "fit_to_sensors", None)
        if method is not None and method(scene.sensors()):
            changed.append(shape.id())
    if changed:
        scene.parameters_changed([])
    return changed
