"""Extremes and bad input of the baker (issue list), each with numbers asserted."""
import numpy as np
import pytest
from bake_meshes import plane

from mi_displace.bake import baker
from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData, load_mesh


def _stack(*meshes):
    pos = np.concatenate([m.positions for m in meshes])
    faces, off = [], 0
    for m in meshes:
        faces.append(m.faces + off)
        off += len(m.positions)
    return MeshData(pos, np.concatenate(faces))


def test_features_beyond_max_distance(sphere_pair):
    high, low = sphere_pair  # displacement reaches 0.05 * 1.25
    r = bake(high, low, res=64, max_distance=0.01, min_hit_fraction=0.0)
    c = r.record["counts"]
    assert c["beyond"] > 0.2 * c["covered"] and c["miss"] == 0
    d = r.maps["displacement"][r.covered]
    assert np.all(np.isfinite(d)) and np.abs(d).max() <= 0.01 + 1e-6


def test_back_faces_are_not_measured(variant):
    low = plane(n=4)
    near = plane(z=0.02, n=8, flip=True)           # faces the wrong way, nearer
    far = plane(z=-0.05, n=8)                      # faces like the low-poly, farther
    r = bake(_stack(near, far), low, res=16, max_distance=0.1, pad=0)
    c = r.record["counts"]
    # both rays hit: outward a back face at +0.02, inward the front face at -0.05
    assert c["ok"] == c["covered"] == 256
    assert np.allclose(r.maps["displacement"], -0.05, atol=1e-5)
    only_back = bake(near, low, res=16, max_distance=0.1, pad=0, min_hit_fraction=0.0)
    assert only_back.record["counts"]["backface"] == 256


def test_ambiguous_projection_is_flagged(variant):
    low = plane(n=2)
    high = _stack(plane(z=0.03, n=4), plane(z=-0.01, n=4))   # two front-facing layers: a fold
    r = bake(high, low, res=8, max_distance=0.1, pad=0)
    assert r.record["counts"]["ambiguous"] == 64
    assert np.allclose(r.maps["displacement"], -0.01, atol=1e-5)   # nearest one kept
    # the farther layer inward is seen by the full-range search of diagnostics mode only
    high = _stack(plane(z=0.01, n=4), plane(z=-0.03, n=4))
    assert bake(high, low, res=8, max_distance=0.1, pad=0).record["counts"]["ambiguous"] == 0
    r = bake(high, low, res=8, max_distance=0.1, pad=0, diagnostics=True)
    assert r.record["counts"]["ambiguous"] == 64
    assert np.allclose(r.maps["displacement"], 0.01, atol=1e-5)
    # an overhang above the hit (a second crossing outward) needs the continuation ray
    high = _stack(plane(z=0.01, n=4), plane(z=0.05, n=4, flip=True), plane(z=0.07, n=4))
    assert bake(high, low, res=8, max_distance=0.1, pad=0).record["counts"]["ambiguous"] == 0
    assert bake(high, low, res=8, max_distance=0.1, pad=0,
                diagnostics=True).record["counts"]["ambiguous"] == 64


def test_concave_crease_crossing_normals(variant):
    # a V-shaped groove: interpolated normals at the crease converge and cross in front of it
    s = np.array([[0, 0, 0], [1, 0, 0.5], [1, 1, 0.5], [0, 1, 0], [-1, 0, 0.5], [-1, 1, 0.5]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 0, 3], [4, 3, 5]])
    uv = np.array([[0.5, 0], [1, 0], [1, 1], [0.5, 1], [0, 0], [0, 1]], np.float32)
    low = MeshData(s, faces, uv)
    high = MeshData(s + np.array([0, 0, 0.05], np.float32), faces)
    r = bake(high, low, res=32, max_distance=0.2, pad=0)
    d = r.maps["displacement"][r.covered]
    assert np.all(np.isfinite(d))
    n_face = 1 / np.sqrt(1.25)                        # |cos| between +z and a face normal
    assert np.median(d) == pytest.approx(0.05 * n_face, rel=0.05)


