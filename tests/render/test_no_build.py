"""Z-buffer + shadow maps need no acceleration structure: shapes kept outside the scene
(``Raster.shapes``) draw the same image, and ``ddm`` ``time`` / ``displaced`` ``scale``
edits re-render without any build (issue 18, animation)."""
import mitsuba as mi
import numpy as np

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


def test_ddm_time_edit_rerenders_without_build(variant):
    shape = mi.load_dict(thorns(0.0))
    sc = unbuilt(shape)
    first = render(sc)
    params = mi.traverse(shape)
    params["time"] = 0.5
    params.update()
    edited = render(sc)
    fresh = render(unbuilt(mi.load_dict(thorns(0.5))))
    assert np.mean(np.abs(edited - first)) > 1e-3   # the thorns moved
    assert np.allclose(edited, fresh, atol=1e-5)


def test_displaced_scale_edit_rerenders_without_build(variant):
    shape = mi.load_dict(displaced_sphere())
    sc = unbuilt(shape)
    first = render(sc)
    params = mi.traverse(shape)
    params["scale"] = 0.16
    params.update()
    edited = render(sc)
    fresh = render(unbuilt(mi.load_dict({**displaced_sphere(), "scale": 0.16})))
    assert np.mean(np.abs(edited - first)) > 1e-3
    assert np.allclose(edited, fresh, atol=1e-5)
