"""Procedural height fields with exact (analytic) gradients.

Every pattern is a pure Dr.Jit function of texture coordinates::

    h, grad = pattern(uv, **parameters)

* ``uv``: :class:`mi.Point2f`, shape ``(2, N)``; unitless texture space.
* ``h``: :class:`mi.Float`, shape ``(N,)``; unitless height in ``[0, 1]`` (the displaced
  shape's ``scale`` carries the physical amplitude).
* ``grad``: :class:`mi.Vector2f`, shape ``(2, N)``; ``(dh/du, dh/dv)`` per unit ``uv``,
  exact wherever ``h`` is differentiable (everywhere except measure-zero creases).

Parameters are Python numbers, validated (``ValueError`` naming the parameter) before any
kernel is traced.  A continuous parameter (every one but the integer counts and seeds of
:data:`INTEGER_PARAMETERS`) may instead be a width-1 ``mi.Float``: it is validated by its
value and enters the kernels as that array, so an AD gradient enabled on it reaches ``h``
and ``grad`` (issue 14: differentiable procedural heights). Each pattern is periodic over the unit square when its counts are
integers: ``h(u + 1, v) == h(u, v) == h(u, v + 1)``, so it tiles seamlessly across the
``u``/``v`` seams of closed surfaces. Coordinates are reduced to ``[0, 1)`` first, so
offsets far from the origin keep float32 precision.
"""
from __future__ import annotations

import inspect
import math

import drjit as dr
import mitsuba as mi
import numpy as np

TWO_PI = 2.0 * math.pi
MAX_CELLS = 1 << 15  # cell keys i + n*j must fit in 32 bits


# ----------------------------------------------------------------------------- validation

def _bound(x) -> str:
    """An interval end as written in messages: integers in full (2147483647), else ``:g``."""
    return str(x) if isinstance(x, int) else f"{x:g}"


def check_real(pattern: str, name: str, value, low=None, high=None, low_open=False,
               high_open=False) -> float:
    """``value`` (a number or a width-1 Dr.Jit array, checked by its detached value) as a
    finite float inside the given interval, else a ``ValueError`` naming ``pattern`` and the
    parameter ``name``."""
    if dr.is_array_v(value):
        if dr.width(value) != 1 or dr.depth_v(value) != 1:
            raise ValueError(f"{pattern}: parameter '{name}' must be a single number, got an "
                             f"array of width {dr.width(value)}")
        value = float(dr.detach(value)[0])
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{pattern}: parameter '{name}' must be a number, got {value!r}") from None
    bad = (not math.isfinite(x)
           or (low is not None and (x <= low if low_open else x < low))
           or (high is not None and (x >= high if high_open else x > high)))
    if bad:
        lo = "(-inf" if low is None else ("(" if low_open else "[") + _bound(low)
        hi = "inf)" if high is None else _bound(high) + (")" if high_open else "]")
        raise ValueError(f"{pattern}: parameter '{name}' must be finite and in {lo}, {hi}, "
                         f"got {value!r}")
    return x


def _integer(pattern: str, name: str, value, low: int = 1, high: int | None = None) -> int:
    """``value`` as an integer in ``[low, high]`` (integral floats accepted), else
    ``ValueError``."""
    x = check_real(pattern, name, value, low=low, high=high)
    if x != int(x):
        raise ValueError(f"{pattern}: parameter '{name}' must be an integer, got {value!r}")
    return int(x)


INTEGER_PARAMETERS = {"ripples": (), "bricks": ("rows", "columns"), "cells": ("cells", "seed")}
"""pattern -> its integer parameters (counts, seeds): not differentiable; every other
parameter is continuous and may carry an AD gradient."""


def _attached(checked: float, given):
    """``given`` itself when it is a Dr.Jit array (validated as ``checked``; its AD graph
    kept), else the checked float."""
    return given if dr.is_array_v(given) else checked


def check_ripples(frequency=8.0, phase=0.0) -> dict:
    """Validated, normalised :func:`ripples` parameters (``frequency`` becomes a pair)."""
    is_pair = isinstance(frequency, (tuple, list, np.ndarray))
    pair = frequency if is_pair else (frequency,) * 2
    if len(pair) != 2:
        raise ValueError(f"ripples: parameter 'frequency' must be a number or a (u, v) pair, "
                         f"got {frequency!r}")
    fu, fv = (check_real("ripples", f"frequency_{axis}" if is_pair else "frequency", f,
                         low=0, low_open=True) for axis, f in zip("uv", pair))
    return dict(frequency=(fu, fv), phase=check_real("ripples", "phase", phase))


