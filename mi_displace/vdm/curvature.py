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
    idx = dr.arange(mi.UInt32, n_rows * n_c)
    row, ci = idx // n_c, idx % n_c
    c = dr.gather(mi.Float, mi.Float(np.asarray(curvatures, np.float32)), ci)
    kept_theta, kept_val, kept_any = [], [], []
    running = mi.Float(-1.0)
    for i in range(n_src):  # loop over the (small) theta dimension, not over elements
        t = dr.gather(mi.Float, t_flat, row * n_src + i)
        st, ct = math.sin(theta_src[i]), math.cos(theta_src[i])
        l, h = t * st, t * ct
        x, y = bend(l, h, c)
        th = dr.atan2(x, -y)
        r = dr.sqrt(x * x + y * y)
        val = dr.select(l > 1e-7, l / dr.maximum(dr.sin(th), 1e-7), r)
        valid = ((t >= 0) & (1.0 - c * h > 0) & (th >= 0) & (th > running)
                 & (th < math.pi / 2 + 1e-6))
        running = dr.select(valid, th, running)
        kept_theta.append(th)
        kept_val.append(val)
        kept_any.append(valid)
    theta_mvm = mvm_mod.maximal_view_angle(running, c, D if floor_depth is None else floor_depth)
    outputs = []
    for j in range(n_dst):
        target = float(theta_dst[j])
        out = mi.Float(-1.0)
        first_val = mi.Float(-1.0)
        found_first = mi.Bool(False)
        prev_th, prev_val, have_prev = mi.Float(0.0), mi.Float(0.0), mi.Bool(False)
        last_val = mi.Float(-1.0)
        for i in range(n_src):
            v, th, ok = kept_val[i], kept_theta[i], kept_any[i]
            first_val = dr.select(ok & ~found_first, v, first_val)
            found_first |= ok
            seg = ok & have_prev & (prev_th <= target) & (target < th) & (out < 0)
            w = (target - prev_th) / dr.maximum(th - prev_th, 1e-12)
            out = dr.select(seg, dr.lerp(prev_val, v, w), out)
            prev_th = dr.select(ok, th, prev_th)
            prev_val = dr.select(ok, v, prev_val)
            have_prev |= ok
            last_val = dr.select(ok, v, last_val)
        # below the first kept angle: hold the first value; beyond the last: -1 if the
        # angle exceeds the MVM (no intersection), else hold the last value
        below = found_first & (out < 0) & (target < prev_th)
        out = dr.select(below, first_val, out)
        beyond = found_first & (out < 0) & (target >= prev_th)
        # -1 entries (target > theta_mvm) are replaced by the value at the MVM angle, a
        # smooth continuation for the SVD (§3.3); the MVM keeps the silhouette
        out = dr.select(beyond, last_val, out)
        out = dr.select(found_first, out, 0.0)
        outputs.append(out)
    d = dr.zeros(mi.Float, n_rows * n_c * n_dst)
    for j, out in enumerate(outputs):
        dr.scatter(d, out, idx * n_dst + j)
    return d, theta_mvm
