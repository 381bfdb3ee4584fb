"""Curvature resampling of the zero-curvature VDM (paper appendix, Fig. 3).

In the plane of the normal and the view azimuth, a flat hit at tangential distance ``l``
and depth ``h`` below P moves, when the reference surface is bent to curvature ``c``
(tile units^-1, convex > 0, centre of curvature below), to

    x = (1/c - h) sin(c l) = l sinc(c l) - h sin(c l)
    y = (1/c - h) cos(c l) - 1/c = -l sin(c l / 2) sinc(c l / 2) - h cos(c l)

(stable forms: c -> 0 gives x = l, y = -h exactly).  Its new polar angle is
``theta' = atan2(x, -y)``.  The texture offset of the hit is unchanged by bending (l is an
arc length on the reference surface), so the curved VDM stores ``d = l / sin(theta')``
(appendix) and the render-time offset is ``d sin(theta_V) (cos phi, sin phi) = l (...)``.

Resampling (appendix): the non-uniform (theta', d) pairs are interpolated linearly at the
uniform theta grid; a pair whose theta' is not larger than every earlier kept theta' is
occluded after bending and dropped; for c > 0 every theta beyond the largest kept theta'
has no intersection (-1).  The maximal view polar angle (MVM, §3.3) is that largest kept
theta' (pi/2 for c <= 0, where every ray reaches the mesostructure).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.vdm import mvm as mvm_mod


def sinc(x):
    """sin(x)/x with sinc(0) = 1 (Dr.Jit or NumPy)."""
    if isinstance(x, np.ndarray) or np.isscalar(x):
        return np.sinc(np.asarray(x) / np.pi)
    small = dr.abs(x) < 1e-4
    return dr.select(small, 1.0 - x * x / 6.0, dr.sin(x) / dr.select(small, 1.0, x))


def bend(l, h, c):
    """Position (x, y) of a flat hit (l, h) after bending to curvature c (module doc).

    Works on Dr.Jit floats or NumPy arrays; l, h, x, y in tile units, c in 1/tile units.
    """
    s = dr.sin(c * l) if not isinstance(l, np.ndarray) else np.sin(c * l)
    cs = dr.cos(c * l) if not isinstance(l, np.ndarray) else np.cos(c * l)
    half = c * l * 0.5
    sh = dr.sin(half) if not isinstance(l, np.ndarray) else np.sin(half)
    x = l * sinc(c * l) - h * s
    y = -l * sh * sinc(half) - h * cs
    return x, y


def curvature_grid(c_lo: float, c_hi: float, n_c: int) -> np.ndarray:
    """Curvature samples [1/tile units]: n_c values from c_lo to c_hi inclusive (1 if equal)."""
    if n_c == 1:
        return np.array([0.5 * (c_lo + c_hi)], np.float64)
    return np.linspace(c_lo, c_hi, n_c)


def resample(t_flat: mi.Float, n_rows: int, theta_src: np.ndarray, theta_dst: np.ndarray,
             curvatures: np.ndarray, D: float, floor_depth: float | None = None
             ) -> tuple[mi.Float, mi.Float]:
    """Curved VDM and MVM from the flat distances (appendix).

    Args:
        t_flat: flat distances, ``n_rows * len(theta_src)`` entries, row-major
            (row = (phi, y, x), then theta_src); -1 marks a miss.
        theta_src: polar angles [rad] of the flat samples (ascending).
        theta_dst: the table's polar angle grid [rad] (ascending).
        curvatures: curvature samples [1/tile units], shape (n_c,).
        D: depth in tile units (points deeper than the centre of curvature are dropped).
        floor_depth: depth of the deepest mesostructure point, D (1 - min H) (default D).

    Returns:
        ``(d, theta_mvm)``: ``d`` has ``n_rows * n_c * n_dst`` entries ordered
        (row, c, theta) in tile units, where the entries with no intersection (the
        paper's -1, i.e. theta > theta_mvm) hold the value at the MVM angle instead
        (:func:`mi_displace.vdm.mvm.with_invalid` restores the -1); ``theta_mvm`` has
        ``n_rows * n_c`` entries (row, c) in radians.
    """
    n_src, n_dst, n_c = len(theta_src), len(theta_dst), len(curvatures)
    # the angles as float32 arrays read in the loops (symbolic loops over the angles: one
    # kernel per pass whatever n_src and n_dst, not an unrolled n_dst x n_src one)
    sin_src, cos_src, dst = (mi.Float(np.asarray(a, np.float32))
                             for a in (np.sin(theta_src), np.cos(theta_src), theta_dst))
    n = n_rows * n_c
    idx = dr.arange(mi.UInt32, n)
    row, ci = idx // n_c, idx % n_c
    c = dr.gather(mi.Float, mi.Float(np.asarray(curvatures, np.float32)), ci)
    # pass 1: bend every flat sample (theta' and d of each (row, c, i)); a sample is kept
    # when its theta' exceeds every earlier kept one (a running maximum along i)
    kept_theta, kept_val = dr.empty(mi.Float, n * n_src), dr.empty(mi.Float, n * n_src)
    kept_any = dr.empty(mi.Bool, n * n_src)

    def bend_step(i, running):
        t = dr.gather(mi.Float, t_flat, row * n_src + i)
        l, h = t * dr.gather(mi.Float, sin_src, i), t * dr.gather(mi.Float, cos_src, i)
        x, y = bend(l, h, c)
        th = dr.atan2(x, -y)
        val = dr.select(l > 1e-7, l / dr.maximum(dr.sin(th), 1e-7), dr.sqrt(x * x + y * y))
        valid = ((t >= 0) & (1.0 - c * h > 0) & (th >= 0) & (th > running)
                 & (th < math.pi / 2 + 1e-6))
        at = idx * n_src + i
        dr.scatter(kept_theta, th, at)
        dr.scatter(kept_val, val, at)
        dr.scatter(kept_any, valid, at)
        return i + 1, dr.select(valid, th, running)

    _, running = dr.while_loop((dr.zeros(mi.UInt32, n), dr.full(mi.Float, -1.0, n)),
                               lambda i, running: i < n_src, bend_step)
    theta_mvm = mvm_mod.maximal_view_angle(running, c, D if floor_depth is None else floor_depth)
    # pass 2: per (row, c, j), linear interpolation of the kept (theta', d) at theta_dst[j]
    lane = dr.arange(mi.UInt32, n * n_dst)
    base, target = lane // n_dst * n_src, dr.gather(mi.Float, dst, lane % n_dst)

    def lerp_step(i, out, first_val, found_first, prev_th, prev_val, have_prev, last_val):
        v, th = dr.gather(mi.Float, kept_val, base + i), dr.gather(mi.Float, kept_theta, base + i)
        ok = dr.gather(mi.Bool, kept_any, base + i)
        first_val = dr.select(ok & ~found_first, v, first_val)
        seg = ok & have_prev & (prev_th <= target) & (target < th) & (out < 0)
        w = (target - prev_th) / dr.maximum(th - prev_th, 1e-12)
        return (i + 1, dr.select(seg, dr.lerp(prev_val, v, w), out), first_val, found_first | ok,
                dr.select(ok, th, prev_th), dr.select(ok, v, prev_val), have_prev | ok,
                dr.select(ok, v, last_val))

    m = n * n_dst
    start = (dr.zeros(mi.UInt32, m), dr.full(mi.Float, -1.0, m), dr.full(mi.Float, -1.0, m),
             dr.full(mi.Bool, False, m), dr.zeros(mi.Float, m), dr.zeros(mi.Float, m),
             dr.full(mi.Bool, False, m), dr.full(mi.Float, -1.0, m))
    _, out, first_val, found_first, prev_th, _, _, last_val = dr.while_loop(
        start, lambda i, *_: i < n_src, lerp_step)
    # below the first kept angle: hold the first value; beyond the last: -1 if the angle
    # exceeds the MVM (no intersection), else hold the last value
    out = dr.select(found_first & (out < 0) & (target < prev_th), first_val, out)
    # -1 entries (target > theta_mvm) are replaced by the value at the MVM angle, a smooth
    # continuation for the SVD (§3.3); the MVM keeps the silhouette
    out = dr.select(found_first & (out < 0) & (target >= prev_th), last_val, out)
    return dr.select(found_first, out, 0.0), theta_mvm
