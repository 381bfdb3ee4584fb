"""Scenes loaded one after another in one process: a mesostructure BSDF that was never set
up (no vdm_mesh, no tile_size) is refused by our loader, warns once under ``mi.load_dict``
and renders as its nested BSDF, and never affects another scene.

Dr.Jit traces every live BSDF into each vectorised call, so such a BSDF of a scene that is
still alive (a reference cycle, a notebook's last traceback) used to fail every later render
with its "not set up" error: the order-dependent failure of the full test run.
"""
import mitsuba as mi
import numpy as np
import pytest

SMALL = {"res": 16, "theta": 4, "phi": 8, "curvatures": 2}


def _scene(shape, integrator):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": integrator},
        "sensor": {"type": "perspective", "fov": 40, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -4, 1.5], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}},
        "amb": {"type": "constant"}, "shape": shape})


def _bsdf(plugin, **kw):
    extra = SMALL if plugin == "vdm" else {}
    return dict({"type": plugin, "height": {"type": "cells", "cells": 2}, "depth": 0.05}, **extra, **kw)


def _renders_nested_with_warning(scene, plugin, reference):
    """The unset BSDF's scene renders as its nested BSDF (``reference``: the same scene with
    the nested diffuse itself), after one warning naming the BSDF and the fix."""
    bsdf = scene.shapes()[0].bsdf()
    assert bsdf.setup_problem().startswith(f"{plugin}: BSDF") and "not set up" in bsdf.setup_problem()
    with pytest.warns(UserWarning, match="not set up.*tile_size.*renders as its nested"):
        img = np.asarray(mi.render(scene, spp=1))
    assert np.all(np.isfinite(img))
    np.testing.assert_allclose(img, np.asarray(mi.render(reference, spp=1)), atol=1e-5)


@pytest.mark.parametrize("integrator", ["path", "raster"])
@pytest.mark.parametrize("plugin", ["vdm", "horizon", "relief"])
def test_an_unset_bsdf_affects_only_its_own_scene(variant, plugin, integrator):
    broken = _scene({"type": "sphere", "bsdf": _bsdf(plugin)}, integrator)   # kept alive
    plain = _scene({"type": "sphere", "bsdf": {"type": "diffuse"}}, integrator)
    _renders_nested_with_warning(broken, plugin, plain)
    # later scenes in the same process render, with the broken one still alive: a plain
    # material, and the same plugin set up properly on a vdm_mesh
    good = _scene({"type": "vdm_mesh", "base": "sphere", "resolution": 8,
                   "bsdf": _bsdf(plugin)}, integrator)
    for scene in (plain, good):
        img = np.asarray(mi.render(scene, spp=1))
        assert np.all(np.isfinite(img)) and img.mean() > 0.05


@pytest.mark.parametrize("plugin", ["vdm", "relief"])
def test_our_loader_refuses_an_unset_bsdf_before_rendering(variant, plugin, tmp_path):
    from mi_displace.render.scene import load

    scene_xml = tmp_path / "unset.xml"
    extra = "".join(f'<integer name="{k}" value="{v}"/>' for k, v in SMALL.items()) if plugin == "vdm" else ""
    scene_xml.write_text(f"""<scene version="3.0.0">
  <integrator type="path"/>
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="8"/></film></sensor>
  <shape type="sphere"><bsdf type="{plugin}" id="meso"><texture type="cells" name="height"/>
    <float name="depth" value="0.05"/>{extra}</bsdf></shape>
</scene>""")
    with pytest.raises(ValueError, match=f"unset.xml.*{plugin}: BSDF 'meso' is not set up"):
        load(scene_xml)


def test_plugin_methods_in_a_trace_run_with_the_collector_paused(variant):
    """Dr.Jit traces every live BSDF and texture into each vectorised call, through plain
    pointers; Python's collector, started by a plugin method's allocations inside that
    trace, could free a dropped scene's instance before its turn (a segfault: seen with
    tests/vdm/test_vdm_plugin.py then this file, without a collection between tests).  A
    Python BSDF nested in ``vdm`` (called from its traced methods) sees the collector off;
    it is on again after the render."""
    import gc
    import sys

    import drjit as dr

    seen = []

    class Probe(mi.BSDF):
        def __init__(self, props):
            super().__init__(props)
            self.m_flags = int(mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide)
            self.m_components = [self.m_flags]

        def _note(self):
            # only the calls from vdm's methods (Dr.Jit also traces the probe directly)
            if sys._getframe(2).f_globals.get("__name__") == "mi_displace.vdm.mesostructure":
                seen.append(gc.isenabled())

        def eval(self, ctx, si, wo, active=True):
            self._note()
            return mi.Spectrum(dr.select(wo.z > 0, 0.5 * wo.z / dr.pi, 0.0))

        def pdf(self, ctx, si, wo, active=True):
            self._note()
            return dr.select(wo.z > 0, wo.z / dr.pi, 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            self._note()
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta, bs.sampled_type = 1.0, mi.UInt32(int(mi.BSDFFlags.DiffuseReflection))
            return bs, mi.Spectrum(0.5)

        def eval_diffuse_reflectance(self, si, active=True):
            self._note()
            return mi.Spectrum(0.5)

        def to_string(self):
            return "Probe"

    mi.register_bsdf("gc_probe", lambda props: Probe(props))
    scene = _scene({"type": "sphere", "bsdf": _bsdf("vdm", tile_size=0.5, svd_terms=4,
                                                     mvm_terms=2, nested={"type": "gc_probe"})},
                   "path")
    assert gc.isenabled()
    img = np.asarray(mi.render(scene, spp=1))
    assert np.all(np.isfinite(img)) and img.mean() > 0
    assert seen and not any(seen), seen
    assert gc.isenabled()
