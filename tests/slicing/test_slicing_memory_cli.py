"""``mi-displace slicing-memory``: the build report of `best` on a mesh and its prisms'
shape, on a mesh whose answers are known (a flat grid: straight prisms)."""
import json

import numpy as np

from tests.slicing.test_slicing_memory import grid_obj


def test_slicing_memory_reports_families_and_straight_prisms(variant, tmp_path, capsys):
    from mi_displace.cli import main

    path = grid_obj(tmp_path / "grid.obj")
    assert main(["slicing-memory", path, "--slices", "4", "--resolution", "32"]) == 0
    report = json.loads(capsys.readouterr().out)
    fams = report["families"]
    assert set(fams) == {"a", "b", "c"} and fams["a"]["triangles"] == 4 * 128
    assert sum(f["bytes"] for f in fams.values()) <= report["bytes"]
    assert report["load_s"] >= report["build_s"] > 0
    # a flat grid: every extrusion direction is the same, so its prisms are straight
    assert np.allclose(report["prisms"]["spread_deg"], 0, atol=1e-3)
    assert np.allclose(report["prisms"]["twist"], 0, atol=1e-6)
    assert report["prisms"]["spread_over_1deg"] == 0


def test_prism_shape_of_a_sphere_mesh_matches_its_radial_directions(variant, tmp_path):
    from mi_displace.slicing import geometry as geo
    from tests.plugins.test_displaced_seams import uv_sphere_obj

    path = uv_sphere_obj(tmp_path / "sphere.obj", nu=16, nv=8)
    bm = geo.make_base_mesh("mesh", {}, path, 1, np.eye(4))
    shape = geo.prism_shape(bm, 0.1)
    # independent truth: a unit sphere's extrusion directions are (close to) radial, so a
    # triangle's spread is the largest angle between its corners' positions, and a side
    # quad lies in the plane through the centre (no twist)
    p = bm.positions / np.linalg.norm(bm.positions, axis=1, keepdims=True)
    f, g = bm.faces, np.roll(bm.faces, -1, 1)
    radial = np.degrees(np.arccos(np.clip((p[f] * p[g]).sum(2), -1, 1))).max(1)
    assert np.allclose(shape["spread_deg"], np.percentile(radial, [50, 95, 100]), atol=2.0)
    assert shape["spread_deg"][0] > 20 and shape["spread_over_1deg"] == 1.0
    assert shape["twist"][2] < 0.05
