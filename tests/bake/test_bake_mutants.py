"""Tests written for mutants of bake/ that survived the suite (issue 19; docs/testing.md,
"Bake, volume and slicing modules").  Each asserts numbers against an independent truth:
planes at known heights, closed forms, or a NumPy re-computation."""
import re

import numpy as np
import pytest
from conftest import _sphere_mesh, plane
from test_bake_extremes import _stack

from mi_displace.bake import baker
from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData


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


def test_uv_warning_is_the_whole_sentence(variant):
    low = plane(n=2)
    low.uvs[4] = low.uvs[0]
    with pytest.warns(UserWarning) as w:
        r = bake(plane(z=0.01, n=4), low, res=32, max_distance=0.1)
    n_deg, n_over = r.record["low"]["uv_degenerate_triangles"], r.record["counts"]["uv_overlap_texels"]
    assert re.fullmatch(rf"low-poly UVs: {n_deg} degenerate triangles, {n_over} texels covered by "
                        r"overlapping triangles \(texture mapping not unambiguous, §3\.1\)",
                        str(w[0].message))


def _png_chunks(path):
    """The chunk types of a PNG file, read from its bytes."""
    data, pos, kinds = open(path, "rb").read(), 8, []
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kinds.append(data[pos + 4:pos + 8].decode())
        pos += 12 + n
    return kinds


def test_unit_vectors_encode_as_documented_and_pngs_are_linear(tmp_path, variant):
    # formats docstring: components x in [-1, 1] stored as round((x + 1) / 2 * 255), PNGs
    # are linear data (no sRGB / gamma chunk claiming a curve)
    from mi_displace.bake import formats

    x = np.float32([-1.0, -0.5, 0.0, 0.5, 1.0])
    n = np.zeros((1, 5, 3), np.float32)
    n[0, :, 0] = x
    n[0, :, 2] = np.sqrt(1 - x ** 2)
    path = formats.write_map(tmp_path, "normal_object", {"displacement": np.zeros((1, 5), np.float32),
                             "normal_tangent": n, "direction_tangent": n, "normal_object": n}, {})
    q = formats.read_png_raw(path)[0, :, 0]
    assert q.tolist() == np.floor((x.astype(np.float64) + 1) / 2 * 255 + 0.5).astype(int).tolist()
    assert q[0] == 0 and q[-1] == 255
    for fmt in ("d8", "d16", "normal_object"):
        chunks = _png_chunks(formats.write_map(tmp_path, fmt, {
            "displacement": np.zeros((1, 5), np.float32), "normal_tangent": n,
            "direction_tangent": n, "normal_object": n}, {}))
        assert chunks[0] == "IHDR" and chunks[-1] == "IEND"
        assert not {"sRGB", "gAMA", "iCCP"} & set(chunks), (fmt, chunks)


def test_missing_map_message_names_the_file(tmp_path):
    from mi_displace.bake import formats

    missing = tmp_path / "none.png"
    with pytest.raises(FileNotFoundError) as e:
        formats.read_map(missing)
    assert str(e.value) == f"map file {str(missing)!r} does not exist"


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


def test_object_normals_of_a_sphere_are_radial(variant):
    # a finer sphere of radius 1.02 over the unit sphere: the high-poly's smooth shading normal
    # at each texel is the radial direction of the texel's UV point (analytic parametrisation)
    import drjit as dr
    import mitsuba as mi

    from mi_displace.core import surfaces

    high = _sphere_mesh(96, 48, 0.0)
    high = MeshData(high.positions * np.float32(1.02), high.faces, None)
    r = bake(high, _sphere_mesh(48, 24, 0.0), res=64, max_distance=0.1, pad=0)
    rows, cols = np.nonzero(r.covered)
    u, v = (cols + 0.5) / 64, 1 - (rows + 0.5) / 64       # formats.UV_CONVENTION
    s = surfaces.make_base("sphere", radius=1.0).sample(mi.Float(u), mi.Float(v))
    radial = np.stack([np.asarray(c) for c in dr.normalize(s.p)], 1)
    n = r.maps["normal_object"][rows, cols]
    cos = (n * radial).sum(1)
    assert len(cos) > 0.9 * 64 * 64 and np.median(cos) > 0.9999 and cos.min() > 0.998
    # the low-poly's chords lie inside the unit sphere by at most 1 - cos(pi / 24) (24 rings)
    d = r.maps["displacement"][rows, cols]
    assert d.min() > 0.02 - 1e-3 and d.max() < 0.02 + (1 - np.cos(np.pi / 24)) * 1.02


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


