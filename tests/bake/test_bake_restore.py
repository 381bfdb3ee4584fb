"""Restoration (§5): subdivision counts, alias-welded seams, holes, CLI round trip."""
import json

import numpy as np
import pytest
from bake_meshes import AMPLITUDE, plane, sphere_height

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import weld_ids
from mi_displace.bake.restore import edge_splits, restore
from mi_displace.cli import main


def test_subdivision_counts_and_seams_without_cracks(sphere_pair, tmp_path):
    high, low = sphere_pair
    bake(high, low, res=64, out_dir=tmp_path, map_formats=["d8"], max_distance=0.2)
    for levels, split in ((1, None), (2, None), (None, 3)):
        out = restore(tmp_path / "low.obj", tmp_path / "d8.png", levels=levels, split=split)
        L = edge_splits(levels, split)
        assert len(out.faces) == len(low.faces) * L * L
        assert np.all(np.isfinite(out.positions)) and np.all(np.isfinite(out.normals))
        # twins on the UV seam: their texels differ (8-bit, bilinear) but positions agree
        import trimesh

        tm = trimesh.Trimesh(out.positions, out.faces, process=False)
        tm.merge_vertices(merge_tex=True, merge_norm=True)
        assert tm.is_watertight or len(trimesh.grouping.group_rows(tm.edges_sorted, require_count=1)) == 0


def test_twins_displace_identically(variant):
    # a square split into two UV islands: the middle column of vertices is duplicated
    lo = plane(n=2)
    left = lo.faces[np.isin(lo.faces, [0, 3, 6]).any(1)]
    right_ids = np.array([1, 4, 7])
    pos = np.concatenate([lo.positions, lo.positions[right_ids]])
    uvs = np.concatenate([lo.uvs * [0.45, 1], lo.uvs[right_ids] * [0.45, 1] + [0.1, 0]]).astype(np.float32)
    uvs[[1, 2, 4, 5, 7, 8]] += [0.1, 0]
    remap = np.arange(9); remap[right_ids] = 9 + np.arange(3)
    right = lo.faces[~np.isin(lo.faces, [0, 3, 6]).any(1)]
    faces = np.concatenate([left, remap[right]])
    from mi_displace.bake.meshdata import MeshData

    low = MeshData(pos, faces, uvs)
    rng = np.random.default_rng(1)
    disp = rng.uniform(0, 0.1, (32, 32)).astype(np.float32)   # twins read different texels
    out = restore(low, {"displacement": disp}, levels=2)
    w = weld_ids(out.positions)
    assert len(np.unique(w)) < len(out.positions)               # seam twins exist ...
    same = np.unique(weld_ids(np.round(out.positions[:, :2], 5)), return_counts=True)[1]
    assert (same > 1).sum() == (len(out.positions) - len(np.unique(w)))  # ... and coincide in 3-D


def test_holes_stay_open(variant):
    low = plane(n=4)
    valid = np.ones((32, 32), np.float32)
    valid[8:24, 8:24] = 0
    full = restore(low, {"displacement": np.zeros((32, 32), np.float32)}, levels=2)
    holed = restore(low, {"displacement": np.zeros((32, 32), np.float32), "valid": valid}, levels=2)
    assert len(holed.faces) < 0.85 * len(full.faces)   # a quarter of the area is void
    centroid = holed.positions[holed.faces].mean(1)
    assert not np.any((np.abs(centroid[:, 0] - 0.5) < 0.2) & (np.abs(centroid[:, 1] - 0.5) < 0.2))


def test_bad_restore_input(tmp_path, variant):
    with pytest.raises(ValueError, match="levels"):
        edge_splits(9, None)
    with pytest.raises(ValueError, match="split"):
        edge_splits(None, 0)
    with pytest.raises(ValueError, match="no UVs"):
        restore(plane(uv=False), {"displacement": np.zeros((4, 4), np.float32)})
    with pytest.raises(ValueError, match="NaN"):
        restore(plane(), {"displacement": np.full((4, 4), np.nan, np.float32)})
    with pytest.raises(FileNotFoundError):
        restore(plane(), tmp_path / "none.png")


