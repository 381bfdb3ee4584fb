"""A textured high-poly's own UV seams, restoration of closed low-polys, the low.obj layout."""
import numpy as np
from bake_meshes import AMPLITUDE, _sphere_mesh

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData, load_mesh, save_obj, weld_ids


def _angle_deg(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1)))


def test_textured_high_poly_does_not_crease_along_its_uv_seams(variant, tmp_path):
    """Issue 16 (2): the same surface as a textured OBJ (vertices split at its UV seams) and
    welded (one vertex per position) bakes the same normals."""
    high = _sphere_mesh(128, 64, AMPLITUDE)
    save_obj(tmp_path / "high.obj", high.positions, high.faces, high.uvs)
    textured = load_mesh(tmp_path / "high.obj", "high-poly")
    weld = weld_ids(textured.positions)
    assert weld.max() + 1 < len(textured.positions)            # the file has seam twins
    welded_pos = np.zeros((weld.max() + 1, 3), np.float32)
    welded_pos[weld] = textured.positions
    welded = MeshData(welded_pos, weld[textured.faces])
    low = _sphere_mesh(24, 12, 0.0)
    a = bake(textured, low, res=96, max_distance=0.2, pad=0)
    b = bake(welded, low, res=96, max_distance=0.2, pad=0)
    use = a.covered & b.covered
    err = _angle_deg(a.maps["normal_object"][use], b.maps["normal_object"][use])
    assert np.all(np.isfinite(a.maps["normal_object"])) and err.max() < 0.01, err.max()


def _sphere_with_a_hole():
    high = _sphere_mesh(128, 64, AMPLITUDE)
    centre = high.positions[high.faces].mean(1)
    high.faces = high.faces[centre[:, 2] < 0.8]          # a cap of the high-poly is missing
    high.uvs = None
    return high


def test_restoration_never_drops_a_face_of_a_closed_low_poly(variant, tmp_path):
    """Issue 16 (3): the normal line finds nothing over the high-poly's hole; the closed
    low-poly keeps every face there (padded map value or its own position) and says so."""
    from mi_displace.bake.restore import restore

    low = _sphere_mesh(24, 12, 0.0)
    r = bake(_sphere_with_a_hole(), low, res=96, max_distance=0.1, out_dir=tmp_path, map_formats=["d16"])
    assert r.record["counts"]["miss"] + r.record["counts"]["beyond"] > 0
    assert r.record["low"]["boundary_edges"] == 0 and r.record["low"]["non_manifold_edges"] == 0
    out = restore(tmp_path / "low.obj", tmp_path / "d16.png", levels=2)
    assert len(out.faces) == 16 * len(low.faces)                 # nothing dropped
    assert out.report["closed"] and out.report["void_vertices"] > 0 and out.report["dropped_faces"] == 0
    assert np.all(np.isfinite(out.positions))
    radius = np.linalg.norm(out.positions, axis=1)
    bound = 1.25 * AMPLITUDE + 0.01          # |height| <= 1.25 A; the low-poly chords sag < 0.01
    assert radius.min() > 1 - bound and radius.max() < 1 + bound
    # an open low-poly (the same sphere without its cap) still drops the faces over the hole
    centre = low.positions[low.faces].mean(1)
    open_low = MeshData(low.positions, low.faces[centre[:, 2] < 0.95], low.uvs)
    r = bake(_sphere_with_a_hole(), open_low, res=96, max_distance=0.1, out_dir=tmp_path / "o",
             map_formats=["d16"])
    out = restore(tmp_path / "o" / "low.obj", tmp_path / "o" / "d16.png", levels=2)
    assert not out.report["closed"] and out.report["dropped_faces"] > 0


def test_bake_reports_non_manifold_edges(variant, tmp_path, capsys):
    from mi_displace.cli import main

    low = _sphere_mesh(24, 12, 0.0)
    f = low.faces
    fin = np.array([[f[40, 0], f[40, 1], len(low.positions)]])     # a third face on one edge
    pos = np.vstack([low.positions, low.positions[f[40, 0]] * 1.01]).astype(np.float32)
    uvs = np.vstack([low.uvs, [[0.99, 0.99]]]).astype(np.float32)
    save_obj(tmp_path / "low.obj", pos, np.vstack([f, fin]), uvs)
    high = _sphere_mesh(64, 32, AMPLITUDE)
    save_obj(tmp_path / "high.obj", high.positions, high.faces)
    assert main(["bake", "--high", str(tmp_path / "high.obj"), "--low", str(tmp_path / "low.obj"),
                 "--res", "32", "--out", str(tmp_path / "b")]) == 0
    import json

    rec = json.loads((tmp_path / "b" / "bake.json").read_text())
    assert rec["low"]["non_manifold_edges"] == 1
    assert "1 non-manifold edge" in capsys.readouterr().out


def test_low_obj_shares_positions_across_uv_seams(variant, tmp_path):
    """Issue 16 (4): one ``v`` per position, UVs per corner (``f v/vt/vn``); reading the file
    back gives the same triangles, UVs and normals."""
    low = _sphere_mesh(24, 12, 0.0)
    r = bake(_sphere_mesh(64, 32, AMPLITUDE), low, res=32, max_distance=0.2, out_dir=tmp_path)
    text = (tmp_path / "low.obj").read_text().splitlines()
    n_v = sum(line.startswith("v ") for line in text)
    n_vt = sum(line.startswith("vt ") for line in text)
    assert n_v == len(np.unique(low.positions, axis=0)) < len(low.positions) == n_vt
    face = next(line for line in text if line.startswith("f "))
    assert len(face.split()[1].split("/")) == 3
    back = load_mesh(tmp_path / "low.obj")
    np.testing.assert_array_equal(back.positions[back.faces], low.positions[low.faces])
    np.testing.assert_array_equal(back.uvs[back.faces], low.uvs[low.faces])
    assert r.record["low"]["boundary_edges"] == 0


def test_void_texels_of_a_closed_low_poly_take_their_neighbours_displacement(variant):
    # a closed sphere, displacement 0.04 everywhere it was measured; the void patch holds
    # garbage (0.5) in the map: its vertices take the harmonic interpolation of the measured
    # displacement vectors around them (0.04 radially, so a little shorter where the ring's
    # directions fan out), and no face is dropped

    from mi_displace.bake.restore import restore

    low = _sphere_mesh(24, 12, 0.0)
    disp = np.full((64, 64), 0.04, np.float32)
    valid = np.ones((64, 64), np.float32)
    disp[27:37, 27:37], valid[24:40, 24:40] = 0.5, 0.0   # garbage 3 texels inside the void
    out = restore(low, {"displacement": disp, "valid": valid}, levels=1)
    assert out.report["closed"] and out.report["void_vertices"] > 0 and out.report["dropped_faces"] == 0
    assert len(out.faces) == 4 * len(low.faces)
    radius = np.linalg.norm(out.positions, axis=1)
    assert np.abs(radius - 1.04).max() < 0.03              # the garbage would give 1.5
