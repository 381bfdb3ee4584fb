"""Horizon mapping (Max 1988; Sloan and Cohen 2000): bump shading plus self-shadows.

Per texel T and azimuth phi_k = 2 pi k / n_azimuth, the horizon elevation

    beta(T, phi_k) = max_{0 < r <= r_max} atan((z(T + r u_k) - z(T)) / r),   z = -D (1 - H)

(tile units; u_k the unit tile-space direction) is found by marching r in steps of one
texel.  At render time P (no texture offset: horizon mapping has no occlusion or
silhouettes) is lit from L iff the light's elevation pi/2 - theta_L exceeds the horizon
interpolated at phi_L.  Shading: the nested BSDF with the height field's normal at T (bump
mapping).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np


def horizon_table(heights: np.ndarray, D: float, n_azimuth: int, max_distance: float = 0.5
                  ) -> np.ndarray:
    """Horizon elevation angles [rad] in [0, pi/2), shape (n_azimuth, res_y, res_x).

    Args:
        heights: (res_y, res_x) in [0, 1], periodic.
        D: depth [tile units].
        n_azimuth: azimuth samples.
        max_distance: march length r_max [tile units] (the horizon beyond it is ignored).
    """
    ry, rx = heights.shape
    if D == 0.0:
        return np.zeros((n_azimuth, ry, rx), np.float32)
    tex = mi.Texture2f(mi.TensorXf(np.ascontiguousarray(heights[..., None], np.float32)),
                       use_accel=False, wrap_mode=dr.WrapMode.Repeat)
    n = n_azimuth * ry * rx
    idx = dr.arange(mi.UInt32, n)
    x, y, k = idx % rx, (idx // rx) % ry, idx // (rx * ry)
    T = mi.Point2f((mi.Float(x) + 0.5) / rx, (mi.Float(y) + 0.5) / ry)
    s, c = dr.sincos(mi.Float(k) * (2 * math.pi / n_azimuth))
    z0 = -D * (1.0 - tex.eval(T)[0])
    dstep = 1.0 / max(rx, ry)
    n_steps = max(1, int(math.ceil(max_distance / dstep)))

    def body(i, best):
        r = mi.Float(i + 1) * dstep
        z = -D * (1.0 - tex.eval(mi.Point2f(T.x + r * c, T.y + r * s))[0])
        return i + 1, dr.maximum(best, dr.atan2(z - z0, r))

    _, best = dr.while_loop(state=(mi.UInt32(0), dr.zeros(mi.Float, n)),
                            cond=lambda i, best: i < n_steps, body=body,
                            labels=("i", "best"), label="horizon_march")
    return np.asarray(best, np.float32).reshape(n_azimuth, ry, rx)


@dataclass(init=False, eq=False)   # its fields a PyTree, so a frozen frame finds the texture
class HorizonLookup:
    """The horizon table as a wrapped trilinear texture over (phi, y, x)."""
    n_azimuth: int
    tex: mi.Texture3f
    nbytes: int

    def __init__(self, table: np.ndarray):
        self.n_azimuth = table.shape[0]
        self.tex = mi.Texture3f(mi.TensorXf(np.ascontiguousarray(table[..., None])),
                                use_accel=False, wrap_mode=dr.WrapMode.Repeat)
        self.nbytes = table.size * 4

    def beta(self, T: mi.Point2f, phi: mi.Float) -> mi.Float:
        z = phi * (1.0 / (2 * math.pi)) + 0.5 / self.n_azimuth
        return self.tex.eval(mi.Point3f(T.x - dr.floor(T.x), T.y - dr.floor(T.y),
                                        z - dr.floor(z)))[0]
