"""Issue 14 (displaced): scale, midlevel and a bitmap height's texels are differentiable
through the tessellation into Mitsuba's projective integrators (checked against central
finite differences of the same loss, same seeds), and texture edits re-displace."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

SPP = 64


def scene(integrator, height, **shape):
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": integrator, "sppi": 0} if integrator == "direct_projective"
        else {"type": integrator, "max_depth": 2, "sppi": 0},
        "sensor": {"type": "perspective", "fov": 35, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -4, 0.5], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": SPP}},
        "light": {"type": "point", "position": [2, -3, 2], "intensity": {"type": "rgb", "value": 20}},
        "ball": {"type": "displaced", "scale": 0.1, "midlevel": 0.5, "height": height,
                 **(shape or {"base": "sphere", "resolution": 48})}})


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


def test_scale_gradient_on_a_mesh_base(variant, tmp_path):
    """The same check on a mesh base (icosphere with spherical UVs, subdivided 3x)."""
    import trimesh

    ico = trimesh.creation.icosphere(3)
    p = ico.vertices
    uv = np.stack([np.arctan2(p[:, 1], p[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(p[:, 2], -1, 1)) / np.pi], 1)
    ico.visual = trimesh.visual.TextureVisuals(uv=uv)
    ico.export(tmp_path / "ico.ply")
    sc = scene("direct_projective", {"type": "ripples", "frequency": 2.0},
               base="mesh", filename=str(tmp_path / "ico.ply"), subdivision=3)
    ad, fd = grad_and_fd(sc, "ball.scale", 0.15, 0.008)
    print(f"mesh scale: AD {ad:.6g}, FD {fd:.6g}")
    assert np.sign(ad) == np.sign(fd) and abs(fd) > 1e-5
    assert abs(ad - fd) <= 0.15 * abs(fd), (ad, fd)


@pytest.mark.parametrize("key,props", [
    ("ball.height.phase", {}),
    ("ball.dicing_rate", {"dicing_rate": 2.0}),
])
def test_gradient_on_a_parameter_that_cannot_have_one_is_refused(variant, key, props):
    sensor = {"type": "perspective", "film": {"type": "hdrfilm", "width": 16, "height": 16},
              "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 0], target=[0, 0, 0], up=[0, 0, 1])}
    shape = {"type": "displaced", "base": "sphere", "height": {"type": "ripples"}, **props}
    if not props:
        shape["resolution"] = 16
    sc = mi.load_dict({"type": "scene", "cam": sensor,
                       "ball": {**shape, **({"r": {"type": "ref", "id": "cam"}} if props else {})}})
    params = mi.traverse(sc)
    dr.enable_grad(params[key])
    with pytest.raises(ValueError, match=key.split(".", 1)[1].replace(".", r"\.")):
        params.update()
