"""The GPU-style `raster` integrator: consistency with `path`, determinism, ambient,
alpha-test pass-through, lights."""
import flip_evaluator as flip
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.io import to_srgb

def scene(integrator, res=64, lights=("point", "sun"), extra=None, shape=None):
    d = {"type": "scene", "integrator": integrator,
         "sensor": {"type": "perspective", "fov": 30, "to_world": mi.ScalarTransform4f().look_at(
                        origin=[0, -5, 1.5], target=[0, 0, 0], up=[0, 0, 1]),
                    "film": {"type": "hdrfilm", "width": res, "height": res,
                             "rfilter": {"type": "box"}}},
         "s": shape or {"type": "displaced", "base": "sphere", "resolution": 96, "scale": 0.08,
                        "height": {"type": "checkerboard",
                                   "to_uv": mi.ScalarTransform4f().scale([8, 4, 1])},
                        "bsdf": {"type": "diffuse",
                                 "reflectance": {"type": "rgb", "value": [0.7, 0.6, 0.5]}}}}
    all_lights = {
        "point": {"type": "point", "position": [3, -3, 4], "intensity": {"type": "rgb", "value": 40}},
        "sun": {"type": "directional", "direction": [-1, 1, -1],
                "irradiance": {"type": "rgb", "value": 0.5}},
        "spot": {"type": "spot", "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -4, 3], target=[0, 0, 0], up=[0, 0, 1]), "cutoff_angle": 15,
            "intensity": {"type": "rgb", "value": 60}},
        "ambient": {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}},
    }
    d.update({k: all_lights[k] for k in lights})
    d.update(extra or {})
    return mi.load_dict(d)


def render(sc, **kw):
    img = np.array(mi.render(sc, **kw))[..., :3]
    assert np.all(np.isfinite(img))
    return img


def mean_flip(a, b):
    return flip.evaluate(to_srgb(a), to_srgb(b), "LDR")[1]


def test_raster_matches_path_within_noise_floor(variant):
    """DESIGN protocol item 4: same geometry and delta lights, raster vs path max_depth=2."""
    path = scene({"type": "path", "max_depth": 2})
    p0, p1 = render(path, spp=256, seed=0), render(path, spp=256, seed=1)
    noise_floor = mean_flip(p0, p1)
    r = render(scene({"type": "raster", "aa": 8}))
    assert r.mean() > 0.02  # really lit
    assert mean_flip(0.5 * (p0 + p1), r) <= noise_floor
    assert abs(r.mean() / p0.mean() - 1) < 0.01
    # one sample per pixel aliases the silhouettes and shadow edges: measurably worse
    r1 = render(scene({"type": "raster", "aa": 1}))
    assert mean_flip(0.5 * (p0 + p1), r1) > mean_flip(0.5 * (p0 + p1), r)


def test_raster_is_bit_identical_between_runs(variant):
    sc = scene({"type": "raster", "aa": 2}, lights=("point", "sun", "spot", "ambient"))
    assert np.array_equal(render(sc), render(sc))


def test_coherent_rays_find_the_incoherent_hits(variant, monkeypatch):
    """The frame's rays are traced as coherent rays (raster.COHERENT: Embree's packet
    traversal): the same hits, so the same image bit for bit as incoherent tracing, with a
    card passed through by the alpha test, shadow rays to delta lights and an area light."""
    from mi_displace.render import raster
    card = {"card": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate(
        [0, -4, 1.2]).rotate([1, 0, 0], 90).scale(0.15),
        "bsdf": {"type": "mask", "opacity": {"type": "rgb", "value": 0.2}, "bsdf": {"type": "diffuse"}}},
        "lamp": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([2, -2, 4]).scale(0.5),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 5.0}}}}
    sc = scene({"type": "raster", "aa": 2}, lights=("point", "sun", "ambient"), extra=card)
    assert raster.COHERENT is True
    coherent = render(sc)
    monkeypatch.setattr(raster, "COHERENT", False)
    incoherent = render(sc)
    assert coherent.mean() > 0.02 and np.array_equal(coherent, incoherent)


