"""The four per-pixel steps of VDM rendering (paper §3.2, Fig. 6).

Given a coarse-surface interaction ``si`` (texture coordinate T, view V = si.wi):

1. **silhouette determination**: ``theta_V > theta_MVM(T, phi_V, c_V)`` -> no mesostructure
   along the view ray (the pixel passes through: a Null BSDF component);
2. **real texture coordinate**: ``T' = T - d_VDM(T, theta_V, phi_V, c_V) sin(theta_V)
   (cos phi_V, sin phi_V)`` (the curved table stores l / sin theta, appendix), then refined
   to the ray's first crossing of the height field near it (:meth:`VDMSteps._refine`, our
   addition: without it 20 % of the pixels of a grazing view shade slopes facing away);
3. **shadow determination** against light L: h = D (1 - H(T')), ``T'' = T' + h tan(theta_L)
   (cos phi_L, sin phi_L)``, ``d_L = d_VDM(T'', theta_L, phi_L, 0)``, shadowed iff
   ``d_L < h sec(theta_L)`` (curvature ignored for shadows, as in the paper) and the light
   ray between that hit and P' really passes through the relief
   (:meth:`VDMSteps._occluded`, our addition, instead of a tolerance);
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
from mi_displace.vdm.relief import first_crossing

#: Face attributes written by ``vdm_mesh`` (:func:`mi_displace.vdm.mesh_curvature.tile_forms`).
FACE_FORMS = {"q": "face_vdm_q", "q_du": "face_vdm_q_du", "q_dv": "face_vdm_q_dv",
              "uv": "face_vdm_uv"}
#: Bisection steps after the linear search of the T' refinement (VDMSteps._refine).
REFINE_BISECTIONS = 5
#: Depth [units of D] by which a point of the light ray must lie inside the relief for
#: VDMSteps._occluded to keep a shadow (float32 rounding of s cos(theta) is ~1e-7 s).
OCCLUSION_MARGIN = 1e-5


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
    tile: mi.Float          # world size of one tile here [world units]


def placement_scale(si: mi.SurfaceInteraction3f, active: mi.Bool) -> mi.Float:
    """s: world length per unit of the ``vdm_mesh``'s own space at ``si`` (its to_world or
    an instance's transform), sqrt(|dp/du x dp/dv| of ``si`` / the face's own, stored in
    ``face_vdm_uv``); 1 where the face has no uv area."""
    own = si.shape.eval_attribute_3(FACE_FORMS["uv"], si, active).z
    world = dr.norm(dr.cross(si.dp_du, si.dp_dv))
    return dr.select(own > 0, dr.sqrt(world / dr.maximum(own, 1e-30)), 1.0)


def view_curvature(si: mi.SurfaceInteraction3f, frame: TileFrame, w: mi.Vector3f,
                   s: mi.Float, active: mi.Bool) -> mi.Float:
    """c_V [1 / tile units] along world direction w: the paper's V_t^T K V_t / |V_t|^2,
    from the tile-coordinate form Q of :func:`mi_displace.vdm.mesh_curvature.tile_forms`
    (linear in uv per face) as s^2 t^T Q t / |V_t|^2 with t the tile coordinates of V_t —
    invariant to rotations and uniform scales of the mesh's placement (instances).  Where
    V is along N (0/0): the mean curvature, s^2 tr(G^-1 Q) / 2."""
    get = lambda key: si.shape.eval_attribute_3(FACE_FORMS[key], si, active)
    centre = get("uv")
    q = get("q") + get("q_du") * (si.uv.x - centre.x) + get("q_dv") * (si.uv.y - centre.y)
    vt = w - dr.dot(w, frame.n) * frame.n
    t = frame.to_tile(vt)
    num = q.x * t.x * t.x + 2.0 * q.y * t.x * t.y + q.z * t.y * t.y
    norm2 = dr.squared_norm(vt)
    g11, g12, g22 = frame.inv
    mean = 0.5 * (g11 * q.x + 2.0 * g12 * q.y + g22 * q.z)
    return s * s * dr.select(norm2 > 1e-6, num / dr.maximum(norm2, 1e-30), mean)


@dataclass(init=False, eq=False)   # its fields a PyTree, so a frozen frame finds the table's textures
class VDMSteps:
    """The per-pixel algorithm over one table.

    Args:
        lookup: the compressed table's textures.
        height: the Mitsuba height texture (H in [0, 1], evaluated at uv).
        depth: mesostructure depth D [tile units]; tile_size: size of a tile in the mesh's
            own units (times the placement scale of :func:`placement_scale` on a vdm_mesh).
        tiling: (u, v) texture periods per unit uv.
        use_curvature: read the vertex curvature tensors (a vdm_mesh) or take c_V = 0.
        shadows: do step 3.
        shadow_bias: eps of step 3 in texels (scaled by sec theta_L).
        shadow_slack: relative tolerance of step 3 in units of the theta spacing: lit iff
            d_L >= h sec(theta_L) (1 - shadow_slack * dtheta) - eps sec(theta_L).  The
            table interpolates d linearly between theta samples dtheta apart, and a
            steeper ray from P'' lands earlier on a slope facing the light, so without
            this slack lit slopes show shadow acne.
        refine_steps, refine_window: the T' refinement of :meth:`_refine` (0 steps: the
            paper's plain lookup).
        shadow_verify: points of the check of :meth:`_occluded` (0: the paper's test alone;
            then a slack of 1 and a bias of 1 texel are needed against false shadows).
    """
    lookup: VDMLookup
    depth: float
    tile_size: float
    tiling: tuple
    height: TiledHeight
    use_curvature: bool
    shadows: bool
    eps: float
    rel: float
    tan_max: float
    refine_steps: int
    refine_window: float
    shadow_verify: int

    def __init__(self, lookup: VDMLookup, height: mi.Texture, depth: float, tile_size: float,
                 tiling, use_curvature: bool, shadows: bool = True, shadow_bias: float = 0.0,
                 shadow_slack: float = 0.0, refine_steps: int = 8,
                 refine_window: float = 0.5, shadow_verify: int = 3):
        self.lookup, self.depth, self.tile_size = lookup, float(depth), float(tile_size)
        self.tiling = (float(tiling[0]), float(tiling[1]))
        self.height = TiledHeight(height, self.tiling, 0.25 / lookup.res)
        self.use_curvature, self.shadows = use_curvature, shadows
        self.eps = float(shadow_bias) / lookup.res
        self.rel = float(shadow_slack) * (math.pi / 2) / lookup.n_theta
        self.tan_max = math.tan(lookup.theta_max)
        self.refine_steps, self.refine_window = int(refine_steps), float(refine_window)
        self.shadow_verify = int(shadow_verify)

    def _view(self, si: mi.SurfaceInteraction3f, active: mi.Bool):
        """Tile frame, theta_V, phi_V, tile step of V, c_V [1/tile units], T and the world
        size of one tile here."""
        frame = TileFrame(si, self.tiling)
        v = si.to_world(si.wi)
        _, theta, phi, step = frame.direction(v)
        if self.use_curvature:
            s = placement_scale(si, active)
            c = view_curvature(si, frame, v, s, active)
            tile = self.tile_size * s
        else:
            c = dr.zeros(mi.Float, dr.width(theta))
            tile = dr.full(mi.Float, self.tile_size, dr.width(theta))
        T = mi.Point2f(si.uv.x * self.tiling[0], si.uv.y * self.tiling[1])
        return frame, theta, phi, step, c, T, tile

    def silhouette(self, si: mi.SurfaceInteraction3f, active: mi.Bool) -> mi.Bool:
        """Step 1 alone (the raster alpha test needs nothing else)."""
        _, theta, phi, _, c, T, _ = self._view(si, active)
        return active & (theta > self.lookup.mvm(T, phi, c))

    def footprint(self, si: mi.SurfaceInteraction3f, active: mi.Bool) -> Footprint:
        """Steps 1 and 2 (and the shading normal of step 4) for the view si.wi."""
        frame, theta, phi, step, c, T, tile = self._view(si, active)
        silhouette = active & (theta > self.lookup.mvm(T, phi, c))        # step 1
        d = self.lookup.d(T, theta, phi, c)                                 # step 2
        st, ct = dr.sin(theta), dr.cos(theta)
        dir_T = step * tile               # tile coordinates per tile unit along V_t
        if self.refine_steps > 0 and self.depth > 0:
            d = self._refine(T, st, ct, dir_T, c, d, ~silhouette & active)
        T2 = T - d * st * dir_T
        H, grad = self.height(T2)
        normal = frame.meso_normal(grad, self.depth * tile)
        uv = mi.Point2f(T2.x / self.tiling[0], T2.y / self.tiling[1])
        return Footprint(silhouette, uv, T2, self.depth * (1.0 - H), normal, frame.a, frame,
                         tile)

    def _refine(self, T, st, ct, dir_T, c, d, active):
        """T' refinement (our addition, not in the paper): the first crossing of the view
        ray with the height field in a window around the table's distance ``d``.

        The interpolated table puts T' a few percent off along the ray; near a relief edge
        that lands P' on a slope facing away from the viewer, which no visible point can
        be.  The ray at distance s (tile units) from P lies ``s cos(theta) - c (s
        sin(theta))^2 / 2`` below the (curved) reference surface; a linear search over
        ``[d (1 - w) - 1 texel, d (1 + w) + 1 texel]`` (w = ``refine_window``, from 0 when
        the ray is already below the relief at the window's start) and bisection find
        where it enters the relief, so the shading point faces the viewer.  Where the
        window holds no crossing the table's value is kept.
        """
        D = self.depth

        def below(s):
            x = s * st
            T_s = mi.Point2f(T.x - x * dir_T.x, T.y - x * dir_T.y)
            return s * ct - 0.5 * c * x * x >= D * (1.0 - self.height.value(T_s))

        pad = 1.0 / self.lookup.res
        lo = dr.maximum(d * (1.0 - self.refine_window) - pad, 0.0)
        lo = dr.select(below(lo), 0.0, lo)
        hi = d * (1.0 + self.refine_window) + pad
        s, found = first_crossing(below, lo, hi, self.refine_steps, REFINE_BISECTIONS,
                                  label="vdm_refine", active=active)
        return dr.select(active & found, s, d)

    def lit(self, fp: Footprint, w: mi.Vector3f, active: mi.Bool = True) -> mi.Bool:
        """Step 3: is P' lit from world direction w (ignoring curvature, §3.2)?  The shadow
        check runs on the ``active`` lanes that face the light only (the others' answers
        are not read), under a symbolic if: a SIMD packet without such a lane skips the
        table lookup; so does the check of a table shadow for a packet without one."""
        if not self.shadows or self.depth == 0.0:
            return mi.Bool(True)
        ct, theta, phi, step = fp.frame.direction(w)

        def blocked(theta, phi, step, T, h, tile, mask):
            theta_c = dr.minimum(theta, self.lookup.theta_max)
            tan_l = dr.minimum(dr.tan(theta_c), self.tan_max)
            sec_l = dr.sqrt(1.0 + tan_l * tan_l)
            T3 = T + h * tan_l * tile * step
            d_l = self.lookup.d(T3, theta_c, phi, dr.zeros(mi.Float, dr.width(theta)))
            s_p = h * sec_l               # distance from P'' to P' along the light ray
            hit = mask & (d_l < s_p * (1.0 - self.rel) - self.eps * sec_l)
            if self.shadow_verify > 0:
                hit = dr.if_stmt((T3, tan_l, sec_l, step * tile, d_l, s_p, hit), hit,
                                 lambda *args: (self._occluded(*args),), lambda *args: (args[-1],),
                                 label="vdm_shadow_verify")[0]
            return (hit,)

        facing = mi.Bool(active) & (ct > 0)
        shadow = dr.if_stmt((theta, phi, step, fp.T, fp.h, fp.tile, facing), facing, blocked,
                            lambda *args: (dr.zeros(mi.Bool, dr.width(args[-1])),),
                            label="vdm_shadow")[0]
        return (ct > 0) & ~shadow

    def _occluded(self, T3, tan_l, sec_l, dir_T, d_l, s_p, active):
        """Check of a table shadow (our addition): some of ``shadow_verify`` points of the
        light ray between the table's hit (distance d_L from P'') and P' lie inside the
        relief.  Interpolated d_L lands short of P' on lit slopes the ray skims; there
        the ray between the two stays above the relief and the shadow is dropped."""
        D = self.depth
        ct = 1.0 / sec_l
        st = tan_l * ct
        k = self.shadow_verify
        inside = dr.zeros(mi.Bool, dr.width(d_l))
        for j in range(1, k + 1):  # k fixed points per pixel, not a loop over elements
            s = d_l + (s_p - d_l) * ((j - 0.5) / k)
            x = s * st
            T_s = mi.Point2f(T3.x - x * dir_T.x, T3.y - x * dir_T.y)
            # inside by more than float32 rounding: on a flat floor the light ray ends on
            # it, and a tie there shadowed ~4 % of the lit directions
            inside |= s * ct > D * (1.0 - self.height.value(T_s)) + OCCLUSION_MARGIN * D
        return active & inside

    def shading(self, si: mi.SurfaceInteraction3f, fp: Footprint) -> mi.SurfaceInteraction3f:
        """Step 4's interaction: the nested BSDF's view of P' (uv T', height-field normal)."""
        return shading_interaction(si, fp.uv, fp.normal, fp.tangent)