def _tilted(n=8, z0=0.02, slope=0.1, slope_y=0.0):
    """A plane z = z0 + slope * x + slope_y * y (n x n quads) over [-0.1, 1.1]^2: the rays
    along the low-poly's +z normal measure d = z0 + slope * x + slope_y * y exactly."""
    p = plane(size=1.2, n=n)
    pos = p.positions - np.float32([0.1, 0.1, 0.0])
    pos[:, 2] = z0 + slope * pos[:, 0] + slope_y * pos[:, 1]
    return MeshData(pos, p.faces, None)


@pytest.mark.parametrize("aa", [1, 2, 3])
def test_texel_value_is_the_mean_over_its_aa_grid(variant, aa):
    # d is linear in x, so the mean over any symmetric aa x aa grid is its value at the
    # texel centre u = (c + 0.5) / W (formats.UV_CONVENTION)
    W = 8
    r = bake(_tilted(), plane(n=2), res=W, aa=aa, max_distance=0.2, pad=0)
    x = (np.arange(W) + 0.5) / W
    assert np.allclose(r.maps["displacement"], 0.02 + 0.1 * x[None, :], atol=2e-6)


def test_conservative_band_texels_take_a_chart_point_of_their_own_footprint(variant):
    # the chart covers u, v in [0.02, 0.478] (not on texel edges): the texels around it whose
    # centres miss but whose corners overlap it are added, valued at a point of the chart
    # (the centre's barycentrics clamped onto a triangle its corners found) that lies within
    # the texel's own footprint; inside, every texel is its centre's value
    W, lo, span = 32, 0.02, 0.458
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, (low.uvs * span + lo).astype(np.float32))
    r = bake(_tilted(), low, res=W, max_distance=0.2, pad=0)
    u = (np.arange(W) + 0.5) / W
    inside = (u > lo) & (u < lo + span)
    band = ~inside & (u + 0.5 / W > lo) & (u - 0.5 / W < lo + span)
    assert band.sum() == 2 and r.record["counts"]["conservative_samples"] > 0
    rows = np.nonzero(r.covered.any(1))[0]
    assert len(rows) == (inside | band).sum() and r.covered[rows][:, inside | band].all()
    assert r.covered.sum() == (inside | band).sum() ** 2
    mid = rows[1:-1]                                    # rows whose centres are inside
    x_of = lambda uu: (np.clip(uu, lo, lo + span) - lo) / span   # chart x of a UV u
    d = r.maps["displacement"][mid]
    assert np.allclose(d[:, inside], 0.02 + 0.1 * x_of(u[inside]), atol=2e-6)
    x = (d[:, band] - 0.02) / 0.1
    assert np.all(x >= x_of(u[band] - 0.5 / W) - 1e-5) and np.all(x <= x_of(u[band] + 0.5 / W) + 1e-5)


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


def test_quantised_sidecars_record_their_bit_depth(tmp_path):
    # the §1.2 table (formats docstring): displacement bits of each quantised format
    from mi_displace.bake import formats

    rng = np.random.default_rng(3)
    n = np.dstack([np.zeros((4, 6, 2)), np.ones((4, 6, 1))]).astype(np.float32)
    maps = {"displacement": rng.uniform(-1, 1, (4, 6)).astype(np.float32), "normal_tangent": n,
            "normal_object": n, "direction_tangent": n,
            "back_depth": rng.uniform(-1, 0, (4, 6)).astype(np.float32)}
    table = {"d8": 8, "d16": 16, "dir24_d8": 8, "dir16_d16": 16, "d8_n24": 8, "dual_d8_n16": 8,
             "d16_n16": 16, "float": 32}
    for fmt, bits in table.items():
        formats.write_map(tmp_path, fmt, maps, {})
        assert formats.read_metadata(tmp_path / f"{fmt}{formats.FORMATS[fmt]}")["displacement"]["bits"] == bits


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