def test_degenerate_and_overlapping_uvs_warn_with_counts(variant):
    low = plane(n=2)
    low.uvs[4] = low.uvs[0]          # a vertex collapses in UV: degenerate triangles
    low.uvs[8] = low.uvs[2]          # and the far corner folds onto another: overlap
    high = plane(z=0.01, n=4)
    with pytest.warns(UserWarning, match="degenerate triangles") as w:
        r = bake(high, low, res=32, max_distance=0.1)
    assert r.record["low"]["uv_degenerate_triangles"] >= 1
    assert r.record["counts"]["uv_overlap_texels"] > 0
    assert f"{r.record['counts']['uv_overlap_texels']} texels covered by overlapping" in str(w[0].message)
    clean = bake(high, plane(n=2), res=32, max_distance=0.1)    # shared edges are no overlap
    assert clean.record["counts"]["uv_overlap_texels"] == 0


def test_one_by_one_map(variant):
    r = bake(plane(z=0.02, n=2), plane(n=1), res=1, max_distance=0.1)
    assert r.maps["displacement"].shape == (1, 1)
    assert r.maps["displacement"][0, 0] == pytest.approx(0.02, abs=1e-6)


def test_8192_request_refused_when_it_cannot_fit(variant, monkeypatch):
    need = baker.memory_estimate(8192, 8192, 1)
    assert need > 8192 * 8192 * 100
    monkeypatch.setenv("MI_DISPLACE_BAKE_MEMORY", str(need))   # just under 1.25x needed
    with pytest.raises(ValueError, match=r"res: a 8192x8192 bake .* GiB"):
        bake(plane(z=0.02), plane(), res=8192)
    with pytest.raises(ValueError, match="exceeds the limit"):
        bake(plane(z=0.02), plane(), res=20000)


def test_meshes_that_do_not_load(tmp_path, variant):
    with pytest.raises(FileNotFoundError, match="high-poly file"):
        bake(tmp_path / "missing.obj", plane(), res=4)
    bad = tmp_path / "bad.obj"
    bad.write_text("this is not a mesh\n")
    with pytest.raises(ValueError, match="bad.obj"):
        load_mesh(bad, "low-poly")
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(ValueError, match="suffix"):
        load_mesh(tmp_path / "x.txt", "low-poly")
    nan = plane()
    nan.positions[0, 0] = np.nan
    with pytest.raises(ValueError, match="low-poly: 1 NaN"):
        bake(plane(z=0.01), nan, res=4)


def test_low_poly_not_near_high_poly(sphere_pair):
    high, low = sphere_pair
    far = MeshData(low.positions + np.float32(10.0), low.faces, low.uvs)
    with pytest.raises(ValueError, match="does not sit near"):
        bake(high, far, res=16)
    inner = MeshData(low.positions * np.float32(0.5), low.faces, low.uvs)  # inside, out of reach
    with pytest.raises(ValueError, match="only 0 of .* covered texels"):
        bake(high, inner, res=16, max_distance=0.1 * high.diagonal)


def test_bad_parameters(variant):
    for kwargs, name in (({"res": 0}, "res"), ({"aa": 0}, "aa"), ({"max_distance": -1.0}, "max_distance"),
                         ({"pad": -1}, "padding"), ({"map_formats": ["jpeg"]}, "formats"),
                         ({"cage_offset": -0.1}, "cage_offset")):
        with pytest.raises(ValueError, match=name):
            bake(plane(z=0.01), plane(), **{"res": 4, **kwargs})


def test_row_blocks_without_uv_charts(variant):
    # the layout fills the bottom 10 % of a 2048^2 map: three of its four row blocks hold no
    # chart at all; they come out empty, the covered rows measure the offset
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, low.uvs * np.float32([1, 0.1]))
    r = bake(plane(z=0.02, n=4), low, res=2048, max_distance=0.05, pad=0)
    rows = np.nonzero(r.covered.any(1))[0]
    assert rows.min() >= 2048 - 206 and r.covered[rows].all()
    assert np.allclose(r.maps["displacement"][r.covered], 0.02, atol=1e-6)
    assert np.all(r.maps["displacement"][~r.covered] == 0)
    assert np.allclose(r.maps["normal_tangent"][~r.covered], [0, 0, 1])