def check_sphere_restoration(positions):
    """Restored vertices at radius 1 + A f(direction), the known function of the sphere pair
    (a restoration at 0.5 or 1.5 times the amplitude is 0.25 A RMS off)."""
    radius = np.linalg.norm(positions, axis=1)
    err = np.abs(radius - (1.0 + AMPLITUDE * sphere_height(positions)))
    assert np.all(np.isfinite(positions))
    assert np.sqrt(np.mean(err ** 2)) < 0.05 * AMPLITUDE and err.max() < 0.2 * AMPLITUDE, \
        (np.sqrt(np.mean(err ** 2)) / AMPLITUDE, err.max() / AMPLITUDE)


def test_cli_bake_restore_meshdiff(sphere_pair, tmp_path, capsys):
    from mi_displace.bake.meshdata import save_obj

    high, low = sphere_pair
    save_obj(tmp_path / "high.obj", high.positions, high.faces)
    save_obj(tmp_path / "low_in.obj", low.positions, low.faces, low.uvs)
    assert main(["bake", "--high", str(tmp_path / "high.obj"), "--low", str(tmp_path / "low_in.obj"),
                 "--res", "64", "--out", str(tmp_path / "b"), "--formats", "d16,float",
                 "--diagnostics"]) == 0
    rec = json.loads((tmp_path / "b" / "bake.json").read_text())
    assert rec["settings"]["width"] == 64 and rec["counts"]["covered"] > 0
    assert (tmp_path / "b" / "diagnostics.png").is_file()
    assert main(["restore", "--map", str(tmp_path / "b" / "d16.png"), "--levels", "2",
                 "--out", str(tmp_path / "r.ply")]) == 0
    capsys.readouterr()
    assert main(["meshdiff", str(tmp_path / "high.obj"), str(tmp_path / "r.ply"),
                 "--samples", "20000", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    for key in ("rms", "hausdorff", "rms_rel", "hausdorff_rel", "hausdorff_ab", "hausdorff_ba"):
        assert np.isfinite(d[key])
    assert d["hausdorff_rel"] < 0.01
    import trimesh

    check_sphere_restoration(np.asarray(trimesh.load(tmp_path / "r.ply", process=False).vertices))
    with pytest.raises(SystemExit) as e:
        main(["restore", "--map", str(tmp_path / "b" / "nothing.png"), "--out", str(tmp_path / "x.ply")])
    assert e.value.code == 2


def test_restore_follows_how_the_map_was_measured(tmp_path, variant):
    low = plane(n=2)
    # along the normal: formats with a quantised direction restore as exactly as d16
    bake(plane(z=0.02, n=4), low, res=16, max_distance=0.05, pad=2, out_dir=tmp_path / "n",
         map_formats=["d16", "dir16_d16", "dir24_d8"])
    for fmt in ("d16.png", "dir16_d16.png", "dir24_d8.png"):
        out = restore(tmp_path / "n" / "low.obj", tmp_path / "n" / fmt, levels=1)
        assert np.allclose(out.positions[:, :2], out.uvs, atol=1e-6), fmt     # no sideways tilt
        assert np.allclose(out.positions[:, 2], 0.02, atol=2e-4 if "d8" in fmt else 1e-6), fmt
    # along a cage: a format without a direction cannot restore it; another low-poly neither
    bake(plane(z=0.02, n=4), low, res=16, cage_offset=0.1, max_distance=0.05, pad=2,
         out_dir=tmp_path / "c", map_formats=["d16", "float"])
    with pytest.raises(ValueError, match="cage.*stores no direction"):
        restore(tmp_path / "c" / "low.obj", tmp_path / "c" / "d16.png")
    restore(tmp_path / "c" / "low.obj", tmp_path / "c" / "float.exr")
    with pytest.raises(ValueError, match="baked over a low-poly with 8 faces"):
        restore(plane(n=3), tmp_path / "n" / "d16.png")


def test_restored_mesh_saves_as_obj_and_ply(tmp_path, variant):
    import trimesh

    from mi_displace.bake.meshdata import load_mesh
    from mi_displace.bake.restore import restore

    out = restore(plane(n=2), {"displacement": np.full((8, 8), 0.03, np.float32)}, levels=1)
    assert np.allclose(out.positions[:, 2], 0.03, atol=1e-6)
    out.save(tmp_path / "r.obj")
    back = load_mesh(tmp_path / "r.obj", "restored")
    assert len(back.faces) == len(out.faces) == 8 * 4
    assert np.allclose(np.sort(back.positions[:, 2]), 0.03, atol=1e-6)
    assert np.allclose(back.uvs[back.faces], out.uvs[out.faces], atol=1e-6)
    out.save(tmp_path / "r.PLY")
    ply = trimesh.load(tmp_path / "r.PLY", process=False)
    assert np.allclose(ply.vertices, out.positions, atol=1e-6)
    with pytest.raises(ValueError, match=r"^out: restored mesh must be \.ply or \.obj, got '.*r\.stl'$"):
        out.save(tmp_path / "r.stl")


def test_dropped_holes_are_reported(variant):
    from mi_displace.bake.restore import restore

    valid = np.ones((32, 32), np.float32)
    valid[8:24, 8:24] = 0
    out = restore(plane(n=4), {"displacement": np.zeros((32, 32), np.float32), "valid": valid}, levels=2)
    assert out.report["holes"] == "dropped: faces with 2 or 3 void vertices (open low-poly)"
    assert out.report["dropped_faces"] == 16 * 32 - len(out.faces) and out.report["dropped_faces"] > 0
    assert not out.report["closed"]


def test_map_sidecars_name_the_low_poly_written_beside_them(variant, tmp_path):
    from mi_displace.bake.formats import read_metadata
    from mi_displace.bake.restore import low_for_map

    bake(plane(z=0.02, n=4), plane(n=2), res=8, max_distance=0.05, out_dir=tmp_path,
         map_formats=["d16", "float"])
    for name in ("d16.png", "float.exr"):
        assert low_for_map(tmp_path / name) == str(tmp_path / "low.obj")
        meta = read_metadata(tmp_path / name)
        assert meta["low_faces"] == 8 and meta["valid"] == "valid.png" and meta["aa"] == 1
        assert meta["max_distance"] == 0.05 and meta["cage"] is None
    assert (tmp_path / "low.obj").is_file()


def test_restore_refuses_a_boolean_or_fractional_split(variant):
    from mi_displace.bake.restore import edge_splits

    for bad in (True, 2.5, 65):
        with pytest.raises(ValueError, match=r"^split: must be an integer in \[1, 64\]"):
            edge_splits(None, bad)
    for bad in (False, 1.5, 7):
        with pytest.raises(ValueError, match=r"^levels: must be an integer in \[0, 6\]"):
            edge_splits(bad, None)
    assert edge_splits(None, 3) == 3 and edge_splits(3, None) == 8 and edge_splits(None, None) == 4


def test_restore_of_another_low_poly_message_whole(variant, tmp_path):
    from mi_displace.bake.restore import restore

    bake(plane(z=0.02, n=4), plane(n=2), res=8, max_distance=0.05, out_dir=tmp_path, map_formats=["d16"])
    with pytest.raises(ValueError) as e:
        restore(plane(n=3), tmp_path / "d16.png")
    assert str(e.value) == ("low: the map was baked over a low-poly with 8 faces, this one has 18; "
                            "pass the low.obj the baker wrote beside the map")
    out = restore(tmp_path / "low.obj", {"displacement": np.zeros((8, 8), np.float32)}, levels=0)
    assert out.report["void_vertices"] == 0 and out.report["holes"] == "no validity mask"