def check_bricks(rows=8, columns=4, mortar=0.1, bevel=0.15) -> dict:
    """Validated :func:`bricks` parameters."""
    p = dict(rows=_integer("bricks", "rows", rows), columns=_integer("bricks", "columns", columns),
             mortar=check_real("bricks", "mortar", mortar, low=0, high=0.5, high_open=True),
             bevel=check_real("bricks", "bevel", bevel, low=0, low_open=True))
    if p["mortar"] + 2 * p["bevel"] > 1:
        raise ValueError(f"bricks: parameter 'mortar' + 2*'bevel' must be <= 1 (the joint and "
                         f"both ramps fit in one brick height), got {p['mortar']:g} + "
                         f"2*{p['bevel']:g}")
    return p


def check_cells(cells=8, radius=0.5, jitter=1.0, seed=0) -> dict:
    """Validated :func:`cells` parameters."""
    return dict(cells=_integer("cells", "cells", cells, high=MAX_CELLS),
                radius=check_real("cells", "radius", radius, low=0, high=1, low_open=True),
                jitter=check_real("cells", "jitter", jitter, low=0, high=1),
                seed=_integer("cells", "seed", seed, low=0, high=2**31 - 1))


# ----------------------------------------------------------------------------- patterns

def _frac(x: mi.Float) -> mi.Float:
    return x - dr.floor(x)


def ripples(uv: mi.Point2f, frequency=8.0, phase=0.0) -> tuple[mi.Float, mi.Vector2f]:
    """Egg-crate sine ripples.

    ``h = 1/2 + 1/2 sin(2 pi f_u u + phase) sin(2 pi f_v v)``;
    ``grad = (pi f_u cos(a) sin(b), pi f_v sin(a) cos(b))`` with ``a, b`` the two angles.

    ``frequency``: periods per unit ``uv`` (a number, or a ``(f_u, f_v)`` pair), > 0; the
    pattern is periodic over the unit square for integer frequencies. ``phase``: radians.
    """
    p = check_ripples(frequency, phase)
    pair = isinstance(frequency, (tuple, list, np.ndarray))
    given = frequency if pair else (frequency, frequency)
    fu, fv = (_attached(f, g) for f, g in zip(p["frequency"], given))
    phase = _attached(p["phase"], phase)
    a = TWO_PI * _frac(fu * uv.x) + phase   # argument reduction: exact periodicity
    b = TWO_PI * _frac(fv * uv.y)
    sa, ca = dr.sincos(a)
    sb, cb = dr.sincos(b)
    h = 0.5 + 0.5 * sa * sb
    return h, mi.Vector2f(math.pi * fu * ca * sb, math.pi * fv * sa * cb)


def bricks(uv: mi.Point2f, rows=8, columns=4, mortar=0.1, bevel=0.15
           ) -> tuple[mi.Float, mi.Vector2f]:
    """Bricks in running bond: ``rows`` x ``columns`` per unit ``uv``, odd rows shifted by
    half a brick.

    Let ``d`` be the ``uv`` distance from the point to its brick's border, in units of the
    brick height ``1/rows`` (both axes measured alike: ``d = rows * min(dist_u, dist_v)``).
    Then ``h = S((d - mortar/2) / bevel)`` with the C1 smoothstep ``S(t) = 3t^2 - 2t^3`` on
    ``t`` clamped to ``[0, 1]``: ``h = 0`` in the joint (``mortar`` = full joint width),
    a ramp of width ``bevel``, ``h = 1`` on the stone top. ``grad = S'(t)/bevel * grad d``
    with ``|grad d| = rows``: exact and continuous everywhere (ramp ends included) except on
    the mitred ramp corners, where the u- and v-ramps meet in a crease (``dist_u == dist_v``).

    ``rows``, ``columns``: positive integers; ``0 <= mortar < 0.5``; ``bevel > 0`` with
    ``mortar + 2*bevel <= 1``. With an odd ``rows`` the bond repeats the unshifted row
    across the ``v`` seam (still periodic, just not alternating there).
    """
    p = check_bricks(rows, columns, mortar, bevel)
    rows, columns = p["rows"], p["columns"]
    mortar, bevel = _attached(p["mortar"], mortar), _attached(p["bevel"], bevel)
    y = rows * _frac(uv.y)
    row = dr.floor(y)
    py = y - row
    shift = 0.5 * (row - 2.0 * dr.floor(0.5 * row))          # 0 on even rows, 1/2 on odd
    px = _frac(columns * _frac(uv.x) + shift)
    ex = (rows / columns) * dr.minimum(px, 1.0 - px)         # border distances, brick heights
    ey = dr.minimum(py, 1.0 - py)
    use_x = ex < ey
    t = dr.clip((dr.select(use_x, ex, ey) - 0.5 * mortar) / bevel, 0.0, 1.0)
    h = t * t * (3.0 - 2.0 * t)
    slope = (6.0 * rows / bevel) * t * (1.0 - t)             # dh/dd * |grad d|
    gu = dr.select(use_x, dr.select(px < 0.5, slope, -slope), 0.0)
    gv = dr.select(use_x, 0.0, dr.select(py < 0.5, slope, -slope))
    return h, mi.Vector2f(gu, gv)


