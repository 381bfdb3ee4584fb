"""restored levels="auto" (issue 13): levels from the map resolution and the projected size."""
import mitsuba as mi
import numpy as np
import pytest

import mi_displace
from conftest import plane

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
