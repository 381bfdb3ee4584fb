"""Slicing on a closed base draws the base by default: under the ramp α-test (`best`, b, c,
screen) zero heights are cut-outs (§3.2), and on a torus or a sphere a cut-out opened the
solid: a ray through a mortar line went on inside the base and out of its far side, and the
Cornell box's torus, facing the camera under a point light from above, showed lit speckles
on its dark front (18 pixels of 96² where `displaced` is dark, against 4 for direction `a`,
whose basic test draws zero heights; the same under `raster` and `path`)."""
import mitsuba as mi
import numpy as np

from slicing_scenes import bricks_torus


def render(obj, integrator, spp):
    d = mi.cornell_box()
    for key in ("light", "small-box", "large-box"):
        d.pop(key, None)
    d["integrator"] = integrator
    d["lamp"] = {"type": "point", "position": [0, 0.9, 0], "intensity": 3.0}
    d["sensor"]["film"].update(width=96, height=96)
    d["obj"] = obj
    img = np.array(mi.render(mi.load_dict(d), spp=spp))[..., :3]
    assert np.all(np.isfinite(img)), "non-finite pixels"
    return img.max(-1)


def test_closed_base_has_no_see_through_under_the_ramp_test(variant):
    torus = bricks_torus(to_world=mi.ScalarTransform4f().scale(0.4))
    truth = render({"type": "displaced", **torus, "resolution": 256},
                   {"type": "path", "max_depth": 2}, 64)
    dark = truth < 0.002

    def speckles(direction):
        img = render({"type": "slicing", **torus, "resolution": 16, "slices": 8,
                      "direction": direction}, {"type": "raster"}, 1)
        return int(((img > 0.02) & dark).sum())

    control = speckles("a")
    assert speckles("best") <= control, control
