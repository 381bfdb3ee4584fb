"""restored: the baked map's texels are differentiable (issue 14), checked by finite differences."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from bake_meshes import plane

from mi_displace.bake.baker import bake


@pytest.fixture
def shape_params(variant_llvm, tmp_path):
    bake(plane(z=0.02, n=8), plane(n=2), res=8, max_distance=0.05, pad=2, out_dir=tmp_path,
         map_formats=["d16"])
    scene = mi.load_dict({"type": "scene", "s": {"type": "restored", "map": str(tmp_path / "d16.png"),
                                                 "levels": 2}})
    return mi.traverse(scene)


def _central_difference(params, key, base, texel, eps, value):
    """(value(x + eps e_texel) - value(x - eps e_texel)) / (2 eps) over the 8 x 8 map."""
    values = []
    for sign in (1, -1):
        x = base.copy()
        x[texel] += sign * eps
        params[key] = mi.TensorXf(x.reshape(8, 8, 1))
        params.update()
        values.append(value())
    return (values[0] - values[1]) / (2 * eps)


def _loss(params, w):
    return dr.sum(w * params["s.vertex_positions"])


def test_texel_gradients_match_finite_differences(shape_params):
    params = shape_params
    key = "s.displacement"
    assert not params.flags(key) & int(mi.ParamFlags.NonDifferentiable)      # exposed as differentiable
    n = dr.width(params["s.vertex_positions"])
    w = mi.Float(np.random.default_rng(0).normal(size=n).astype(np.float32))
    base = np.array(params[key].array)
    tensor = params[key]
    dr.enable_grad(tensor)
    params.update()
    loss = _loss(params, w)
    dr.backward(loss)
    grad = np.array(dr.grad(tensor).array)
    assert np.all(np.isfinite(grad)) and np.abs(grad).max() > 0
    for texel in (0, 9, 27, 36, 63):
        fd = _central_difference(params, key, base, texel, 1e-3, lambda: float(_loss(params, w)[0]))
        assert grad[texel] == pytest.approx(fd, rel=0.02, abs=1e-3), texel


def test_edits_redisplace_and_bad_edits_are_refused(shape_params):
    params = shape_params
    key = "s.displacement"
    z0 = np.array(params["s.vertex_positions"]).reshape(-1, 3)[:, 2]
    params[key] = mi.TensorXf(np.array(params[key]) + np.float32(0.01))
    params.update()
    z1 = np.array(params["s.vertex_positions"]).reshape(-1, 3)[:, 2]
    np.testing.assert_allclose(z1 - z0, 0.01, atol=1e-5)        # the plane rises by the edit
    params[key] = mi.TensorXf(np.full((8, 8, 1), np.nan, np.float32))
    with pytest.raises(Exception, match="NaN"):
        params.update()


def test_render_gradient_of_a_texel_matches_finite_differences(variant_llvm, tmp_path):
    """Through Mitsuba's `prb`: d(mean pixel)/d(texel) against central differences of the
    same render.  The plane fills the view (no silhouette), lit by a point light, so the
    gradient flows through the shading positions and normals the texels move."""
    bake(plane(z=0.02, n=8), plane(n=2), res=8, max_distance=0.05, pad=2, out_dir=tmp_path,
         map_formats=["d16"])
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "prb", "max_depth": 2},
        "s": {"type": "restored", "map": str(tmp_path / "d16.png"), "levels": 3},
        "light": {"type": "point", "position": [0.5, 0.3, 0.4], "intensity": {"type": "rgb", "value": 1.0}},
        "sensor": {"type": "perspective", "fov": 30, "film": {"type": "hdrfilm", "width": 24, "height": 24},
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0.5, 0.5, 1.2], target=[0.5, 0.5, 0],
                                                              up=[0, 1, 0])}})
    params = mi.traverse(scene)
    key = "s.displacement"
    base = np.array(params[key].array)
    tensor = params[key]
    dr.enable_grad(tensor)
    params.update()
    img = mi.render(scene, params, spp=32, seed=1)
    assert np.all(np.isfinite(np.array(img)))
    dr.backward(dr.mean(img.array))
    grad = np.array(dr.grad(tensor).array)
    for texel in (18, 27):          # texels under the lit middle of the view
        fd = _central_difference(params, key, base, texel, 2e-3, lambda: float(
            dr.mean(mi.render(scene, params, spp=256, seed=2).array)[0]))
        assert abs(fd) > 1e-3 and np.sign(grad[texel]) == np.sign(fd)
        assert grad[texel] == pytest.approx(fd, rel=0.1), (texel, grad[texel], fd)