def test_an_isolated_sliver_chart_gets_no_texels_and_is_counted(variant):
    # uv_raster docstring: only uncovered texels next to a covered one try their corners, so a
    # UV island thinner than a texel and far from every covered texel gets none, and is
    # reported in triangles_without_texels (the main chart gets all its texels)
    low = plane(n=2)
    pos = np.concatenate([low.positions, low.positions[low.faces[0]]])
    uvs = np.concatenate([low.uvs * np.float32(0.5),
                          np.float32([[0.80, 0.70], [0.80 + 0.3 / 16, 0.70], [0.80, 0.90]])])
    faces = low.faces.copy()
    faces[0] = [9, 10, 11]
    r = bake(plane(z=0.02, n=4), MeshData(pos, faces, uvs.astype(np.float32)), res=16,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["triangles_without_texels"] == 1
    assert not r.covered[:, 11:].any() and r.covered[8:, :8].sum() > 0.6 * 64   # face 0 moved


def test_overlap_is_measured_at_most_at_256(variant):
    # "it costs 2 x 256^2 rays at most" (overlap_texels): the record says at what resolution
    r = bake(plane(z=0.02, n=2), plane(n=1), res=300, max_distance=0.05, pad=0)
    assert r.record["counts"]["uv_overlap_resolution"] == 256
    r = bake(plane(z=0.02, n=2), plane(n=1), res=(40, 20), max_distance=0.05, pad=0)
    assert r.record["counts"]["uv_overlap_resolution"] == 40


@pytest.mark.parametrize("mirror", [False, True])
def test_decode_tangent_map_gives_the_object_normals(variant, mirror):
    # a tilted high-poly z = 0.02 + 0.1 x + 0.05 y: its normal is (-0.1, -0.05, 1) / |.|;
    # decoding the tangent-space map in MikkTSpace's frame (mikktspace.decode_tangent_map)
    # gives it back, also with the UVs mirrored in u (bitangent sign -1)
    from mi_displace.bake.mikktspace import decode_tangent_map

    low = plane(n=2)
    if mirror:
        low.uvs[:, 0] = 1 - low.uvs[:, 0]
    r = bake(_tilted(slope_y=0.05), low, res=16, max_distance=0.2, pad=0)
    out, inside = decode_tangent_map(r.low, r.maps["normal_tangent"])
    truth = np.float32([-0.1, -0.05, 1]) / np.linalg.norm([-0.1, -0.05, 1])
    assert inside.sum() == 256
    assert np.allclose(out[inside], truth, atol=1e-4)
    assert np.allclose(r.maps["normal_object"][inside], truth, atol=1e-4)


def test_degenerate_triangles_copy_the_tangent_of_their_vertex(variant):
    # MikkTSpace's DegenEpilogue: a triangle with two corners at one position takes, per
    # corner, the tangent of a good corner of the same (welded) vertex.  UVs (y, x): the
    # tangent dP/du is +y everywhere, not the default (1, 0, 0)
    from mi_displace.bake.meshdata import vertex_normals
    from mi_displace.bake.mikktspace import mikktspace

    low = plane(n=2)
    uvs = low.uvs[:, ::-1].copy()
    for bad in ([4, 5, 4], [4, 4, 5], [5, 4, 4]):
        faces = np.concatenate([low.faces, [bad]])
        t, s = mikktspace(low.positions, faces, vertex_normals(low.positions, low.faces), uvs)
        assert np.allclose(t[:-1], [0, 1, 0], atol=1e-6)
        assert np.allclose(t[-1], [0, 1, 0], atol=1e-6), bad
        assert np.all(s[-1] == s[0, 0])


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


def test_padded_texels_are_counted(variant):
    # a chart of 4 x 4 texels in an 8 x 8 map, padded by 2 texels: the 6 x 6 block around it
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, (low.uvs * np.float32(0.5)).astype(np.float32))
    r = bake(plane(z=0.02, n=4), low, res=8, max_distance=0.05, pad=2)
    c = r.record["counts"]
    assert c["covered"] == 16 and c["padded"] == int(r.maps["filled"].sum()) - 16 == 36 - 16


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


