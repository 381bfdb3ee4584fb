"""Issue 14 (displaced): scale, midlevel, a bitmap height's texels and the procedural
heights' continuous parameters are differentiable through the tessellation into Mitsuba's
projective integrators (checked against central finite differences of the same loss), and
texture edits re-displace.

The sphere scenes are :func:`mi_displace.inverse.gradcheck.sphere_scene`; ``light=CAMERA``
(the light at the eye) hides every shadow: Mitsuba's projective integrators do not
differentiate the shadow boundaries of point lights (docs/differentiable.md measures the
bias they leave), so the tight checks are made without them."""
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.inverse import gradcheck as gc

SPP = 64


def scene(integrator, height, **shape):
    return gc.sphere_scene(height, integrator, spp=SPP, **shape)


def grad_and_fd(sc, key, target_value, eps, direction=None):
    """dL/dkey . direction by AD and by central differences, L = mean (image - target)^2.

    The differences use 4x the samples (edges move by a fraction of a pixel: the coverage
    of each pixel must be resolved) and Richardson's extrapolation over eps and eps / 2
    (removes the O(eps^2) curvature bias)."""
    params = mi.traverse(sc)
    v0 = type(params[key])(params[key])
    params[key] = type(v0)(target_value)
    params.update()
    target = mi.render(sc, spp=4 * SPP, seed=7)
    direction = type(v0)(1.0) if direction is None else direction

    def loss(value, grad=False, spp=SPP):
        params[key] = value
        if grad:
            dr.enable_grad(params[key])
        params.update()
        image = mi.render(sc, params, spp=spp, seed=3)
        assert np.all(np.isfinite(np.asarray(image)))
        return dr.mean(dr.square(image - target), axis=None)

    value = loss(type(v0)(v0), grad=True)
    dr.backward(value)
    ad = float(dr.sum(dr.grad(params[key]) * direction, axis=None).array[0])
    def central(e):
        plus = loss(type(v0)(v0 + e * direction), spp=4 * SPP).array[0]
        minus = loss(type(v0)(v0 - e * direction), spp=4 * SPP).array[0]
        return (plus - minus) / (2 * e)

    return ad, (4 * central(eps / 2) - central(eps)) / 3


@pytest.mark.parametrize("integrator,key,target,eps", [
    ("direct_projective", "ball.scale", 0.15, 0.008),
    ("prb_projective", "ball.midlevel", 0.3, 0.1),
])
def test_scale_and_midlevel_gradients_match_finite_differences(variant, integrator, key, target, eps):
    ad, fd = grad_and_fd(scene(integrator, {"type": "ripples"}), key, target, eps)
    print(f"{key} ({integrator}): AD {ad:.6g}, FD {fd:.6g}")
    assert np.sign(ad) == np.sign(fd) and abs(fd) > 1e-5
    assert abs(ad - fd) <= 0.15 * abs(fd), (ad, fd)


def test_bitmap_texel_gradient_matches_finite_differences(variant, tmp_path):
    """The ripples pattern stored as a 512 x 256 bitmap; d/dt L(h + t) (a uniform lift of every
    texel) against central differences."""
    v, u = np.meshgrid((np.arange(256) + 0.5) / 256, (np.arange(512) + 0.5) / 512, indexing="ij")
    si = dr.zeros(mi.SurfaceInteraction3f, u.size)
    si.uv = mi.Point2f(mi.Float(u.ravel()), mi.Float(v.ravel()))
    h = np.asarray(mi.load_dict({"type": "ripples"}).eval_1(si)).reshape(256, 512, 1)
    mi.Bitmap(h.astype(np.float32)).write(str(tmp_path / "h.exr"))
    sc = scene("direct_projective", {"type": "bitmap", "filename": str(tmp_path / "h.exr"),
                                     "raw": True})
    key = "ball.height.data"
    assert key in mi.traverse(sc) and not mi.traverse(sc).flags(key) & mi.ParamFlags.NonDifferentiable
    target = mi.TensorXf(np.clip(h - 0.2, 0, 1).astype(np.float32))
    direction = mi.TensorXf(np.ones_like(h, dtype=np.float32))
    ad, fd = grad_and_fd(sc, key, target, 0.1, direction)
    print(f"bitmap lift: AD {ad:.6g}, FD {fd:.6g}")
    assert np.sign(ad) == np.sign(fd) and abs(fd) > 1e-5
    assert abs(ad - fd) <= 0.15 * abs(fd), (ad, fd)


