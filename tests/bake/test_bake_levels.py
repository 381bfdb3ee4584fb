"""restored levels="auto" (issue 13): levels from the map resolution and the projected size."""
import mitsuba as mi
import numpy as np
import pytest

import mi_displace
from bake_meshes import plane

from mi_displace.bake.baker import bake
from mi_displace.bake.levels import auto_levels, pixel_footprint


def _sensor(distance, width=64, fov=40.0):
    return mi.load_dict(_sensor_dict(distance, width, fov))


def _sensor_dict(distance, width=64, fov=40.0):
    return ({"type": "perspective", "fov": fov, "film": {"type": "hdrfilm", "width": width,
                                                                     "height": width},
                         "to_world": mi.ScalarTransform4f().look_at(origin=[0.5, 0.5, distance],
                                                                    target=[0.5, 0.5, 0], up=[0, 1, 0])})


def test_pixel_footprint_of_a_perspective_camera(variant_llvm):
    f = pixel_footprint(_sensor(3.0, width=100, fov=40.0))
    assert np.allclose(f["origin"], [0.5, 0.5, 3.0]) and np.allclose(f["direction"], [0, 0, -1])
    # 100 pixels over 40 degrees: about 0.4 degrees each near the centre
    assert f["angle"] == pytest.approx(2 * np.tan(np.radians(20)) / 100, rel=0.01)
    assert f["tan_half"] == pytest.approx(np.tan(np.radians(20)), rel=0.01)


def test_levels_follow_the_map_and_the_screen(variant_llvm):
    low = plane(n=1)                                         # 2 triangles, unit edges
    eye = np.eye(4)
    # no sensor: the map alone; the longest edges (the diagonals) span sqrt(2) x the map's
    # side in texels: 8 sqrt 2 = 11.3 -> 2^4; 64 sqrt 2 -> 2^7, clamped to 6
    assert auto_levels(low, (64, 64), [], eye)[0] == 6
    assert auto_levels(low, (8, 8), [], eye)[0] == 4
    # a camera: the unit square spans 64 px / (2 d tan 20 deg) pixels per unit
    for d in (2.0, 8.0):
        levels, why = auto_levels(low, (4096, 4096), [_sensor(d)], eye)
        px = 64 / (2 * d * np.tan(np.radians(20)))
        assert why["pixels_per_edge_p90"] == pytest.approx(px * np.sqrt(2), rel=0.05)  # the diagonal
        assert levels == int(np.ceil(np.log2(why["pixels_per_edge_p90"])))
    near, _ = auto_levels(low, (4096, 4096), [_sensor(2.0)], eye)
    far, _ = auto_levels(low, (4096, 4096), [_sensor(8.0)], eye)
    assert near - far == 2                                   # 4x farther: two levels fewer
    assert auto_levels(low, (4096, 4096), [_sensor(2.0)], eye, dicing_rate=4.0)[0] == near - 2
    assert auto_levels(low, (4, 4), [_sensor(2.0)], eye)[0] == 3         # the map caps it
    # behind the camera: nothing seen, the map decides
    behind = np.diag([1.0, 1.0, 1.0, 1.0]); behind[2, 3] = 5.0
    assert auto_levels(low, (64, 64), [_sensor(2.0)], behind)[1]["levels_screen"] is None
    with pytest.raises(ValueError, match="dicing_rate"):
        auto_levels(low, (64, 64), [], eye, dicing_rate=0.0)


def test_restored_auto_levels_and_build_stats(variant_llvm, tmp_path):
    lo = plane(n=2)
    bake(plane(z=0.02, n=8), lo, res=32, max_distance=0.05, pad=2, out_dir=tmp_path, map_formats=["d16"])
    scene = mi.load_dict({
        "type": "scene", "cam": _sensor_dict(4.0),
        "s": {"type": "restored", "map": str(tmp_path / "d16.png"), "levels": "auto",
              "camera": {"type": "ref", "id": "cam"}}})
    (shape,) = scene.shapes()
    st = shape.build_stats
    assert st["levels"] == min(st["levels_map"], st["levels_screen"]) and st["sensors"] == 1
    assert st["levels_map"] == 5          # diagonals of half a unit square: 32 / sqrt 2 = 22.6 texels
    assert st["faces"] == shape.face_count() == len(lo.faces) * 4 ** st["levels"]
    assert st["bytes"] > 0 and st["build_s"] > 0 and st["restore_s"] > 0
    assert np.all(np.isfinite(np.asarray(mi.traverse(shape)["vertex_positions"])))
    # without a referenced sensor: the map decides until the scene's sensors are given
    scene2 = mi.load_dict({"type": "scene", "cam": _sensor_dict(40.0),
                           "s": {"type": "restored", "map": str(tmp_path / "d16.png"), "levels": "auto"}})
    (shape2,) = scene2.shapes()
    assert shape2.build_stats["levels"] == 5 and shape2.build_stats["rule"] == "auto: map (no sensor)"
    assert mi_displace.fit_to_sensors(scene2) == [shape2.id()]          # far camera: fewer levels, rebuilt
    assert shape2.build_stats["levels"] < 5 and shape2.face_count() == len(lo.faces) * 4 ** shape2.build_stats["levels"]
    with pytest.raises(Exception, match="levels"):
        mi.load_dict({"type": "restored", "map": str(tmp_path / "d16.png"), "levels": "many"})