def test_a_constant_map_round_trips_in_every_format(tmp_path):
    # hi == lo: the quantisation span falls back to 1 (no division by zero), every texel
    # decodes to the constant
    from mi_displace.bake import formats

    n = np.dstack([np.zeros((4, 6, 2)), np.ones((4, 6, 1))]).astype(np.float32)
    maps = {"displacement": np.full((4, 6), 0.25, np.float32), "normal_tangent": n,
            "normal_object": n, "normal_mitsuba": n, "direction_tangent": n, "back_depth": np.full((4, 6), 0.25, np.float32),
            "ao": np.full((4, 6), 0.5, np.float32), "curvature": np.zeros((4, 6), np.float32),
            "cavity": np.zeros((4, 6), np.float32), "albedo": np.full((4, 6, 3), 0.5, np.float32)}
    import warnings

    for fmt in formats.FORMATS:
        with warnings.catch_warnings():
            warnings.simplefilter("error")            # no 0 / 0 on the way
            path = formats.write_map(tmp_path, fmt, maps, {})
        q = formats.read_metadata(path).get("displacement")
        assert q is None or q["scale"] > 0, fmt       # a consumer may divide by it
        out = formats.read_map(path)
        if out["displacement"] is not None:
            assert out["valid"] is None               # no mask named by this sidecar
            assert np.allclose(out["displacement"], 0.25, atol=1e-7), fmt
        name = fmt.removesuffix("_float")
        if name in ("ao", "curvature", "cavity", "albedo"):   # a flat surface map: its constant
            assert np.allclose(out[name], maps[name], atol=1e-4), fmt


def test_overlap_count_is_the_texel_centres_inside_both_triangles(variant):
    # a two-triangle low-poly whose second triangle's UVs are moved onto the first one: the
    # overlap reaches below the map's bottom row; overlap_texels counts the grid centres
    # strictly inside both (margin 1e-4 in barycentrics), as a NumPy point-in-triangle test does
    from mi_displace.bake.uv_raster import UVLayout, overlap_texels

    pos = np.float32([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0]])
    uvs = np.float32([[0.05, -0.2], [0.9, -0.1], [0.3, 0.85], [0.2, -0.3], [0.8, 0.7], [0.1, 0.6]])
    low = MeshData(pos, np.array([[0, 1, 2], [3, 4, 5]]), uvs)
    res = 64
    c = (np.arange(res) + 0.5) / res
    u, v = np.meshgrid(c, 1 - c, indexing="xy")
    pts = np.stack([u.ravel(), v.ravel()], 1)

    def inside(tri):
        a, b, cc = uvs[tri]
        m = np.linalg.inv(np.stack([b - a, cc - a], 1))
        w = (pts - a) @ m.T
        return np.minimum(np.minimum(w[:, 0], w[:, 1]), 1 - w.sum(1)) > 1e-4

    both = inside([0, 1, 2]) & inside([3, 4, 5])
    expected = int(both.sum())
    assert expected > 100 and both.reshape(res, res)[-1].any()   # the bottom row too
    assert overlap_texels(UVLayout(low), res) == expected


def test_texels_beyond_the_padding_hold_plus_z_normals(variant):
    # the chart fills the left half of each row; texels beyond the padding are empty and
    # hold displacement 0 and +z normals (baker._texel_average), never NaN
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, (low.uvs * np.float32([0.5, 1.0])).astype(np.float32))
    r = bake(plane(z=0.02, n=4), low, res=16, max_distance=0.05, pad=1)
    empty = ~r.maps["filled"]
    assert empty.sum() == 16 * 7
    for name in ("normal_object", "normal_tangent", "direction_tangent"):
        assert np.array_equal(r.maps[name][empty], np.tile(np.float32([0, 0, 1]), (int(empty.sum()), 1))), name
    assert np.all(r.maps["displacement"][empty] == 0)


def test_footprint_of_a_thin_lens_is_the_pinhole_one(variant_llvm):
    # pixel_footprint traces the rays through the lens centre: a thin-lens camera gives the
    # eye, direction and angle of the pinhole camera with its field of view
    from mi_displace.bake.levels import pixel_footprint

    pin = pixel_footprint(_look("perspective", 3.0, 64, 64, fov=40.0))
    lens = pixel_footprint(_look("thinlens", 3.0, 64, 64, fov=40.0, aperture_radius=0.3, focus_distance=3.0))
    assert np.allclose(lens["origin"], [0.5, 0.5, 3.0], atol=1e-5)
    assert np.allclose(lens["direction"], pin["direction"], atol=1e-6)
    assert lens["angle"] == pytest.approx(pin["angle"], rel=1e-4)
