"""The BSDFs of the slicing family, seen through their proxy's walls (a null pass-through
where the ray finds nothing): the slices of the displacement volume (paper 002 §3) and the
depth object / visual hull (§4, §5), with the depth object's view-dependent colour (§4.2).

Their shapes (``plugins/slicing.py``, ``plugins/depth_object.py``) build the model and hand
it to the BSDF; the walks themselves are :mod:`mi_displace.slicing.sliced` and
:mod:`mi_displace.slicing.depth_object`.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.slicing import depth_object as dobj
from mi_displace.vdm.frame import shading_interaction
from mi_displace.vdm.mesostructure import MesostructureBSDF, read_shared


class _Prepared:
    """The last interaction's walk (:meth:`SlicingBSDF._prepare`): its variables' indices,
    the variables (kept alive, so the indices are not reused) and the result.  A plain
    object, not a PyTree, on purpose: a frozen frame (``raster``'s ``freeze``) traverses the
    BSDF's attributes as its inputs, and the symbolic variables of an earlier trace are no
    input (Dr.Jit refused: "jit_var_schedule(): not permitted")."""

    def __init__(self):
        self.key, self.alive, self.result = None, None, None


class SlicingBSDF(MesostructureBSDF):
    """The α-tested slices of a :class:`SlicedVolume` seen through the volume's walls.

    Subclasses implement ``_walk(si, active)`` (the ``_prepare`` of MesostructureBSDF,
    computed once per interaction) and ``_lit``."""

    PLUGIN = "slicing"
    HAS_SILHOUETTE = True

    def __init__(self, props: mi.Properties, model):
        super().__init__(props, read_shared(props, self.PLUGIN))
        self.model = model   # a SlicedVolume (or a DepthObject in the subclass)
        self.self_shadows = bool(props.get("self_shadows", True))
        self._cache = _Prepared()

    def set_model(self, model) -> None:
        """Draw ``model`` from now on (a rebuilt volume); the last walk is forgotten."""
        self.model = model
        self._cache = _Prepared()

    def _facing(self, w):
        # the proxy is the volume's boundary: the fragment's own normal decides (nested BSDF)
        return dr.full(mi.Bool, True, dr.width(w))

    def _prepare(self, si, active):
        # Mitsuba asks eval, eval_null_transmission and eval_diffuse_reflectance of the same
        # interaction in one kernel: walk the slices once per interaction (all valid lanes,
        # so a later call's mask is always covered); the cache keeps si's variables alive,
        # so their JIT indices cannot be reused by another interaction.  Each vectorised
        # call gets its own copies of si: the walk is shared by queries made in one
        # dispatch (the raster integrator's shading asks eval and eval_diffuse_reflectance so,
        # raster.shade_hit).
        key = (si.t.index, si.p.x.index, si.wi.x.index)
        if self._cache.key == key:
            return self._cache.result
        result = self._walk(si, si.is_valid())
        self._cache.key, self._cache.alive, self._cache.result = key, (si.t, si.p, si.wi), result
        return result

    def _walk(self, si, active):
        active = mi.Bool(active)
        wi = si.to_world(si.wi)
        origin, d = si.p + wi * si.t, -wi   # the ray's own origin: a camera inside works too
        third = dr.full(mi.Float, 1 / 3, dr.width(si.t))   # the proxy face's centre (faces
        bn, su, sv = self.model.walls_scene.frame(si.prim_index, (third, third), active)  # = walls)
        choice = self.model.choose(d, dr.normalize(bn), su, sv)
        hit = self.model.find_view(origin, d, choice, active, si.t)
        normal = self.model.normal(hit)
        # shaded from the side the ray arrives on: the gradient normal faces away from the
        # viewer where the slices show a fragment the true surface hides (grazing views,
        # screen planes) or where the ray reached a fragment's far side (through a groove
        # whose zero heights the ramp test masks out); there the self-shadow ray starts
        # back along the ray, in the free space it came through
        back = dr.dot(normal, wi) < 0
        normal = dr.select(back, -normal, normal)
        si2 = shading_interaction(si, hit.uv, normal, hit.su)
        si2.p = hit.p
        return (hit, normal, dr.select(back, wi, normal)), active & ~hit.found, si2

    def _lit(self, state, wo_world, active):
        hit, normal, offset = state
        if not self.self_shadows:
            return dr.full(mi.Bool, True, dr.width(wo_world))
        return ~self.model.occluded(hit, offset, wo_world,
                                    active & hit.found & (dr.dot(normal, wo_world) > 0))

    def to_string(self):
        return f"{type(self).__name__}[{self.model.stats}]"


class ViewColour(mi.Texture):
    """The §4.2 colour at ``si.p`` for the viewer along ``-wi`` (the depth object BSDF puts
    the found point and the view direction into the interaction it shades)."""

    def __init__(self, obj: dobj.DepthObject):
        super().__init__(mi.Properties())
        self.obj = obj

    def _value(self, si):
        return self.obj.color(si.p, -si.to_world(si.wi))

    def eval(self, si, active=True):
        return mi.UnpolarizedSpectrum(self._value(si))

    def eval_3(self, si, active=True):
        return self._value(si)

    def eval_1(self, si, active=True):
        return dr.mean(self._value(si), axis=0)

    def mean(self):
        return mi.Float(float(np.mean(self.obj.images.color)))

    def is_spatially_varying(self):
        return True

    def traverse(self, cb):
        pass


class DepthObjectBSDF(SlicingBSDF):
    """The depth object seen through its cube (``self.model``: a DepthObject)."""

    PLUGIN = "depth_object"

    def _walk(self, si, active):
        active = mi.Bool(active)
        wi = si.to_world(si.wi)
        origin, d = si.p + wi * si.t, -wi
        found, p = self.model.find(origin, d, active)
        normal = self.model.normal(p, d)
        normal = dr.select(dr.dot(normal, d) > 0, -normal, normal)
        si2 = shading_interaction(si, si.uv, normal, dr.cross(normal, mi.Vector3f(0.31, 0.53, 0.79)))
        si2.p = p
        return (p, normal), active & ~found, si2

    def _lit(self, state, wo_world, active):
        p, normal = state
        return ~self.model.occluded(p, normal, wo_world, active & (dr.dot(normal, wo_world) > 0))
