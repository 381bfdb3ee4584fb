"""The VDM-family BSDFs expose their nested material through mi.traverse (issue 14)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

KEY = "s.bsdf.nested.reflectance.value"


def _scene(kind, integrator):
    bsdf = {"type": kind, "height": {"type": "cells", "to_uv": mi.ScalarTransform4f().scale([2, 2, 1])},
            "depth": 0.05, "tiling": 2,
            "nested": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}}
    if kind == "vdm":
        bsdf.update(res=16, theta=4, phi=8, svd_terms=4, mvm_terms=2)
    return mi.load_dict({
        "type": "scene", "integrator": integrator,
        "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -3, 3], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 24, "height": 24}},
        "key": {"type": "point", "position": [1, -1, 3], "intensity": {"type": "rgb", "value": 10}},
        "s": {"type": "vdm_mesh", "base": "plane", "resolution": 2, "bsdf": bsdf}})


@pytest.mark.parametrize("kind", ["vdm", "horizon", "relief"])
def test_nested_material_is_editable(variant, kind):
    scene = _scene(kind, {"type": "raster"})
    params = mi.traverse(scene)
    assert KEY in params
    before = np.asarray(mi.render(scene)).mean()
    params[KEY] = mi.Color3f(0.25)
    params.update()
    assert np.asarray(mi.render(scene)).mean() == pytest.approx(0.5 * before, rel=1e-5)


@pytest.mark.slow
def test_gradient_of_the_nested_material(variant):
    """~35 s on a loaded 2-core machine (prb's kernels compile): slow."""
    # gradient through Mitsuba's own differentiable integrator: the direct-light image is
    # linear in the albedo, so d mean / d albedo = mean / albedo
    scene = _scene("vdm", {"type": "prb", "max_depth": 2})
    params = mi.traverse(scene)
    params.keep([KEY])
    dr.enable_grad(params[KEY])
    image = mi.render(scene, params, spp=4, seed=1)
    loss = dr.mean(image, axis=None)
    dr.backward(loss)
    grad = float(np.sum(np.asarray(dr.grad(params[KEY]))))
    value = float(np.asarray(loss).ravel()[0])
    assert value > 0 and grad == pytest.approx(value / 0.5, rel=0.05), (grad, value)