def _look(kind, distance, width, height, **extra):
    import mitsuba as mi

    to_world = mi.ScalarTransform4f().look_at(origin=[0.5, 0.5, distance], target=[0.5, 0.5, 0], up=[0, 1, 0])
    if kind == "orthographic":
        to_world = to_world @ mi.ScalarTransform4f().scale([0.5, 0.5, 1.0])
    return mi.load_dict({"type": kind, "film": {"type": "hdrfilm", "width": width, "height": height},
                         "to_world": to_world, **extra})


def test_orthographic_footprint_and_levels(variant_llvm):
    # an orthographic camera scaled by 0.5 shows [-0.5, 0.5] across its 64 pixels: 1/64 world
    # units a pixel at every depth; the unit square's diagonal spans 64 sqrt 2 pixels
    from mi_displace.bake.levels import auto_levels, pixel_footprint

    cam = _look("orthographic", 3.0, 64, 32)
    f = pixel_footprint(cam)
    assert f["angle"] == 0.0 and f["spacing"] == pytest.approx(1 / 64, rel=1e-5)
    assert f["aspect"] == 0.5 and np.allclose(f["direction"], [0, 0, -1])
    levels, why = auto_levels(plane(n=1), (4096, 4096), [cam], np.eye(4), dicing_rate=4.0)
    assert why["pixels_per_edge_p90"] == pytest.approx(64 * np.sqrt(2), rel=1e-4)
    assert levels == why["levels_screen"] == 5            # 22.6 px per 4 px: 2^5


def test_perspective_footprint_of_a_wide_film(variant_llvm):
    import math

    from mi_displace.bake.levels import pixel_footprint

    f = pixel_footprint(_look("perspective", 3.0, 100, 40, fov=40.0))
    assert f["aspect"] == 0.4 and f["tan_half"] == pytest.approx(math.tan(math.radians(20)), rel=1e-3)


def test_only_edges_inside_the_view_cone_count(variant_llvm):
    # a 0.1-wide square half a unit in front of the eye: on the axis it is seen; 0.6 to the
    # side it lies outside the 40-degree cone (1.2 tan 20 sqrt 2 x 0.5 + its edge, 0.45) and
    # only the map decides
    from mi_displace.bake.levels import auto_levels

    cam = _look("perspective", 3.0, 64, 64, fov=40.0)
    small = plane(size=0.1, n=1)
    for lateral, seen in ((0.0, True), (0.6, False)):
        m = np.eye(4)
        m[:3, 3] = [0.45 + lateral, 0.45, 2.5]
        why = auto_levels(small, (64, 64), [cam], m)[1]
        assert (why["levels_screen"] is not None) == seen, lateral


def test_footprint_of_a_thin_lens_is_the_pinhole_one(variant_llvm):
    # pixel_footprint traces the rays through the lens centre: a thin-lens camera gives the
    # eye, direction and angle of the pinhole camera with its field of view
    from mi_displace.bake.levels import pixel_footprint

    pin = pixel_footprint(_look("perspective", 3.0, 64, 64, fov=40.0))
    lens = pixel_footprint(_look("thinlens", 3.0, 64, 64, fov=40.0, aperture_radius=0.3, focus_distance=3.0))
    assert np.allclose(lens["origin"], [0.5, 0.5, 3.0], atol=1e-5)
    assert np.allclose(lens["direction"], pin["direction"], atol=1e-6)
    assert lens["angle"] == pytest.approx(pin["angle"], rel=1e-4)
