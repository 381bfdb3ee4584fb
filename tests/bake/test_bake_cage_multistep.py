"""The cage option (Fig. 8) and multistep displacement (§4, Fig. 9)."""
import numpy as np
import pytest
from bake_meshes import plane
from test_bake_extremes import _stack

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData, save_obj
from mi_displace.bake.restore import restore


def test_cage_offset_measures_along_the_cage(variant, tmp_path):
    r = bake(plane(z=0.02, n=4), plane(n=2), res=16, cage_offset=0.1, max_distance=0.05, pad=0)
    assert np.allclose(r.maps["displacement"], 0.02, atol=1e-6)


def test_cage_rays_that_miss_are_classified(variant):
    # the high-poly covers x < 0.5 only: rays over the other half miss (status, no crash)
    from mi_displace.bake.trace import MISS, OK

    high = plane(z=0.02, n=4)
    high = MeshData(high.positions * np.float32([0.5, 1, 1]), high.faces, None)
    r = bake(high, plane(n=2), res=16, cage_offset=0.1, max_distance=0.05, pad=0,
             min_hit_fraction=0.25)
    left = np.arange(16) < 7
    assert np.all(r.status[:, left] == OK) and np.all(r.status[:, ~left][:, 2:] == MISS)
    assert np.allclose(r.maps["displacement"][:, left], 0.02, atol=1e-6)


def test_tilted_cage_direction_round_trip(variant, tmp_path):
    low = plane(n=2)
    cage = MeshData(low.positions + np.float32([0.05, 0.0, 0.1]), low.faces, low.uvs)
    save_obj(tmp_path / "cage.obj", cage.positions, cage.faces, cage.uvs)
    r = bake(plane(z=0.02, n=4, size=1.2), low, res=16, cage=tmp_path / "cage.obj",
             max_distance=0.05, pad=2, out_dir=tmp_path / "b", map_formats=["float", "dir24_d8"])
    direction = np.array([0.05, 0.0, 0.1]) / np.linalg.norm([0.05, 0.0, 0.1])
    cov = r.covered
    assert np.allclose(r.maps["direction_tangent"][cov], direction, atol=1e-5)
    assert np.allclose(r.maps["displacement"][cov], 0.02 / direction[2], atol=1e-5)
    for fmt, tol in (("float.exr", 1e-5), ("dir24_d8.png", 2e-3)):
        out = restore(tmp_path / "b" / "low.obj", tmp_path / "b" / fmt, levels=1)
        moved = out.positions - np.c_[out.uvs, np.zeros(len(out.uvs))]
        assert np.allclose(moved, [0.01, 0.0, 0.02], atol=tol), fmt
    with pytest.raises(ValueError, match="cage"):
        bake(plane(z=0.02), low, res=8, cage=MeshData(plane(n=3).positions, plane(n=3).faces))


def test_two_maps_restore_an_overhang_one_map_cannot(variant, tmp_path):
    from mi_displace.bake.multistep import leaning_horn_sphere, multistep_bake, multistep_restore
    from mi_displace.evaluate.metrics import mesh_distance

    high = leaning_horn_sphere(192, 96, height=0.6, width=0.2, tilt_deg=80)
    inter = leaning_horn_sphere(96, 48, height=0.6, width=0.2, tilt_deg=40)
    high.uvs = inter.uvs = None
    low = leaning_horn_sphere(32, 16, height=0.0)
    one = bake(high, low, res=256, out_dir=tmp_path / "one", map_formats=["float"], max_distance=0.8,
               diagnostics=True)
    assert one.record["counts"]["ambiguous"] > 50          # the overhang is flagged
    r1 = restore(tmp_path / "one" / "low.obj", tmp_path / "one" / "float.exr", levels=3)
    multistep_bake(high, inter, low, tmp_path / "two", res=256, levels1=2, max_distance1=0.8)
    r2 = multistep_restore(tmp_path / "two" / "stage1" / "low.obj", tmp_path / "two" / "stage1" / "float.exr",
                           tmp_path / "two" / "stage2" / "float.exr", 2, 1)
    assert 0.99 * len(r1.faces) <= len(r2.faces) <= len(r1.faces)   # same triangle budget
    d1 = mesh_distance((high.positions, high.faces), (r1.positions, r1.faces), samples=20_000)
    d2 = mesh_distance((high.positions, high.faces), (r2.positions, r2.faces), samples=20_000)
    # the overhang: the original's farthest point from the restoration (high -> restored)
    # halves; both restorations are closed (stage 2's few texels that find nothing are filled
    # from their neighbours, not dropped), so the RMS is about the same
    assert d2["hausdorff_ab"] < 0.5 * d1["hausdorff_ab"], (d1["hausdorff_ab"], d2["hausdorff_ab"])
    assert d2["hausdorff_rel"] < d1["hausdorff_rel"]
    assert d2["rms_rel"] < 1.25 * d1["rms_rel"], (d1["rms_rel"], d2["rms_rel"])


def test_cage_ray_flags_a_second_crossing_and_only_that(variant):
    # cage 0.1 above the low-poly: the ray from the cage meets z = 0.02 first (t = 0.08),
    # then z = -0.02 within max_distance: a fold along the cage direction (ambiguous);
    # one layer alone is unambiguous
    low = plane(n=2)
    r = bake(_stack(plane(z=0.02, n=4), plane(z=-0.02, n=4)), low, res=8, cage_offset=0.1,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["ambiguous"] == 64
    assert np.allclose(r.maps["displacement"], 0.02, atol=1e-6)
    r = bake(_stack(plane(z=0.02, n=4), plane(z=-0.07, n=4)), low, res=8, cage_offset=0.1,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["ambiguous"] == 0 and r.record["counts"]["ok"] == 64


def test_cage_tilted_along_the_bitangent_restores(variant, tmp_path):
    # the direction's y (bitangent) component must be used as such: a cage shifted along +y
    from mi_displace.bake.meshdata import save_obj
    from mi_displace.bake.restore import restore

    low = plane(n=2)
    cage = MeshData(low.positions + np.float32([0.0, 0.05, 0.1]), low.faces, low.uvs)
    save_obj(tmp_path / "cage.obj", cage.positions, cage.faces, cage.uvs)
    bake(plane(z=0.02, n=4, size=1.2), low, res=16, cage=tmp_path / "cage.obj", max_distance=0.05,
         pad=2, out_dir=tmp_path / "b", map_formats=["float"])
    out = restore(tmp_path / "b" / "low.obj", tmp_path / "b" / "float.exr", levels=1)
    moved = out.positions - np.c_[out.uvs, np.zeros(len(out.uvs))]
    assert np.allclose(moved, [0.0, 0.01, 0.02], atol=1e-5)
