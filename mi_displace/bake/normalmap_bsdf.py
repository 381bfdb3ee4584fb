"""``mikk_normalmap``: Mitsuba's ``normalmap`` BSDF decoding in the MikkTSpace frame.

Used exactly like ``normalmap`` (nested BSDF, ``normalmap`` texture with ``raw``), but the
texture's ``(x + 1) / 2`` colours (``green="-y"``: DirectX, y negated) are decoded in the MikkTSpace frame the baker (Blender,
Unity, Unreal) used: :func:`mi_displace.bake.mitsuba_frames.mikk_decode` with the per-vertex
tangents our MikkTSpace port computes on the shape (:meth:`MikkNormalMap.prepare_shape`; the
mi-displace loaders call it, Python users call
:func:`mi_displace.bake.mitsuba_frames.prepare_scene` after ``mi.load_*``).  The shading
frame's ``s`` then follows ``dp/du`` as in ``normalmap.cpp``.
"""
from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi

from mi_displace.bake import mitsuba_frames as frames
from mi_displace.core.texture_height import warn_if_srgb
from mi_displace.vdm.mesostructure import nested_objects


class MikkNormalMap(mi.BSDF):
    """A nested BSDF under the MikkTSpace-decoded normal of a tangent-space map."""

    def __init__(self, props: mi.Properties, values: dict):
        super().__init__(props)
        self.normalmap = values["normalmap"]
        self.flip_green = values["green"] == "-y"
        warn_if_srgb(self.normalmap, "mikk_normalmap", "normalmap")
        bsdfs = nested_objects(props, mi.BSDF)
        if len(bsdfs) != 1:
            raise ValueError(f"mikk_normalmap: expected exactly one nested BSDF, got {len(bsdfs)}")
        self.nested = bsdfs[0][1]
        self.m_components = [self.nested.flags(i) for i in range(self.nested.component_count())]
        self.m_flags = int(self.nested.flags()) | int(mi.BSDFFlags.SpatiallyVarying)
        self.prepared = 0
        self.warned = False

    def prepare_shape(self, shape: mi.Shape) -> bool:
        """Add the MikkTSpace attributes to ``shape`` (once; ValueError naming it if it is not
        a mesh with UVs and vertex normals); True when its vertices were split."""
        self.prepared += 1
        if shape.has_attribute(frames.ATTR_TANGENT):
            return False
        return frames.add_mikktspace(shape, shape.id())

    def setup_problem(self) -> str | None:
        """One line when no shape was given the MikkTSpace frame (see :meth:`prepare_shape`)."""
        if self.prepared:
            return None
        return ("mikk_normalmap: no shape was given its MikkTSpace tangents: call "
                "mi_displace.bake.mitsuba_frames.prepare_scene(scene) after loading")

    def frame(self, si: mi.SurfaceInteraction3f, active=True) -> mi.Frame3f:
        """The perturbed shading frame (normalmap.cpp's ``frame()``, MikkTSpace decode).

        Unprepared (no shape has the attributes; they would read as zeros), it is the
        unperturbed frame, after one warning naming the fix: never an exception inside a
        trace, which also traces the BSDFs of other scenes (``docs/platform.md``)."""
        problem = self.setup_problem()
        if problem:
            if not self.warned:
                self.warned = True
                warnings.warn(problem + "; rendering without the normal map")
                mi.Log(mi.LogLevel.Warn, problem)
            return mi.Frame3f(si.sh_frame)
        x = mi.Vector3f(self.normalmap.eval_3(si, active) * 2.0 - 1.0)
        if self.flip_green:   # DirectX: G = 1 - G, so y = -y
            x.y = -x.y
        shape = si.shape
        t = shape.eval_attribute_3(frames.ATTR_TANGENT, si, active)
        sign = shape.eval_attribute_1(frames.ATTR_SIGN, si, active)
        n = shape.eval_attribute_3(frames.ATTR_NORMAL, si, active)
        result = mi.Frame3f(frames.mikk_decode(x, mi.Vector3f(t), sign, mi.Vector3f(n)))
        result.s = dr.normalize(si.dp_du - result.n * dr.dot(result.n, si.dp_du))
        result.t = dr.cross(result.n, result.s)
        return result

    def _perturbed(self, si, active) -> mi.SurfaceInteraction3f:
        perturbed = mi.SurfaceInteraction3f(si)
        perturbed.sh_frame = self.frame(si, active)
        perturbed.wi = perturbed.to_local(si.to_world(si.wi))
        return perturbed

    def sample(self, ctx, si, sample1, sample2, active=True):
        perturbed = self._perturbed(si, active)
        bs, weight = self.nested.sample(ctx, perturbed, sample1, sample2, active)
        wo_world = perturbed.to_world(bs.wo)
        wo = si.to_local(wo_world)
        # the sampled direction must lie on the same side in both frames (normalmap.cpp)
        active &= mi.Frame3f.cos_theta(bs.wo) * mi.Frame3f.cos_theta(wo) > 0
        bs.wo = wo
        return bs, dr.select(active, weight, 0.0)

    def _to_perturbed(self, si, wo, active):
        """The perturbed interaction, ``wo`` in its frame, and the lanes where ``wo`` lies on
        the same side in both frames (normalmap.cpp)."""
        perturbed = self._perturbed(si, active)
        wo_p = perturbed.to_local(si.to_world(wo))
        return perturbed, wo_p, active & (mi.Frame3f.cos_theta(wo) * mi.Frame3f.cos_theta(wo_p) > 0)

    def eval(self, ctx, si, wo, active=True):
        perturbed, wo_p, active = self._to_perturbed(si, wo, active)
        return dr.select(active, self.nested.eval(ctx, perturbed, wo_p, active), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        perturbed, wo_p, active = self._to_perturbed(si, wo, active)
        return dr.select(active, self.nested.pdf(ctx, perturbed, wo_p, active), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        perturbed, wo_p, active = self._to_perturbed(si, wo, active)
        value, pdf = self.nested.eval_pdf(ctx, perturbed, wo_p, active)
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

    def traverse(self, cb):
        cb.put("normalmap", self.normalmap, mi.ParamFlags.Differentiable)
        cb.put("nested_bsdf", self.nested, mi.ParamFlags.Differentiable)

    def to_string(self):
        return f"MikkNormalMap[prepared shapes={self.prepared}, nested={self.nested}]"
