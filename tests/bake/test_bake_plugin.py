"""``<shape type="restored">`` loads from XML / dict and matches the Python restoration."""
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.bake.baker import bake
from mi_displace.bake.restore import restore


def test_restored_shape_matches_restore(sphere_pair, tmp_path):
    high, low = sphere_pair
    bake(high, low, res=64, out_dir=tmp_path, map_formats=["d16"], max_distance=0.2)
    shape = mi.load_dict({"type": "restored", "map": str(tmp_path / "d16.png"), "levels": 1})
    ref = restore(tmp_path / "low.obj", tmp_path / "d16.png", levels=1)
    params = mi.traverse(shape)
    pos = np.asarray(params["vertex_positions"]).reshape(-1, 3)
    assert shape.face_count() == len(ref.faces) == 4 * len(low.faces)
    np.testing.assert_allclose(pos, ref.positions, atol=1e-6)
    assert np.all(np.isfinite(np.asarray(params["vertex_normals"])))


def test_restored_shape_bad_input(variant, tmp_path):
    with pytest.raises(Exception, match="map"):
        mi.load_dict({"type": "restored"})
    with pytest.raises(Exception, match="does not exist"):
        mi.load_dict({"type": "restored", "map": str(tmp_path / "none.png")})


def test_bunny_scene_loads(variant):
    from pathlib import Path

    from mi_displace.render.scene import load

    scene, _ = load(Path(__file__).resolve().parents[2] / "scenes" / "bake_bunny.xml",
                    mode="approximation", integrator="raster", levels=1)
    (shape,) = scene.shapes()
    low_faces = sum(1 for line in open(Path(__file__).resolve().parents[2] / "scenes" / "parts"
                                       / "bake_bunny" / "low.obj") if line.startswith("f "))
    # level 1: 4 faces per low-poly face, less the few dropped over the scan's holes
    assert 0.97 * 4 * low_faces <= shape.face_count() <= 4 * low_faces
