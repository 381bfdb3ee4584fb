"""Render-time lookups of the compressed VDM and MVM (Dr.Jit textures, §3.3).

* weights W(x, y, phi): a 3-D texture of shape (n_phi, res, res, K), wrapped (x, y and
  phi are periodic), trilinear;
* E_VDM(theta, c): a 2-D texture (n_c, n_theta, K), clamped, bilinear;
* E_MVM(c): a 1-D texture (n_c, K), clamped, linear.

``h = sum_i W^i E_VDM^i`` with ``d_VDM = h / cos(theta)`` (the table stores h = d cos theta,
:mod:`mi_displace.vdm.build`) and ``theta_MVM = sum_i W^i E_MVM^i``.  Texel centres match the
sampling grids of :mod:`mi_displace.vdm.table` (texels at (i + 0.5) / res, theta centred,
phi_k = 2 pi k / n_phi, curvatures c_lo ... c_hi inclusive).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.vdm.build import VDMData


#: In-memory cache of lookups by (table key, svd_terms, mvm_terms, variant), most recent
#: last.  Reusing the very same texture buffers across scene loads keeps the traced
#: kernels identical, so Dr.Jit's kernel cache hits instead of recompiling per load.
_CACHE: dict = {}
#: Smallest cos(theta) in d = h / cos(theta) (theta_V within 0.6 deg of grazing).
MIN_COS = 0.01
CACHE_ENTRIES = 4


def cached_lookup(data: VDMData, svd_terms: int, mvm_terms: int) -> "VDMLookup":
    """A :class:`VDMLookup` for ``data``, shared with earlier loads of the same table."""
    key = (data.stats.get("key"), int(svd_terms), int(mvm_terms), mi.variant())
    if key[0] is None:
        return VDMLookup(data, svd_terms, mvm_terms)
    hit = _CACHE.pop(key, None)
    if hit is None:
        hit = VDMLookup(data, svd_terms, mvm_terms)
    _CACHE[key] = hit
    while len(_CACHE) > CACHE_ENTRIES:
        _CACHE.pop(next(iter(_CACHE)))
    return hit


@dataclass(init=False, eq=False)   # its fields a PyTree, so a frozen frame finds the textures
class VDMLookup:
    """Textures of one built table at the given term counts (svd_terms, mvm_terms)."""
    weights: mi.Texture3f
    e_vdm: mi.Texture2f
    e_mvm: mi.Texture1f
    res: int
    n_phi: int
    n_theta: int
    n_c: int
    c_lo: float
    c_hi: float
    theta_max: float
    nbytes: int

    def __init__(self, data: VDMData, svd_terms: int, mvm_terms: int):
        s = data.spec
        e_vdm, e_mvm = data.compressed.eigen_functions(svd_terms, mvm_terms)
        k = e_vdm.shape[1]
        n_c = len(data.curvatures)
        w = data.compressed.weights[:, :k].reshape(s.n_phi, s.res, s.res, k)
        self.weights = mi.Texture3f(mi.TensorXf(np.ascontiguousarray(w)), use_accel=False,
                                    wrap_mode=dr.WrapMode.Repeat)
        self.e_vdm = mi.Texture2f(mi.TensorXf(np.ascontiguousarray(e_vdm.reshape(n_c, s.n_theta, k))),
                                  use_accel=False, wrap_mode=dr.WrapMode.Clamp)
        self.e_mvm = mi.Texture1f(mi.TensorXf(np.ascontiguousarray(e_mvm.reshape(n_c, k))),
                                  use_accel=False, wrap_mode=dr.WrapMode.Clamp)
        self.res, self.n_phi, self.n_theta, self.n_c = s.res, s.n_phi, s.n_theta, n_c
        self.c_lo, self.c_hi = float(data.curvatures[0]), float(data.curvatures[-1])
        self.theta_max = (s.n_theta - 0.5) / s.n_theta * (math.pi / 2)
        self.nbytes = data.compressed.nbytes(svd_terms, mvm_terms)

    # -- texture coordinates -------------------------------------------------------------
    def _c_coord(self, c: mi.Float) -> mi.Float:
        if self.n_c == 1:
            return dr.zeros(mi.Float, dr.width(c)) + 0.5
        x = (dr.clip(c, self.c_lo, self.c_hi) - self.c_lo) / (self.c_hi - self.c_lo)
        return (x * (self.n_c - 1) + 0.5) / self.n_c

    def _w(self, T: mi.Point2f, phi: mi.Float, nearest: bool = False) -> list:
        x, y = T.x - dr.floor(T.x), T.y - dr.floor(T.y)
        if nearest:  # §3.2: nearest texel in texture space for the silhouette test
            x = (dr.floor(x * self.res) + 0.5) / self.res
            y = (dr.floor(y * self.res) + 0.5) / self.res
        z = phi * (1.0 / (2 * math.pi)) + 0.5 / self.n_phi
        return self.weights.eval(mi.Point3f(x, y, z - dr.floor(z)))

    # -- the two maps ----------------------------------------------------------------------
    def d(self, T: mi.Point2f, theta: mi.Float, phi: mi.Float, c: mi.Float) -> mi.Float:
        """d_VDM [tile units] (l / sin theta) at tile coordinate T, view (theta, phi), c."""
        w = self._w(T, phi)
        e = self.e_vdm.eval(mi.Point2f(dr.clip(theta, 0.0, math.pi / 2) * (2 / math.pi),
                                       self._c_coord(c)))
        h = dr.maximum(sum((wi * ei for wi, ei in zip(w[1:], e[1:])), w[0] * e[0]), 0.0)
        return h / dr.maximum(dr.cos(theta), MIN_COS)

    def mvm(self, T: mi.Point2f, phi: mi.Float, c: mi.Float) -> mi.Float:
        """theta_MVM [rad] from the nearest texel (silhouette test)."""
        w = self._w(T, phi, nearest=True)
        e = self.e_mvm.eval(mi.Point1f(self._c_coord(c)))
        return sum((wi * ei for wi, ei in zip(w[1:], e[1:])), w[0] * e[0])