def _wrap(i: mi.Int32, n: int) -> mi.Int32:
    return dr.select(i < 0, i + n, dr.select(i >= n, i - n, i))


def cells(uv: mi.Point2f, cells=8, radius=0.5, jitter=1.0, seed=0
          ) -> tuple[mi.Float, mi.Vector2f]:
    """Round bumps on a jittered grid of ``cells`` x ``cells`` per unit ``uv``.

    Cell ``(i, j)`` holds one feature point ``c_ij = (i, j) + 1/2 + jitter (r_ij - 1/2)`` (in
    cell units) with ``r_ij`` a TEA hash of ``(i + cells*j, seed)``, so the layout is
    deterministic and periodic (indices wrap modulo ``cells``). With ``x = cells * uv`` and
    ``q = |x - c|^2 / radius^2``, each feature carries the C1 compact bump
    ``b = (1 - q)^2`` for ``q < 1`` (0 outside); ``h = max`` of ``b`` over the 3x3
    neighbouring cells and ``grad = -4 (1 - q) (x - c) cells / radius^2`` of the winner
    (exact except where two bumps tie).

    ``cells``: positive integer; ``0 < radius <= 1`` (cell units; at most 1 keeps every
    bump inside the 3x3 neighbourhood); ``0 <= jitter <= 1``; ``seed``: integer >= 0.
    """
    p = check_cells(cells, radius, jitter, seed)
    n, seed = p["cells"], p["seed"]
    radius, jitter = _attached(p["radius"], radius), _attached(p["jitter"], jitter)
    x, y = n * _frac(uv.x), n * _frac(uv.y)
    fx, fy = dr.floor(x), dr.floor(y)
    ix, iy = mi.Int32(fx), mi.Int32(fy)
    h, gu, gv = mi.Float(0.0), mi.Float(0.0), mi.Float(0.0)
    k = -4.0 * n / (radius * radius)
    for dj in (-1, 0, 1):          # 9 neighbours: unrolled at trace time, not per element
        for di in (-1, 0, 1):
            key = mi.UInt32(_wrap(ix + di, n) + n * _wrap(iy + dj, n))
            dx = x - (fx + (di + 0.5 + jitter * (mi.sample_tea_float32(key, 2 * seed) - 0.5)))
            dy = y - (fy + (dj + 0.5 + jitter * (mi.sample_tea_float32(key, 2 * seed + 1) - 0.5)))
            w = dr.maximum(1.0 - (dx * dx + dy * dy) / (radius * radius), 0.0)
            better = w * w > h
            h = dr.select(better, w * w, h)
            gu = dr.select(better, k * w * dx, gu)
            gv = dr.select(better, k * w * dy, gv)
    return h, mi.Vector2f(gu, gv)


# ----------------------------------------------------------------------------- means

def mean_ripples(frequency=8.0, phase=0.0) -> float:
    """Exact mean of :func:`ripples` over the unit square (``1/2`` for integer frequencies):
    ``1/2 + 1/2 I(f_u, phase) I(f_v, 0)``, ``I(f, p) = (cos p - cos(2 pi f + p)) / (2 pi f)``.
    """
    p = check_ripples(frequency, phase)
    (fu, fv), phase = p["frequency"], p["phase"]

    def integral(f, ph):
        return (math.cos(ph) - math.cos(TWO_PI * f + ph)) / (TWO_PI * f)

    return 0.5 + 0.5 * integral(fu, phase) * integral(fv, 0.0)