def test_ambient_equals_path_on_convex_diffuse(variant):
    """A convex diffuse sphere under a constant emitter: albedo x L is exact."""
    sphere = {"type": "sphere", "bsdf": {"type": "diffuse",
                                         "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.3]}}}
    r = render(scene({"type": "raster"}, lights=("ambient",), shape=sphere))
    p = render(scene({"type": "path", "max_depth": 2}, lights=("ambient",), shape=sphere), spp=256)
    inside = np.all(np.abs(r - 0.3) > 1e-3, axis=2)  # pixels on the sphere, not background
    assert inside.sum() > 500
    assert np.allclose(r[inside], [0.21, 0.15, 0.09], rtol=1e-5)
    assert abs(p[inside].mean() / r[inside].mean() - 1) < 0.01
    assert np.allclose(r[~inside], 0.3)  # the background is the environment


def test_alpha_test_passes_through_null_bsdf(variant):
    # The card sits between camera and sphere, off every shadow ray (shadow rays are
    # blocked by any surface, as in Mitsuba's `path`).
    def with_card(opacity):
        card = {"card": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate(
            [0, -4, 1.2]).rotate([1, 0, 0], 90).scale(0.15),
            "bsdf": {"type": "mask", "opacity": {"type": "rgb", "value": opacity},
                     "bsdf": {"type": "diffuse"}}}}
        return render(scene({"type": "raster"}, extra=card))

    bare = render(scene({"type": "raster"}))
    # equal up to the float32 change of hit points of the continued ray
    assert np.mean(np.abs(with_card(0.0) - bare)) < 1e-4
    assert np.mean(np.abs(with_card(0.3) - bare)) < 1e-4  # below the 1/2 alpha threshold
    assert np.mean(np.abs(with_card(1.0) - bare)) > 1e-2  # opaque card hides the sphere


def test_spot_light_is_a_cone(variant):
    img = render(scene({"type": "raster"}, lights=("spot",)))
    lit = img.sum(2) > 1e-4
    assert 0 < lit.sum() < 0.5 * img.shape[0] * img.shape[1]


def test_bad_parameters(variant):
    with pytest.raises(Exception, match="'aa'"):
        scene({"type": "raster", "aa": 0})
    for bad in (0, "many"):
        with pytest.raises(Exception, match="'max_layers'"):
            scene({"type": "raster", "max_layers": bad})


def cards(count, opacity=0.0):
    """``count`` see-through (null) cards between the camera and the sphere."""
    return {f"card{k}": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate(
        [0, -4 + 0.2 * k, 1.2 - 0.08 * k]).rotate([1, 0, 0], 90).scale(0.4),
        "bsdf": {"type": "mask", "opacity": {"type": "rgb", "value": opacity},
                 "bsdf": {"type": "diffuse"}}} for k in range(count)}


@pytest.mark.parametrize("visibility", ["raytrace", "zbuffer"])
def test_layer_limit_is_sized_from_the_scene(variant, visibility):
    """Twelve see-through cards (more than the old fixed limit of 8): by default every ray
    passes all of them and sees the sphere (raster.layer_limit)."""
    integrator = {"type": "raster", "visibility": visibility}
    bare = render(scene(integrator))
    img = render(scene(integrator, extra=cards(12)))
    behind = np.abs(render(scene(integrator, extra=cards(12, 1.0))) - bare).max(-1) > 1e-2
    assert behind.mean() > 0.05   # the cards cover part of the sphere
    assert np.abs(img - bare).max(-1)[behind].max() < 1e-3


def test_a_given_layer_limit_warns_naming_max_layers(variant):
    """A ray cut short by an explicit max_layers is counted and named, never silent."""
    with pytest.warns(UserWarning, match="max_layers=4"):
        render(scene({"type": "raster", "max_layers": 4}, extra=cards(12)))


def test_grazing_view_and_grazing_light_stay_finite(variant):
    """Camera and light at 89.5 degrees from a displaced plane's normal."""
    plane = {"type": "displaced", "base": "plane", "resolution": 128, "scale": 0.002,
             "height": {"type": "ripples", "frequency": 16.0},
             "to_world": mi.ScalarTransform4f().scale(10)}
    grazing = np.tan(np.radians(89.5))
    sc = mi.load_dict({
        "type": "scene", "integrator": {"type": "raster", "aa": 2},
        "sensor": {"type": "perspective", "fov": 20,
                   "to_world": mi.ScalarTransform4f().look_at(
                       origin=[0, -grazing * 0.05, 0.05], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64}},
        "sun": {"type": "directional", "direction": [grazing, 0, -1],
                "irradiance": {"type": "rgb", "value": 1.0}},
        "plane": plane})
    img = render(sc)
    lit = img.sum(2) > 0
    assert 0.05 < lit.mean() < 0.95  # ripple flanks facing the light lit, the rest in shadow


def test_found_interaction_is_the_traced_one(variant):
    """``first_opaque_hit`` builds the interaction it returns from the loop's preliminary
    intersection: bit for bit what tracing the found ray again gives, with a card that
    passes (null), one that stops rays, and misses."""
    from mi_displace.render import raster

    def card(x, y, opacity):
        return {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate(
            [x, y, 0.8]).rotate([1, 0, 0], 90).scale(0.3),
            "bsdf": {"type": "mask", "opacity": {"type": "rgb", "value": opacity},
                     "bsdf": {"type": "diffuse"}}}
    # a card in front that passes (opacity 0.2), one behind it, half hidden, that stops rays
    sc = scene({"type": "raster"}, res=48, extra={"pass": card(0.0, -3.0, 0.2),
                                                  "stop": card(0.4, -2.0, 0.9)})
    ray, _, _, _ = raster.pixel_rays(sc.sensors()[0], 1)
    active = mi.Bool(True)
    si, found, _ = raster.first_opaque_hit(sc, ray, 8, active)
    traced = sc.ray_intersect(found, active)
    for name in ("t", "p", "n", "uv", "dp_du", "dp_dv", "prim_index"):
        assert np.array_equal(np.array(getattr(si, name)), np.array(getattr(traced, name))), name
    passed = np.any(np.array(found.o) != np.array(ray.o), axis=0)   # went on past a layer
    assert 0.05 < passed.mean() < 0.95 and np.array(traced.is_valid()).mean() > 0.2
