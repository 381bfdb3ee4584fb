"""Scale invariance: the whole scene (object, camera position and clip planes) scaled by
1e-3 (a model in millimetres) or 1e3 renders the image of the unscaled scene.

Slicing on a torus walks its slices by ray queries (``rasterise=false``, as under ``path``),
at grazing angles too, so every offset of the walk counts; depth objects and hulls capture
their six images from a source of that size.  Bound: at most 0.5 % of the 64^2 pixels
differ by more than 0.02 (measured: 0 pixels for depth objects, hulls and directions a and
best, 2 pixels for screen)."""
import mitsuba as mi
import numpy as np
import pytest

from test_transforms import BRICKS, checker


def shape(name, s):
    if name in ("depth_object", "visual_hull"):
        return {"type": name, "slices": 48, "resolution": 48,
                "source": {"type": "sphere", "radius": 0.6 * s, "center": [0.1 * s, 0, 0],
                           "bsdf": checker()}}
    return {"type": "slicing", "base": "torus", "major_radius": 1.0, "minor_radius": 0.4,
            "resolution": 16, "scale": 0.08, "slices": 8, "direction": name, "rasterise": False,
            "height": {**BRICKS, "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])},
            "bsdf": checker(), "to_world": mi.ScalarTransform4f().scale(s)}


def image(name, s, res=64):
    eye = (np.array([0.3, -3.0, 2.4]) * s).tolist()
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "raster"}, "obj": shape(name, s),
        "amb": {"type": "constant", "radiance": 0.3},
        "sun": {"type": "directional", "direction": [-0.4, 0.5, -0.75], "irradiance": 2.0},
        "sensor": {"type": "perspective", "fov": 35, "near_clip": 1e-2 * s, "far_clip": 1e3 * s,
                   "to_world": mi.ScalarTransform4f().look_at(origin=eye, target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}}})
    img = np.array(mi.render(scene))[..., :3]
    assert np.all(np.isfinite(img)), "non-finite pixels"
    return img


@pytest.mark.parametrize("name", ["a", "best", "screen", "depth_object", "visual_hull"])
def test_scaled_scene_renders_the_same_image(variant, name):
    ref = image(name, 1.0)
    assert (np.abs(ref - 0.3).max(-1) > 1e-3).mean() > 0.1, "the object is in view"
    for s in (1e-3, 1e3):
        differ = (np.abs(image(name, s) - ref).max(-1) > 0.02).mean()
        assert differ <= 0.005, (s, differ)
