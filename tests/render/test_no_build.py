"""Z-buffer + shadow maps need no acceleration structure: shapes kept outside the scene
(``Raster.shapes``) draw the same image, and ``ddm`` ``time`` / ``displaced`` ``scale``
edits re-render without any build (issue 18, animation)."""
import mitsuba as mi
import numpy as np
import pytest

from test_zbuffer import LIGHTS, camera, displaced_sphere

OPTIONS = {"visibility": "zbuffer", "shadows": "map", "shadow_resolution": 512}


def scene(shapes):
    d = {"type": "scene", "integrator": {"type": "raster", **OPTIONS}, "sensor": camera()}
    d.update(LIGHTS)
    d.update(shapes)
    return mi.load_dict(d)


def unbuilt(shape):
    sc = scene({})
    assert len(sc.shapes()) == 0
    sc.integrator().shapes = [shape]
    return sc


def render(sc):
    img = np.array(mi.render(sc))
    assert np.all(np.isfinite(img)) and img.mean() > 0.01
    return img


def thorns(time):
    return {"type": "ddm", "base": "sphere", "tile": "thorn", "tiles_u": 12, "tiles_v": 6,
            "height": 0.3, "mode": "maps", "map_resolution": 32, "velocity_u": 0.25,
            "time": time}


def test_shapes_outside_the_scene_draw_the_same_image(variant):
    inside = render(scene({"s": displaced_sphere()}))
    outside = render(unbuilt(mi.load_dict(displaced_sphere())))
    assert np.array_equal(inside, outside)


@pytest.mark.parametrize("edit", ["ddm time", "displaced scale"])
def test_edits_rerender_without_build(variant, edit):
    """The edited shape, drawn outside any scene, equals a fresh build with the new value."""
    make, key, value = {
        "ddm time": (lambda v: thorns(v), "time", 0.5),
        "displaced scale": (lambda v: {**displaced_sphere(), "scale": v}, "scale", 0.16),
    }[edit]
    shape = mi.load_dict(make(0.0 if key == "time" else 0.08))
    sc = unbuilt(shape)
    first = render(sc)
    params = mi.traverse(shape)
    params[key] = value
    params.update()
    edited = render(sc)
    fresh = render(unbuilt(mi.load_dict(make(value))))
    assert np.mean(np.abs(edited - first)) > 1e-3   # the geometry moved
    assert np.allclose(edited, fresh, atol=1e-5)
