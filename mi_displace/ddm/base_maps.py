"""Geometry images of the base surface (HDDM §3.1, §4.1): the position map P(u, v) and the
normal map N(u, v), their validity, the 8-neighbour diffusion fill, and tile pruning.

Sampling convention: texel (i, j) of an ``ru`` x ``rv`` map holds S at
u = i / ru along a periodic axis (the map wraps) and u = i / (ru - 1) along an open axis
(both ends sampled; lookups outside [0, 1] clamp), likewise for v.  With that convention
the paper's shader-style lookup (§3.2) is: s = u * ru (or u * (ru - 1)), the four texels
floor(s) + {0, 1} in each axis, bilinear weights from the fraction of s.  The pair (P, N)
with this lookup is a uniform tessellation of S (§3.1).

Polygonal bases (:class:`~mi_displace.ddm.mesh_base.MeshBase`): texels outside the UV
layout are *invalid*; :func:`diffuse_fill` gives each of them the value of the nearest
valid texel by the paper's diffusion (§4.1), so that vertices falling there are clamped to
the nearest boundary; tiles whose footprint touches no valid texel are pruned.  Texels
of any base whose normal is degenerate (zero length, NaN) are invalid too.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.tessellate import gather

MAX_MAP_RESOLUTION = 8192
MIN_MAP_RESOLUTION = 4


def texel_coordinates(ru: int, rv: int, periodic_u: bool, periodic_v: bool):
    """(u, v) of every texel, row-major (v rows), as two mi.Float of length ru * rv."""
    i = dr.arange(mi.UInt32, ru * rv)
    iu, iv = mi.Float(i % ru), mi.Float(i // ru)

    def coord(k, r, periodic):
        return k / (r if periodic else r - 1)

    return coord(iu, ru, periodic_u), coord(iv, rv, periodic_v)


def diffuse_fill(valid: np.ndarray, periodic_u: bool, periodic_v: bool):
    """HDDM §4.1 diffusion: invalid texels repeatedly take the value of a valid 8-neighbour.

    Each sweep, every still-invalid texel that has valid neighbours is assigned from one of
    them; of several, the one whose *source* texel lies nearest (Euclidean, in texels) —
    so the front carries the nearest valid location, as the paper intends.  Sweeps repeat
    until every texel is filled (the number of sweeps is the largest chessboard distance).
    Vectorised NumPy over the texels still open (one-off preprocessing).

    Args:
        valid: (rv, ru) bool.
        periodic_u, periodic_v: whether neighbours wrap around.

    Returns:
        ``(source, sweeps)``: (rv, ru) int64 flat index of the valid texel whose value each
        texel holds (valid texels: themselves) and the number of sweeps.

    Raises:
        ValueError: no texel is valid.
    """
    rv, ru = valid.shape
    if not valid.any():
        raise ValueError("ddm: the base map has no valid texel to diffuse from")
    src = np.where(valid.ravel(), np.arange(valid.size), -1)
    todo = np.flatnonzero(~valid.ravel())
    ty, tx = todo // ru, todo % ru
    sweeps = 0
    offsets = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
    while len(todo):
        best = np.full(len(todo), -1)
        best_d = np.full(len(todo), np.inf)
        for dy, dx in offsets:
            ny, nx = ty + dy, tx + dx
            inside = np.ones(len(todo), bool)
            if periodic_v:
                ny %= rv
            else:
                inside &= (ny >= 0) & (ny < rv)
            if periodic_u:
                nx %= ru
            else:
                inside &= (nx >= 0) & (nx < ru)
            s = np.where(inside, src[np.clip(ny, 0, rv - 1) * ru + np.clip(nx, 0, ru - 1)], -1)
            ok = s >= 0
            ddy = np.abs(np.where(ok, s // ru, 0) - ty)
            ddx = np.abs(np.where(ok, s % ru, 0) - tx)
            if periodic_v:
                ddy = np.minimum(ddy, rv - ddy)
            if periodic_u:
                ddx = np.minimum(ddx, ru - ddx)
            d = np.where(ok, ddx * ddx + ddy * ddy, np.inf)
            better = d < best_d
            best = np.where(better, s, best)
            best_d = np.where(better, d, best_d)
        filled = best >= 0
        src[todo[filled]] = best[filled]   # synchronous: assigned after the sweep
        todo, ty, tx = todo[~filled], ty[~filled], tx[~filled]
        sweeps += 1
    return src.reshape(rv, ru), sweeps


def bilinear(position, normal, idx, wu, wv, su, sv, derivatives: bool):
    """The §3.2 shader lookup from four texel indices ``idx`` (00, 10, 01, 11 in u, v) and
    fractions ``wu``, ``wv``: bilinear P and N, plus (P_u, P_v, N_u, N_v) per unit uv
    (``su``, ``sv``: texels per unit uv) when ``derivatives``."""
    ps = [gather(mi.Vector3f, position, k) for k in idx]
    ns = [gather(mi.Vector3f, normal, k) for k in idx]

    def bilerp(c):
        return dr.lerp(dr.lerp(c[0], c[1], wu), dr.lerp(c[2], c[3], wu), wv)

    p, n = bilerp(ps), bilerp(ns)
    if not derivatives:
        return p, n

    def d_du(c):
        return ((c[1] - c[0]) * (1 - wv) + (c[3] - c[2]) * wv) * su

    def d_dv(c):
        return (dr.lerp(c[2], c[3], wu) - dr.lerp(c[0], c[1], wu)) * sv

    return p, n, (d_du(ps), d_dv(ps), d_du(ns), d_dv(ns))


@dataclass
class GeometryImage:
    """The (P, N) texture pair of a base surface (§3.1).

    Attributes:
        position, normal: mi.Vector3f of ru * rv texels (row-major, v rows) [object units /
            unit normals]; invalid texels hold their diffusion-filled values.
        valid: (rv, ru) bool, before filling.
        ru, rv: texels along u and v; periodic_u, periodic_v: wrap flags.
        stats: build figures (seconds, invalid texels, diffusion sweeps).
    """

    position: mi.Vector3f
    normal: mi.Vector3f
    valid: np.ndarray
    ru: int
    rv: int
    periodic_u: bool
    periodic_v: bool
    stats: dict = field(default_factory=dict)

    @property
    def nbytes(self) -> int:
        """Bytes HDDM stores: two RGB float32 maps (§3.1) plus a 1-byte validity bitmap."""
        return self.ru * self.rv * (2 * 3 * 4 + 1)

    def _axis(self, x, r: int, periodic: bool):
        """Texel indices i0, i1, weight of i1 and d(s)/dx along one axis (§3.2 lookup)."""
        if periodic:
            s = x * r
            f0 = dr.floor(s)
            w = s - f0
            i0 = mi.Int32(f0 - r * dr.floor(f0 / r))      # wrap (negative u included)
            i0 = dr.select(i0 >= r, i0 - r, i0)
            i1 = dr.select(i0 + 1 >= r, i0 + 1 - r, i0 + 1)
            return mi.UInt32(i0), mi.UInt32(i1), w, float(r)
        s = dr.clip(x, 0.0, 1.0) * (r - 1)
        i0 = mi.UInt32(dr.minimum(dr.floor(s), r - 2))
        w = s - mi.Float(i0)
        return i0, i0 + 1, w, float(r - 1)

    def lookup(self, u, v, derivatives: bool = False):
        """Bilinear P and N at (u, v) — four texels each, interpolated in the shader (§3.2).

        Returns:
            ``(P, N)``, plus ``(P_u, P_v, N_u, N_v)`` (derivatives of the bilinear
            interpolant per unit uv, exact inside each texel) when ``derivatives``.
            N is the interpolated map value, not renormalised (eq. 2 uses it as it is).
        """
        iu0, iu1, wu, su = self._axis(u, self.ru, self.periodic_u)
        iv0, iv1, wv, sv = self._axis(v, self.rv, self.periodic_v)
        r0, r1 = iv0 * self.ru, iv1 * self.ru
        return bilinear(self.position, self.normal, (r0 + iu0, r0 + iu1, r1 + iu0, r1 + iu1),
                        wu, wv, su, sv, derivatives)

    def clamped_count(self, u: mi.Float, v: mi.Float) -> int:
        """How many of the points (u, v) fall in an invalid texel (nearest texel), i.e. are
        clamped to the nearest valid value by the filled maps (§4.1).  Dr.Jit."""
        if self.valid.all():
            return 0
        mask = mi.Bool(np.ascontiguousarray(self.valid.ravel()))

        def nearest(x, r, periodic):
            if periodic:
                k = mi.Int32(dr.round(x * r))
                return mi.UInt32(k - r * mi.Int32(dr.floor(mi.Float(k) / r)))
            return mi.UInt32(dr.round(dr.clip(x, 0.0, 1.0) * (r - 1)))

        k = nearest(v, self.rv, self.periodic_v) * self.ru + nearest(u, self.ru, self.periodic_u)
        return int(dr.count(~dr.gather(mi.Bool, mask, k))[0])

    def texel_valid(self, u, v) -> np.ndarray:
        """Validity of the nearest texel to each (u, v) (NumPy bool)."""
        uu, vv = np.asarray(u, np.float64), np.asarray(v, np.float64)

        def nearest(x, r, periodic):
            if periodic:
                return np.round(x * r).astype(np.int64) % r
            return np.clip(np.round(np.clip(x, 0, 1) * (r - 1)), 0, r - 1).astype(np.int64)

        return self.valid[nearest(vv, self.rv, self.periodic_v), nearest(uu, self.ru, self.periodic_u)]


def check_resolution(value, name: str = "map_resolution") -> int:
    """A map resolution in MIN_MAP_RESOLUTION..MAX_MAP_RESOLUTION, else ValueError naming
    the parameter: fewer than 4 texels around a periodic axis collapse the base (1: every
    vertex on one point, 2: on a segment, 3: a flat prism), and 2 or 3 along an open
    axis of a curved base leave nothing of its shape."""
    if int(value) != value or not MIN_MAP_RESOLUTION <= value <= MAX_MAP_RESOLUTION:
        raise ValueError(f"ddm: '{name}' must be an integer in {MIN_MAP_RESOLUTION}.."
                         f"{MAX_MAP_RESOLUTION} (fewer texels collapse the base), got {value!r}")
    return int(value)


def build_maps(base, ru: int, rv: int | None = None) -> GeometryImage:
    """Sample P and N of ``base`` into an ``ru`` x ``rv`` geometry image and fill it.

    Parametric bases are evaluated analytically at the texel coordinates; a
    :class:`~mi_displace.ddm.mesh_base.MeshBase` is rasterised in UV space (one ray per
    texel) with validity = covered.  Degenerate normals make a texel invalid.  Invalid
    texels get the diffusion-filled values of :func:`diffuse_fill`.
    """
    ru = check_resolution(ru)
    rv = ru if rv is None else check_resolution(rv)
    start = time.perf_counter()
    pu, pv = bool(base.periodic_u), bool(base.periodic_v)
    u, v = texel_coordinates(ru, rv, pu, pv)
    if hasattr(base, "locate"):   # a polygonal base (MeshBase): no analytic S(u, v) to sample
        covered, prim, b1, b2 = base.locate(u, v)
        p, nn = base.interpolate(prim, b1, b2)
        n = nn / dr.maximum(dr.norm(nn), 1e-20)
        ok = covered & (dr.norm(nn) > 1e-6)
    else:
        s = base.sample(u, v)
        p, n = mi.Vector3f(s.p), mi.Vector3f(s.n)
        ok = dr.isfinite(dr.norm(n)) & (dr.abs(dr.norm(n) - 1) < 0.1) & dr.all(dr.isfinite(p))
    valid = np.asarray(ok).reshape(rv, ru)
    if not valid.any():
        raise ValueError(f"ddm: no valid texel in the {ru} x {rv} base map "
                         "(UV layout outside [0, 1]^2, or degenerate normals everywhere)")
    sweeps = 0
    if not valid.all():
        src, sweeps = diffuse_fill(valid, pu, pv)
        k = mi.UInt32(src.ravel().astype(np.uint32))
        p, n = gather(mi.Vector3f, p, k), gather(mi.Vector3f, n, k)
    p, n = mi.Vector3f(p), mi.Vector3f(n)
    dr.eval(p, n)
    stats = {"map_build_s": time.perf_counter() - start, "invalid_texels": int((~valid).sum()),
             "diffusion_sweeps": int(sweeps)}
    return GeometryImage(p, n, valid, ru, rv, pu, pv, stats)


def prune(layout, bounds: np.ndarray, maps: GeometryImage):
    """Drop tiles whose footprint covers no valid texel (§4.1 CPU-side optimisation).

    Args:
        layout: :class:`~mi_displace.ddm.layout.Layout`.
        bounds: (K, 4) per tile of the set: x_min, y_min, x_max, y_max (canonical).
        maps: the geometry image with its validity bitmap.

    Returns:
        ``(kept_layout, pruned_count)``.  The footprint is the tile's uv box grown by one
        texel (the bilinear lookup reads the neighbours); a summed-area table over the
        (wrap-padded) validity bitmap counts its valid texels.
    """
    if maps.valid.all():
        return layout, 0
    ru, rv = maps.ru, maps.rv
    pad_u, pad_v = (ru, ru) if maps.periodic_u else (0, 0), (rv, rv) if maps.periodic_v else (0, 0)
    padded = np.pad(maps.valid.astype(np.int64), (pad_v, pad_u), mode="wrap")
    sat = np.zeros((padded.shape[0] + 1, padded.shape[1] + 1), np.int64)
    sat[1:, 1:] = padded.cumsum(0).cumsum(1)
    b = bounds[layout.tile_index]
    su, sv = layout.size
    lo_u, hi_u = layout.offsets[:, 0] + su * b[:, 0], layout.offsets[:, 0] + su * b[:, 2]
    lo_v, hi_v = layout.offsets[:, 1] + sv * b[:, 1], layout.offsets[:, 1] + sv * b[:, 3]

    def texel_range(lo, hi, r, periodic, pad):
        scale = r if periodic else max(r - 1, 1)
        a = np.floor(lo * scale).astype(np.int64) - 1
        z = np.ceil(hi * scale).astype(np.int64) + 1
        if periodic:
            shift = np.floor_divide(a, r) * r
            a, z = a - shift, z - shift
            z = np.minimum(z, a + r - 1)
            return a + pad, z + pad
        return np.clip(a, 0, r - 1), np.clip(z, 0, r - 1)

    a_u, z_u = texel_range(lo_u, hi_u, ru, maps.periodic_u, pad_u[0])
    a_v, z_v = texel_range(lo_v, hi_v, rv, maps.periodic_v, pad_v[0])
    count = sat[z_v + 1, z_u + 1] - sat[a_v, z_u + 1] - sat[z_v + 1, a_u] + sat[a_v, a_u]
    keep = count > 0
    return layout.subset(keep), int((~keep).sum())


def map_error(base, maps: GeometryImage, w_max: float, samples: int = 1 << 16, seed: int = 0) -> float:
    """Largest error of the mapped point T = P + N w against S + n w (object units) at the
    cell centres of ``maps`` (where bilinear interpolation errs most) and at ``samples``
    seeded random (u, v), over w in {0, w_max}; points in invalid texels are skipped."""
    ru, rv = maps.ru, maps.rv
    i = dr.arange(mi.UInt32, ru * rv)
    su = ru if maps.periodic_u else max(ru - 1, 1)
    sv = rv if maps.periodic_v else max(rv - 1, 1)
    cu = dr.minimum((mi.Float(i % ru) + 0.5) / su, 1.0)
    cv = dr.minimum((mi.Float(i // ru) + 0.5) / sv, 1.0)
    rng = np.random.default_rng(seed)
    u = np.concatenate([np.asarray(cu), rng.random(samples)])
    v = np.concatenate([np.asarray(cv), rng.random(samples)])
    keep = np.ones(len(u), bool)      # all four texels of the lookup valid (clamps excluded)
    for du in (-0.5 / su, 0.5 / su):
        for dv in (-0.5 / sv, 0.5 / sv):
            keep &= maps.texel_valid(u + du, v + dv)
    u, v = mi.Float(u[keep].astype(np.float32)), mi.Float(v[keep].astype(np.float32))
    s = base.sample(u, v)
    p, n = maps.lookup(u, v)
    d0 = dr.norm(p - s.p)
    d1 = dr.norm(p + n * w_max - (s.p + s.n * w_max))
    return float(dr.max(dr.maximum(d0, d1))[0])


AUTO_MAX_RESOLUTION = 2048


def choose_resolution(base, tolerance: float, w_max: float, start: int = 32, build=None,
                      error=None, order: float = 2.0) -> tuple[int, list]:
    """The smallest power-of-two ``map_resolution`` whose mapped points stay within
    ``tolerance`` x (bounding-box diagonal of the base) of the exact ones (``error``, by
    default :func:`map_error`, of the maps ``build(r)`` makes, by default
    :func:`build_maps`; mesh bases pass the per-chart pair of
    :mod:`mi_displace.ddm.charts`).

    Bilinear geometry images of a smooth base err as 1/R^``order`` (2, measured in
    docs/ddm.md; a mesh base is piecewise linear, its creases make it 1), so one
    measurement at ``start`` predicts R; the prediction is checked, doubled until it holds (at most
    :data:`AUTO_MAX_RESOLUTION`, which is returned if even that misses) and halved while
    the half still holds (not below :data:`MIN_MAP_RESOLUTION`).

    Returns:
        ``(resolution, trials, maps)`` with trials = [(R, relative error), ...] and the maps
        ``build(resolution)`` made for the trial (the caller keeps them, not a second build).
    """
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"ddm: 'tolerance' must be a positive number, got {tolerance!r}")
    diagonal = base_sample_diagonal(base)
    build = build or (lambda r: build_maps(base, r))
    measure = error or map_error
    trials, built = {}, {}   # built: the maps of the last two trials (the answer is one of them)

    def error(r: int) -> float:
        if r not in trials:
            built[r] = build(r)
            trials[r] = measure(base, built[r], w_max) / diagonal
            while len(built) > 2:
                del built[next(iter(built))]
        return trials[r]

    r = start
    if error(r) > tolerance:
        predicted = r * (error(r) / tolerance) ** (1 / order)
        r = min(AUTO_MAX_RESOLUTION, 2 ** math.ceil(math.log2(predicted)))
        while error(r) > tolerance and r < AUTO_MAX_RESOLUTION:
            r *= 2
    while r // 2 >= MIN_MAP_RESOLUTION and error(r // 2) <= tolerance:
        r //= 2
    return r, sorted(trials.items()), built[r]


def base_sample_diagonal(base, n: int = 64) -> float:
    """Bounding-box diagonal of the base, from an n x n sample (object units)."""
    u, v = texel_coordinates(n, n, False, False)
    # a constant coordinate (the plane's z) comes back as a width-1 array: broadcast it
    p = np.stack([np.broadcast_to(np.asarray(c), (n * n,)) for c in base.sample(u, v).p], 1)
    return float(np.linalg.norm(p.max(0) - p.min(0)))