def test_texture_edits_redisplace_like_a_fresh_load(variant, tmp_path):
    h = np.linspace(0, 1, 16 * 32, dtype=np.float32).reshape(16, 32, 1)
    mi.Bitmap(h).write(str(tmp_path / "a.exr"))
    mi.Bitmap(1 - h).write(str(tmp_path / "b.exr"))
    shape = {"type": "displaced", "base": "sphere", "resolution": 32, "scale": 0.2}
    edited = mi.load_dict({**shape, "height": {"type": "bitmap", "filename": str(tmp_path / "a.exr"), "raw": True}})
    fresh = mi.load_dict({**shape, "height": {"type": "bitmap", "filename": str(tmp_path / "b.exr"), "raw": True}})
    params = mi.traverse(edited)
    params["height.data"] = mi.TensorXf(1 - h)
    params.update()
    a = np.asarray(mi.traverse(edited)["vertex_positions"])
    b = np.asarray(mi.traverse(fresh)["vertex_positions"])
    assert np.abs(a - b).max() < 1e-6


@pytest.fixture
def icosphere(tmp_path):
    """An icosphere (1,280 triangles) with spherical UVs, as a PLY file: a mesh base."""
    import trimesh

    ico = trimesh.creation.icosphere(3)
    p = ico.vertices
    uv = np.stack([np.arctan2(p[:, 1], p[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(p[:, 2], -1, 1)) / np.pi], 1)
    ico.visual = trimesh.visual.TextureVisuals(uv=uv)
    ico.export(tmp_path / "ico.ply")
    return str(tmp_path / "ico.ply")


def test_scale_gradient_on_a_mesh_base(variant, icosphere):
    """The same check on a mesh base (icosphere with spherical UVs, subdivided 3x)."""
    sc = scene("direct_projective", {"type": "ripples", "frequency": 2.0},
               base="mesh", filename=icosphere, subdivision=3)
    ad, fd = grad_and_fd(sc, "ball.scale", 0.15, 0.008)
    print(f"mesh scale: AD {ad:.6g}, FD {fd:.6g}")
    assert np.sign(ad) == np.sign(fd) and abs(fd) > 1e-5
    assert abs(ad - fd) <= 0.15 * abs(fd), (ad, fd)


@pytest.mark.parametrize("key,props", [
    ("ball.height.seed", {"height": {"type": "cells"}}),
    ("ball.height.rows", {"height": {"type": "bricks"}}),
    ("ball.dicing_rate", {"dicing_rate": 2.0}),
])
def test_gradient_on_a_parameter_that_cannot_have_one_is_refused(variant, key, props):
    sensor = {"type": "perspective", "film": {"type": "hdrfilm", "width": 16, "height": 16},
              "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 0], target=[0, 0, 0], up=[0, 0, 1])}
    shape = {"type": "displaced", "base": "sphere", "height": {"type": "ripples"}, **props}
    dicing = "dicing_rate" in props
    if not dicing:
        shape["resolution"] = 16
    sc = mi.load_dict({"type": "scene", "cam": sensor,
                       "ball": {**shape, **({"r": {"type": "ref", "id": "cam"}} if dicing else {})}})
    params = mi.traverse(sc)
    assert params.flags(key) & mi.ParamFlags.NonDifferentiable
    dr.enable_grad(params[key])
    with pytest.raises(ValueError, match=key.split(".", 1)[1].replace(".", r"\.")):
        params.update()


@pytest.mark.parametrize("texture", ["ripples", "bricks", "cells"])
def test_procedural_parameters_traverse_as_differentiable_and_edits_redisplace(variant, texture):
    """Continuous parameters Differentiable, counts and seeds not; an edit of each checked
    parameter re-displaces exactly like a fresh load at the new value."""
    from mi_displace.core.heightfield import INTEGER_PARAMETERS
    shape = {"type": "displaced", "base": "sphere", "resolution": 24, "scale": 0.1,
             "midlevel": 0.5}
    rows = [r for r in gc.PROCEDURAL if r[0]["type"] == texture]
    edited = mi.load_dict({**shape, "height": rows[0][0]})
    params = mi.traverse(edited)
    keys = [k[len("height."):] for k in params.keys() if k.startswith("height.") and k != "height.to_uv"]
    for k in keys:
        flagged = bool(params.flags(f"height.{k}") & mi.ParamFlags.NonDifferentiable)
        assert flagged == (k in INTEGER_PARAMETERS[texture]), k
    edits = {}
    for tex, name, value, _ in rows:
        before = np.asarray(mi.traverse(edited)["vertex_positions"])
        params[f"height.{name}"] = value
        params.update()
        edits[name] = value
        fresh = mi.load_dict({**shape, "height": {**tex, **edits}})
        a = np.asarray(mi.traverse(edited)["vertex_positions"])
        assert np.abs(a - before).max() > 1e-4, name      # the edit moved the surface
        np.testing.assert_allclose(a, np.asarray(mi.traverse(fresh)["vertex_positions"]), atol=1e-6)


@pytest.mark.parametrize("integrator,row", [("direct_projective", r) for r in gc.PROCEDURAL] + [
    ("prb_projective", gc.PROCEDURAL[3])],
    ids=lambda x: x if isinstance(x, str) else f"{x[0]['type']}-{x[1]}")
def test_procedural_gradient_matches_finite_differences(variant, integrator, row):
    """No shadow boundaries in view (light at the eye): within 10 % (+ noise) of the
    central differences, 64 spp (AD mean of 3 seeds, differences at 256 spp, 3 seeds);
    prb_projective once (max_depth 2: the same estimator, bench grad runs it on all)."""
    r = gc.check_procedural(*row, integrator=integrator, light=gc.CAMERA)
    print(f"{row[1]} ({integrator}): {r}")
    assert gc.agrees(r), r


@pytest.mark.parametrize("tessellation", [pytest.param("mesh_base", marks=pytest.mark.slow),
                                          "diced"])
def test_procedural_gradient_on_a_mesh_base_and_diced(variant, icosphere, tessellation):
    """ripples' frequency_u (4 -> 4.3) through a mesh base (the icosphere, subdivision 3)
    and through screen-adaptive dicing (1 px per micro-edge): 10 % + noise, light at the eye."""
    shape = ({"base": "mesh", "filename": icosphere, "subdivision": 3}
             if tessellation == "mesh_base" else
             {"dicing_rate": 1.0, "cam": {"type": "ref", "id": "sensor"}})
    sc = gc.sphere_scene({"type": "ripples", "frequency": 4.0}, light=gc.CAMERA, **shape)
    key = "ball.height.frequency_u"
    r = gc.check(sc, key, gc.target_at(sc, key, 4.3), eps=0.05, repeats=3, fd_repeats=3)
    print(tessellation, r)
    assert gc.agrees(r), r


@pytest.mark.slow
def test_texel_gradient_on_a_mesh_base(variant, icosphere):
    """A bitmap's texels through a mesh base: a Gaussian bump of texels of a 32 x 64 map
    (the ripples pattern at frequency 2, sampled), on the side of the icosphere facing the
    camera (u = 0.25), light at the eye: 10 % + noise (AD and FD 3 seeds each)."""
    from mi_displace.inverse import recover
    v, u = np.meshgrid((np.arange(32) + 0.5) / 32, (np.arange(64) + 0.5) / 64, indexing="ij")
    h = (0.5 + 0.4 * np.sin(4 * np.pi * u) * np.sin(2 * np.pi * v)).astype(np.float32)
    sc = gc.sphere_scene(recover.bitmap_height(h), light=gc.CAMERA, base="mesh",
                         filename=icosphere, subdivision=3)
    key = "ball.height.data"
    target = gc.target_at(sc, key, mi.TensorXf(np.clip(h + 0.1, 0, 1)[..., None]))
    bump = gc.texel_bump(h.shape + (1,), (16, 16), 3.0)
    r = gc.check(sc, key, target, bump, eps=0.05, repeats=3, fd_repeats=3)
    print(r)
    assert gc.agrees(r), r


def test_adam_recovers_a_procedural_parameter(variant):
    """End to end: mi.ad.Adam on ripples' frequency_u through direct_projective, from 4.0
    towards a render at 4.4 (light at the eye, 16 spp, lr 0.05): the best of 12 steps is
    within 0.05 of the truth, its loss under 5 % of the start's."""
    sc = gc.sphere_scene({"type": "ripples", "frequency": 4.0}, light=gc.CAMERA, spp=16)
    key = "ball.height.frequency_u"
    target = gc.target_at(sc, key, 4.4)
    params = mi.traverse(sc)
    opt = mi.ad.Adam(lr=0.05)
    opt[key] = mi.Float(4.0)
    params.update(opt)
    history = []
    for it in range(12):
        value = float(opt[key][0])
        loss = dr.mean(dr.square(mi.render(sc, params, spp=16, seed=it) - target), axis=None)
        dr.backward(loss)
        history.append((float(loss.array[0]), value))
        opt.step()
        params.update(opt)
    best_loss, best_value = min(history)
    print(history)
    assert best_loss < 0.05 * history[0][0] and abs(best_value - 4.4) < 0.05, history


def test_procedural_gradient_sign_with_shadows_in_view(variant):
    """The worst case under a side light (bricks' mortar: its walls cast the shadows whose
    boundaries Mitsuba does not differentiate): biased low, but the sign is right."""
    r = gc.check_procedural(*gc.PROCEDURAL[2], light=gc.SIDE_LIGHT)
    print(r)
    assert r["grad_finite"] and np.sign(r["ad"]) == np.sign(r["fd"]) and abs(r["fd"]) > 0


@pytest.mark.parametrize("case", ["zero_height", "folding", "pole"])
def test_gradients_at_the_extremes(variant, case):
    """Finite gradients that agree with the central differences (sign, and 10 % + noise with
    the light at the eye) at zero height (scale 0), at folding (scale 2.5 on the unit sphere,
    larger than its radius of curvature: the surface folds through the centre) and seen from
    above the pole (the collapsed pole rows)."""
    shape, camera, up, height, key, target, eps = {
        "zero_height": ({"scale": 0.0}, gc.CAMERA, (0, 0, 1), {"type": "ripples"},
                        "ball.scale", 0.05, 0.01),
        "folding": ({"scale": 2.5}, (0, -8, 1), (0, 0, 1), {"type": "ripples", "frequency": 2.0},
                    "ball.midlevel", 0.4, 0.02),
        "pole": ({}, (0, 0, 4), (0, 1, 0), {"type": "ripples"}, "ball.height.frequency_v", 8.3,
                 0.05),
    }[case]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")     # folding: the crossing check warns, as it should
        sc = gc.sphere_scene(height, light=camera, camera=camera, up=up, **shape)
        r = gc.check(sc, key, gc.target_at(sc, key, target), eps=eps, repeats=3, fd_repeats=3)
    print(case, r)
    assert gc.agrees(r), r