def test_chart_borders_on_texel_edges(variant):
    # UVs in [0, 0.5]^2 at 64^2: the border runs along texel edges, so the conservative band
    # texels' corner probes find no triangle (nothing to add, no crash)
    low = plane(n=2)
    r = bake(plane(z=0.02, n=4), MeshData(low.positions, low.faces, low.uvs * 0.5), res=64,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["conservative_samples"] == 0
    assert r.covered.sum() == 32 * 32 and np.allclose(r.maps["displacement"][r.covered], 0.02, atol=1e-6)


def test_anti_aliased_texel_keeps_the_samples_that_hit(variant):
    from mi_displace.bake.trace import MISS, OK

    # the high-poly ends at x = 0.47: texel column 7 (x in [0.4375, 0.5]) has two sample
    # columns, at 0.453 (hits) and 0.484 (misses)
    high = plane(z=0.02, n=4)
    high = MeshData(high.positions * np.float32([0.47, 1, 1]), high.faces, None)
    r = bake(high, plane(n=2), res=16, aa=2, max_distance=0.05, pad=0, min_hit_fraction=0.25)
    assert np.all(r.status[:, 7] == OK) and np.allclose(r.maps["displacement"][:, 7], 0.02, atol=1e-6)
    assert np.all(r.status[:, 8:] == MISS)


def test_dual_depth_is_the_next_surface_behind(variant):
    # the front surface at +0.03 and a far wall at -0.02 (facing away, as a thin shell's
    # inner side does): back_depth is -0.02; without a second surface it is -max_distance
    low = plane(n=2)
    r = bake(_stack(plane(z=0.03, n=4), plane(z=-0.02, n=4, flip=True)), low, res=8,
             max_distance=0.1, pad=0, map_formats=["dual_d8_n16"])
    assert np.allclose(r.maps["displacement"], 0.03, atol=1e-5)
    assert np.allclose(r.maps["back_depth"], -0.02, atol=1e-5)
    r = bake(plane(z=-0.04, n=4), low, res=8, max_distance=0.1, pad=0, map_formats=["dual_d8_n16"])
    assert np.allclose(r.maps["displacement"], -0.04, atol=1e-5)
    assert np.allclose(r.maps["back_depth"], -0.1, atol=1e-6)


def test_without_meminfo_a_default_bake_still_fits(monkeypatch):
    # no MemAvailable to read (not Linux, or /proc hidden): the fallback must be an amount
    # that admits an ordinary bake (a 1024^2 map, aa 2), not zero
    class NoProc:
        def __init__(self, *args):
            pass

        def read_text(self):
            raise OSError("no /proc")

    monkeypatch.delenv("MI_DISPLACE_BAKE_MEMORY", raising=False)
    monkeypatch.setattr(baker, "Path", NoProc)
    have = baker.available_memory()
    assert have > baker.memory_estimate(1024, 1024, 2) / 0.8
    assert baker.check_settings(1024, 2, None, 8) == (1024, 1024)


def test_a_low_poly_a_fifth_of_the_diagonal_away_is_refused(variant):
    high = plane(z=0.02, n=4)
    shift = np.float32(0.2 * high.diagonal)
    far = plane(n=2)
    far = MeshData(far.positions + np.float32([1.0, 0.0, 0.0]) * shift + np.float32([1, 0, 0]),
                   far.faces, far.uvs)
    with pytest.raises(ValueError, match=r"^low-poly does not sit near the high-poly: bounding boxes"):
        bake(high, far, res=8, max_distance=0.05)
    near = plane(n=2)       # a gap of 1 % of the diagonal is accepted
    near = MeshData(near.positions + np.float32([1.0 + 0.01 * high.diagonal, 0, 0]), near.faces, near.uvs)
    from mi_displace.bake.baker import prepare_inputs

    prepare_inputs(high, near)


def test_memory_refusal_message_whole(variant, monkeypatch):
    need = baker.memory_estimate(512, 512, 2)
    monkeypatch.setenv("MI_DISPLACE_BAKE_MEMORY", str(need))
    with pytest.raises(ValueError) as e:
        bake(plane(z=0.02), plane(), res=512, aa=2)
    assert str(e.value) == (f"res: a 512x512 bake with aa 2 needs about {need / 2**30:.1f} GiB but only "
                            f"{need / 2**30:.1f} GiB is available; lower 'res' or 'aa'")


def test_a_low_poly_eleven_times_larger_is_refused(variant):
    high = plane(z=0.02, n=4)
    big = plane(size=10.5, n=2)          # overlaps the high-poly, but 10.5x its diagonal
    with pytest.raises(ValueError, match="^low-poly does not sit near the high-poly: bounding boxes"):
        bake(high, big, res=8, max_distance=0.05)