def mean_bricks(rows=8, columns=4, mortar=0.1, bevel=0.15, samples=100_000) -> float:
    """Mean of :func:`bricks` over the unit square (= over one brick), by 1D quadrature in
    NumPy: ``E[S(t(d))] = int S'(t) A(mortar/2 + bevel t) dt / A(0)`` with ``A(s)`` the area
    of the brick's inset ``{d > s}`` (``(W - 2s)(1 - 2s)``, ``W = rows/columns``).
    """
    p = check_bricks(rows, columns, mortar, bevel)
    width = p["rows"] / p["columns"]
    t = (np.arange(samples) + 0.5) / samples
    s = 0.5 * p["mortar"] + p["bevel"] * t
    area = np.maximum(width - 2 * s, 0.0) * np.maximum(1.0 - 2 * s, 0.0)
    return float(np.mean(6.0 * t * (1.0 - t) * area) / width)


def mean_cells(cells=8, radius=0.5, jitter=1.0, seed=0) -> float:
    """Mean of :func:`cells` over the unit square: midpoint rule on an ``m x m`` grid
    (``m = clamp(32 cells, 512, 2048)``), one Dr.Jit kernel. Without overlaps the exact
    value is ``pi radius^2 / 3``.
    """
    p = check_cells(cells, radius, jitter, seed)
    return grid_mean(lambda uv: evaluate("cells", uv, **p)[0],
                     min(max(32 * p["cells"], 512), 2048))


def grid_mean(fn, m: int) -> float:
    """Mean of ``fn(uv) -> mi.Float`` over the unit square by the ``m x m`` midpoint rule."""
    idx = dr.arange(mi.UInt32, m * m)
    uv = mi.Point2f((mi.Float(idx % m) + 0.5) / m, (mi.Float(idx // m) + 0.5) / m)
    return float(dr.mean(fn(uv))[0])


PATTERNS = {
    "ripples": (ripples, check_ripples, mean_ripples),
    "bricks": (bricks, check_bricks, mean_bricks),
    "cells": (cells, check_cells, mean_cells),
}
"""name -> (pattern function, parameter check, mean over the unit square)."""


def pattern_defaults(pattern: str) -> dict:
    """Default parameters of ``pattern`` (from its check function's signature)."""
    return {name: p.default for name, p in
            inspect.signature(PATTERNS[pattern][1]).parameters.items()}


# ----------------------------------------------------------------------------- to_uv

UVAffine = tuple[tuple[float, float, float, float], tuple[float, float]]


def uv_affine(transform, where: str = "texture") -> UVAffine | None:
    """The 2D affine map ``uv' = A uv + t`` of a Mitsuba ``to_uv`` transform, like
    ``bitmap``: ``A`` = upper-left 2x2, ``t`` = first two entries of the last column.

    ``transform``: ``mi.ScalarTransform4f``/``3f`` (or ``4d``/``3d``) or a 4x4 / 3x3 array.
    Returns ``((a00, a01, a10, a11), (t0, t1))`` as Python floats, or ``None`` for identity.
    """
    m = np.asarray(getattr(transform, "matrix", transform), dtype=np.float64)
    if m.shape not in ((3, 3), (4, 4)) or not np.all(np.isfinite(m)):
        raise ValueError(f"{where}: parameter 'to_uv' must be a finite 3x3 or 4x4 transform, "
                         f"got {m.shape} array {m.tolist()}")
    a, t = m[:2, :2], m[:2, -1]
    if np.array_equal(a, np.eye(2)) and not t.any():
        return None
    return (float(a[0, 0]), float(a[0, 1]), float(a[1, 0]), float(a[1, 1])), (float(t[0]),
                                                                              float(t[1]))


def evaluate(pattern: str, uv: mi.Point2f, to_uv: UVAffine | None = None, **params
             ) -> tuple[mi.Float, mi.Vector2f]:
    """``pattern`` (a key of :data:`PATTERNS`) at ``uv' = A uv + t`` with the chain rule
    ``grad_uv = A^T grad_uv'``; ``to_uv`` as returned by :func:`uv_affine`."""
    if pattern not in PATTERNS:
        raise ValueError(f"unknown height pattern {pattern!r}; expected one of {list(PATTERNS)}")
    fn = PATTERNS[pattern][0]
    if to_uv is None:
        return fn(uv, **params)
    (a00, a01, a10, a11), (t0, t1) = to_uv
    h, g = fn(mi.Point2f(a00 * uv.x + a01 * uv.y + t0, a10 * uv.x + a11 * uv.y + t1), **params)
    return h, mi.Vector2f(a00 * g.x + a10 * g.y, a01 * g.x + a11 * g.y)
