"""Gradients of an image loss w.r.t. height texels and scale against central finite
differences (:mod:`mi_displace.inverse.gradcheck`), direct_projective, fixed seeds.

A gradient enabled on a parameter that cannot have one (procedural texture numbers,
dicing_rate) is refused by the displaced plugin itself, naming it: see
tests/plugins/test_displaced_grad.py::test_gradient_on_a_parameter_that_cannot_have_one_is_refused.
"""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.inverse import gradcheck, recover

N = 16


def _scene(grazing_deg=None):
    """The recovery plane seen by one camera: straight above (``views`` 1), or at
    ``grazing_deg`` elevation (sensor 0 of a 2-camera ring: a single view is the top one)."""
    truth = recover.load_height_map(size=N)
    scene = mi.load_dict(recover.scene_dict(truth, 1 if grazing_deg is None else 2, 32, 64,
                                            "direct_projective", grazing_deg=grazing_deg))
    target = mi.render(scene, spp=512, seed=99)
    params = mi.traverse(scene)
    params[recover.KEY] = mi.TensorXf((0.25 + 0.5 * truth)[..., None])   # a squashed map
    params.update()
    return scene, target


def test_texel_gradient_matches_finite_differences(variant):
    # one 256-spp central difference of this bump scatters by ~12 % of its value, one 64-spp
    # AD value by ~9 %: 8 seeds of each bring the standard error of AD - FD to ~5 %
    scene, target = _scene()
    r = gradcheck.check(scene, recover.KEY, target,
                        gradcheck.texel_bump((N, N, 1), (N // 2, N // 2), 1.5), eps=0.05,
                        repeats=8, fd_repeats=8)
    print(r)
    assert gradcheck.agrees(r, 0.1), r


def test_scale_gradient_matches_finite_differences(variant):
    scene, target = _scene()
    r = gradcheck.check(scene, "surface.scale", target, eps=0.01, repeats=3, fd_repeats=3)
    print(r)
    assert gradcheck.agrees(r, 0.05), r


@pytest.mark.parametrize("case", ["zero_height", "grazing"])
def test_gradients_are_finite_at_zero_height_and_grazing_views(variant, case):
    scene, target = _scene(grazing_deg=4.0 if case == "grazing" else None)
    params = mi.traverse(scene)
    if case == "zero_height":   # every texel at midlevel: the flat plane
        params[recover.KEY] = mi.TensorXf(np.full((N, N, 1), 0.5, np.float32))
    dr.enable_grad(params[recover.KEY])
    params.update()
    image = mi.render(scene, params, spp=16, seed=5)
    assert np.all(np.isfinite(np.asarray(image)))
    dr.backward(dr.mean(dr.square(image - target), axis=None))
    g = np.asarray(dr.grad(params[recover.KEY]))
    assert np.all(np.isfinite(g)) and np.count_nonzero(g) > N * N // 4
    # and a gradient agrees with the central differences there (sign, 10 % + noise): at zero
    # height scale and midlevel do nothing (the flat plane fills the view: both exactly 0),
    # so there a texel bump (it tilts the normals)
    if case == "zero_height":
        r = gradcheck.check(scene, recover.KEY, target, gradcheck.texel_bump(
            (N, N, 1), (N // 2, N // 2), 1.5), eps=0.05, repeats=8, fd_repeats=8)
    else:
        r = gradcheck.check(scene, "surface.scale", target, eps=0.01, repeats=3, fd_repeats=3)
    print(case, r)
    assert gradcheck.agrees(r, 0.1), r
