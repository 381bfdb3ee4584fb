"""The four per-pixel steps of VDM rendering (paper §3.2, Fig. 6).

Given a coarse-surface interaction ``si`` (texture coordinate T, view V = si.wi):

1. **silhouette determination**: ``theta_V > theta_MVM(T, phi_V, c_V)`` -> no mesostructure
   along the view ray (the pixel passes through: a Null BSDF component);
2. **real texture coordinate**: ``T' = T - d_VDM(T, theta_V, phi_V, c_V) sin(theta_V)
   (cos phi_V, sin phi_V)`` (the curved table stores l / sin theta, appendix);
3. **shadow determination** against light L: h = D (1 - H(T')), ``T'' = T' + h tan(theta_L)
   (cos phi_L, sin phi_L)``, ``d_L = d_VDM(T'', theta_L, phi_L, 0)``, lit iff
   ``d_L >= h sec(theta_L) - eps`` (curvature ignored for shadows, as in the paper);
4. **pixel shading**: the nested BSDF at T' with the height field's normal; shadowed
   pixels get ambient only (their delta-light ``eval`` is 0, while
   ``eval_diffuse_reflectance`` — the raster integrator's ambient albedo — stays).

Units: T, d, l, h, D in tile units (see :mod:`mi_displace.vdm.table`); the tile frame
(:mod:`mi_displace.vdm.frame`) converts between tile and world units, curvatures are
scaled to tile units by ``tile_size``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mi_displace.vdm.frame import TiledHeight, TileFrame, shading_interaction
from mi_displace.vdm.lookup import VDMLookup

KDIAG, KOFF = "vertex_vdm_kdiag", "vertex_vdm_koff"


@dataclass
class Footprint:
    """The result of steps 1-2 at one batch of interactions."""

    silhouette: mi.Bool
    uv: mi.Point2f          # real texture coordinate T' as uv
    T: mi.Point2f           # T' in tile units
    h: mi.Float             # depth of P' [tile units]
    normal: mi.Vector3f     # mesostructure normal at T' (world)
    tangent: mi.Vector3f
    frame: TileFrame


def view_curvature(si: mi.SurfaceInteraction3f, w: mi.Vector3f, n: mi.Vector3f,
                   active: mi.Bool) -> mi.Float:
    """c_V = V_t^T K V_t / |V_t|^2 [1 / world units] from the interpolated vertex tensor K
    (the paper's formula); the mean curvature trace(K)/2 where V is along N (0/0)."""
    kd = si.shape.eval_attribute_3(KDIAG, si, active)
    ko = si.shape.eval_attribute_3(KOFF, si, active)
    vt = w - dr.dot(w, n) * n
    kv = mi.Vector3f(kd.x * vt.x + ko.x * vt.y + ko.y * vt.z,
                     ko.x * vt.x + kd.y * vt.y + ko.z * vt.z,
                     ko.y * vt.x + ko.z * vt.y + kd.z * vt.z)
    q = dr.squared_norm(vt)
    mean = 0.5 * (kd.x + kd.y + kd.z)
    return dr.select(q > 1e-6, dr.dot(vt, kv) / dr.maximum(q, 1e-30), mean)


class VDMSteps:
    """The per-pixel algorithm over one table.

    Args:
        lookup: the compressed table's textures.
        height: the Mitsuba height texture (H in [0, 1], evaluated at uv).
        depth: mesostructure depth D [tile units]; tile_size: world size of a tile.
        tiling: (u, v) texture periods per unit uv.
        use_curvature: read the vertex curvature tensors (a vdm_mesh) or take c_V = 0.
        shadows: do step 3.
        shadow_bias: eps of step 3 in texels (scaled by sec theta_L).
        shadow_slack: relative tolerance of step 3 in units of the theta spacing: lit iff
            d_L >= h sec(theta_L) (1 - shadow_slack * dtheta) - eps sec(theta_L).  The
            table interpolates d linearly between theta samples dtheta apart, and a
            steeper ray from P'' lands earlier on a slope facing the light, so without
            this slack lit slopes show shadow acne.
    """

    def __init__(self, lookup: VDMLookup, height: mi.Texture, depth: float, tile_size: float,
                 tiling, use_curvature: bool, shadows: bool = True, shadow_bias: float = 1.0,
                 shadow_slack: float = 1.0):
        self.lookup, self.depth, self.tile_size = lookup, float(depth), float(tile_size)
        self.tiling = (float(tiling[0]), float(tiling[1]))
        self.height = TiledHeight(height, self.tiling, 0.25 / lookup.res)
        self.use_curvature, self.shadows = use_curvature, shadows
        self.eps = float(shadow_bias) / lookup.res
        self.rel = float(shadow_slack) * (math.pi / 2) / lookup.n_theta
        self.tan_max = math.tan(lookup.theta_max)

    def _view(self, si: mi.SurfaceInteraction3f, active: mi.Bool):
        """Tile frame, theta_V, phi_V, tile step of V, c_V [1/tile units] and T."""
        frame = TileFrame(si, self.tiling)
        v = si.to_world(si.wi)
        _, theta, phi, step = frame.direction(v)
        if self.use_curvature:
            c = view_curvature(si, v, frame.n, active) * self.tile_size
        else:
            c = dr.zeros(mi.Float, dr.width(theta))
        T = mi.Point2f(si.uv.x * self.tiling[0], si.uv.y * self.tiling[1])
        return frame, theta, phi, step, c, T

    def silhouette(self, si: mi.SurfaceInteraction3f, active: mi.Bool) -> mi.Bool:
        """Step 1 alone (the raster alpha test needs nothing else)."""
        _, theta, phi, _, c, T = self._view(si, active)
        return active & (theta > self.lookup.mvm(T, phi, c))

    def footprint(self, si: mi.SurfaceInteraction3f, active: mi.Bool) -> Footprint:
        """Steps 1 and 2 (and the shading normal of step 4) for the view si.wi."""
        frame, theta, phi, step, c, T = self._view(si, active)
        silhouette = active & (theta > self.lookup.mvm(T, phi, c))        # step 1
        l = self.lookup.d(T, theta, phi, c) * dr.sin(theta)                # step 2
        T2 = T - l * self.tile_size * step
        H, grad = self.height(T2)
        normal = frame.meso_normal(grad, self.depth * self.tile_size)
        uv = mi.Point2f(T2.x / self.tiling[0], T2.y / self.tiling[1])
        return Footprint(silhouette, uv, T2, self.depth * (1.0 - H), normal, frame.a, frame)

    def lit(self, fp: Footprint, w: mi.Vector3f) -> mi.Bool:
        """Step 3: is P' lit from world direction w (ignoring curvature, §3.2)?"""
        if not self.shadows or self.depth == 0.0:
            return mi.Bool(True)
        ct, theta, phi, step = fp.frame.direction(w)
        theta_c = dr.minimum(theta, self.lookup.theta_max)
        tan_l = dr.minimum(dr.tan(theta_c), self.tan_max)
        sec_l = dr.sqrt(1.0 + tan_l * tan_l)
        T3 = fp.T + fp.h * tan_l * self.tile_size * step
        d_l = self.lookup.d(T3, theta_c, phi, dr.zeros(mi.Float, dr.width(theta)))
        return (ct > 0) & (d_l >= fp.h * sec_l * (1.0 - self.rel) - self.eps * sec_l)

    def shading(self, si: mi.SurfaceInteraction3f, fp: Footprint) -> mi.SurfaceInteraction3f:
        """Step 4's interaction: the nested BSDF's view of P' (uv T', height-field normal)."""
        return shading_interaction(si, fp.uv, fp.normal, fp.tangent)
