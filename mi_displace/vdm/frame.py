"""The local texture-tile frame of a surface point and mesostructure shading (§3.2).

At a surface interaction on the coarse (reference) mesh, one texture tile spans
``J = [dp/du / tiling_u, dp/dv / tiling_v]`` (world units per tile unit, 3x2).  Directions
are expressed in it: the polar angle theta from the shading normal, the azimuth phi of the
tangential part in tile space (from the texture's x axis), and the tile-space vector that
one world unit of that tangential direction covers.  The mesostructure point at tile
coordinate T lies at ``r(T) = P + J T - depth (1 - H(T)) n``, whose normal
``(J_1 + depth H_1 n) x (J_2 + depth H_2 n)`` shades the nested BSDF (the height field's
normal of the paper's pixel shading step).  Shared by VDM, horizon and relief mapping.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mi_displace.core.texture_height import height_function


class TiledHeight:
    """H(T) and dH/dT at tile coordinates T: the texture at uv = T / tiling."""

    def __init__(self, texture: mi.Texture, tiling, fd_step_tiles: float):
        self.tiling = (float(tiling[0]), float(tiling[1]))
        self.texture = texture
        self._fn = height_function(texture, fd_step_tiles / max(self.tiling))

    def uv(self, T: mi.Point2f) -> mi.Point2f:
        return mi.Point2f(T.x / self.tiling[0], T.y / self.tiling[1])

    def __call__(self, T: mi.Point2f):
        """(H, dH/dT): unitless height in [0, 1] and its gradient per tile unit."""
        h, g = self._fn(self.uv(T))
        return h, mi.Vector2f(g.x / self.tiling[0], g.y / self.tiling[1])

    def value(self, T: mi.Point2f) -> mi.Float:
        """H only (no gradient)."""
        si = dr.zeros(mi.SurfaceInteraction3f, dr.width(T))
        si.uv = self.uv(T)
        return self.texture.eval_1(si)


class TileFrame:
    """Per-lane tile frame at ``si`` (Dr.Jit, one entry per lane).

    Attributes:
        n: unit shading normal of the coarse surface (world).
        a, b: world vectors spanned by one tile unit along T_x, T_y.
        inv: the 2x2 inverse Gram matrix of (a, b) as (g11, g12, g22).
    """

    def __init__(self, si: mi.SurfaceInteraction3f, tiling: tuple[float, float]):
        self.n = mi.Vector3f(si.sh_frame.n)
        a = si.dp_du / tiling[0]
        b = si.dp_dv / tiling[1]
        # keep only the tangential parts (dp/du is tangent to the face, not to sh_frame.n)
        self.a = a - dr.dot(a, self.n) * self.n
        self.b = b - dr.dot(b, self.n) * self.n
        e, f, g = dr.dot(self.a, self.a), dr.dot(self.a, self.b), dr.dot(self.b, self.b)
        det = dr.maximum(e * g - f * f, 1e-30)
        self.inv = (g / det, -f / det, e / det)
        self.valid = (e * g - f * f) > 1e-24 * (e * g + 1e-30)

    def to_tile(self, w: mi.Vector3f) -> mi.Vector2f:
        """Tile-space coordinates (alpha, beta) of the tangential part of world ``w``."""
        wa, wb = dr.dot(w, self.a), dr.dot(w, self.b)
        g11, g12, g22 = self.inv
        return mi.Vector2f(g11 * wa + g12 * wb, g12 * wa + g22 * wb)

    def direction(self, w: mi.Vector3f):
        """(cos theta, theta, phi, step): polar angle from n, tile-space azimuth, and the
        tile-space vector covered by one world unit along w's unit tangential direction."""
        ct = dr.clip(dr.dot(w, self.n), -1.0, 1.0)
        wt = w - dr.dot(w, self.n) * self.n
        norm = dr.norm(wt)
        unit = dr.select(norm > 1e-12, wt / dr.maximum(norm, 1e-30), dr.normalize(self.a))
        step = self.to_tile(unit)
        phi = dr.atan2(step.y, step.x)
        phi = dr.select(phi < 0, phi + dr.two_pi, phi)
        return ct, dr.acos(ct), phi, step

    def meso_normal(self, grad_T: mi.Vector2f, depth: float) -> mi.Vector3f:
        """Unit normal of the mesostructure with tile-space height gradient ``grad_T``."""
        t1 = self.a + depth * grad_T.x * self.n
        t2 = self.b + depth * grad_T.y * self.n
        m = dr.cross(t1, t2)
        m = dr.select(dr.dot(m, self.n) < 0, -m, m)
        return dr.select(self.valid & (dr.squared_norm(m) > 0), dr.normalize(m), self.n)


def shading_interaction(si: mi.SurfaceInteraction3f, uv: mi.Point2f, normal: mi.Vector3f,
                        tangent: mi.Vector3f) -> mi.SurfaceInteraction3f:
    """A copy of ``si`` at texture coordinate ``uv`` with shading frame (tangent, normal),
    ``wi`` re-expressed in it (for the nested BSDF)."""
    out = mi.SurfaceInteraction3f(si)
    wi_world = si.to_world(si.wi)
    s = tangent - dr.dot(tangent, normal) * normal
    # relative: a tangent along the normal leaves float32 rounding (~1e-7 |tangent|) here,
    # whose direction is arbitrary (not orthogonal to the normal)
    s = dr.select(dr.squared_norm(s) > 1e-10 * dr.squared_norm(tangent), dr.normalize(s),
                  mi.Frame3f(normal).s)
    out.sh_frame = mi.Frame3f(s, dr.cross(normal, s), normal)
    out.uv = uv
    out.wi = out.to_local(wi_world)
    return out
