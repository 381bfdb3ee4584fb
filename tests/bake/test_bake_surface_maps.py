"""Ambient occlusion, curvature / cavity, albedo transfer and the DirectX green channel,
against closed forms and known transfers."""
import mitsuba as mi
import numpy as np
import pytest

from bake_meshes import _sphere_mesh, plane


def _union(*meshes):
    from mi_displace.bake.meshdata import MeshData

    offsets = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
    return MeshData(np.concatenate([m.positions for m in meshes]),
                    np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]))


def _centred(mesh, shift):
    mesh.positions[:, :2] -= shift
    return mesh


def _floor_and_ceiling(h):
    """(high, low): a 2 x 2 floor at z = 0 (the low-poly, UVs (x, y)) and the same floor
    (4 x 4 quads) under an 8 x 8 ceiling at height h facing down."""
    low = _centred(plane(2.0, n=1), 1.0)
    floor = _centred(plane(2.0, n=4, uv=False), 1.0)
    ceiling = _centred(plane(8.0, z=h, n=1, uv=False, flip=True), 4.0)
    return _union(floor, ceiling), low


def _interior(shape, margin):
    H, W = shape
    return (slice(int(margin * H), int((1 - margin) * H)), slice(int(margin * W), int((1 - margin) * W)))


def _se_bound(p, n):
    """4 standard errors of a mean of n Bernoulli(p) draws."""
    return 4 * np.sqrt(p * (1 - p) / n) + 1e-6


@pytest.mark.parametrize("h,distance", [(0.2, 0.4), (0.3, 0.4)])
def test_ao_floor_under_ceiling(variant, h, distance):
    """Cosine-weighted visibility within `distance` under a ceiling at height h: a direction
    at polar angle theta reaches the ceiling at h / cos(theta), so it is open iff
    cos(theta) < h / distance, and P(cos < c) = c^2 for cosine-weighted directions."""
    from mi_displace.bake.baker import bake

    high, low = _floor_and_ceiling(h)
    samples = 128
    r = bake(high, low, res=24, max_distance=0.05, map_formats=["ao"], ao_samples=samples,
             ao_distance=distance)
    ao = r.maps["ao"][_interior((24, 24), 0.25)]
    truth = (h / distance) ** 2
    assert np.all(np.isfinite(r.maps["ao"]))
    assert abs(ao.mean() - truth) < _se_bound(truth, ao.size * samples)
    # with the ceiling out of reach the floor is fully open
    r = bake(high, low, res=8, max_distance=0.05, map_formats=["ao"], ao_samples=16,
             ao_distance=0.9 * h)
    assert np.all(r.maps["ao"] == 1.0)


@pytest.mark.parametrize("alpha_deg", [30.0, 60.0, 90.0])
def test_ao_v_groove_crease(variant, alpha_deg):
    """At the crease of a V groove whose walls make angle alpha with the normal, the open
    directions (|x| < z tan alpha) project onto the unit disk as the ellipse
    x^2 / sin^2 alpha + y^2 < 1: AO = sin(alpha) (alpha = 90 degrees: a plane, AO = 1)."""
    import drjit as dr

    from mi_displace.bake.occlusion import ambient_occlusion

    a = np.radians(alpha_deg)
    L = 1e3   # walls far larger than anything a ray could pass
    wall = np.array([[0, -L, 0], [0, L, 0], [L * np.sin(a), L, L * np.cos(a)],
                     [L * np.sin(a), -L, L * np.cos(a)]], np.float32)
    other = wall * np.array([-1, 1, 1], np.float32)
    mesh = mi.Mesh("groove", 8, 4)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.concatenate([wall, other]).ravel())
    params["faces"] = mi.UInt32(np.array([0, 1, 2, 0, 2, 3, 4, 6, 5, 4, 7, 6], np.uint32))
    params.update()
    scene = mi.load_dict({"type": "scene", "groove": mesh})
    lanes, samples = 2048, 64
    x = dr.zeros(mi.Point3f, lanes)
    up = mi.Vector3f(0, 0, 1) + dr.zeros(mi.Vector3f, lanes)
    ao = ambient_occlusion(scene, x, up, up, dr.arange(mi.UInt64, lanes), samples, dr.inf, 1e-5, 7)
    ao = np.asarray(ao)
    truth = np.sin(a)
    assert np.all(np.isfinite(ao))
    assert abs(ao.mean() - truth) < _se_bound(truth, lanes * samples)


def test_ao_seeded_and_independent_of_blocks(variant, monkeypatch):
    """The same seed gives the same map, whatever the block size; another seed another."""
    from mi_displace.bake import baker

    high, low = _floor_and_ceiling(0.2)
    kw = dict(res=16, aa=2, max_distance=0.05, map_formats=["ao"], ao_samples=8, ao_distance=0.4)
    a = baker.bake(high, low, ao_seed=3, **kw).maps["ao"]
    monkeypatch.setattr(baker, "CHUNK_SAMPLES", 16 * 4 * 3)   # three rows per block
    b = baker.bake(high, low, ao_seed=3, **kw).maps["ao"]
    c = baker.bake(high, low, ao_seed=4, **kw).maps["ao"]
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_ao_settings_errors(variant):
    from mi_displace.bake.baker import bake

    high, low = _floor_and_ceiling(0.2)
    for kw, name in (({"ao_samples": 0}, "ao_samples"), ({"ao_distance": -1.0}, "ao_distance"),
                     ({"ao_seed": -2}, "ao_seed"), ({"green": "y"}, "green"),
                     ({"curvature_range": 0.0}, "curvature_range")):
        with pytest.raises(ValueError, match=name):
            bake(high, low, res=8, map_formats=["ao"], **kw)
    with pytest.raises(ValueError, match="high_texture"):
        bake(high, low, res=8, map_formats=["albedo"])


def _cylinder(n_around, n_along, radius, height, uv=True):
    """An open cylinder around z (outward normals), z in [0, height], UVs (angle / 2 pi,
    z / height) with a seam column of twins."""
    from mi_displace.bake.meshdata import MeshData

    t = np.linspace(0, 2 * np.pi, n_around + 1)
    z = np.linspace(0, height, n_along + 1)
    T, Z = np.meshgrid(t, z, indexing="xy")
    A = T % (2 * np.pi)                         # the seam twins at bit-identical positions
    pos = np.stack([radius * np.cos(A), radius * np.sin(A), Z], -1).reshape(-1, 3)
    i = np.arange(n_along)[:, None] * (n_around + 1) + np.arange(n_around)[None, :]
    i = i.ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n_around + 2], 1),
                            np.stack([i, i + n_around + 2, i + n_around + 1], 1)])
    uvs = np.stack([T / (2 * np.pi), Z / height], -1).reshape(-1, 2).astype(np.float32) if uv else None
    return MeshData(pos.astype(np.float32), faces.astype(np.int64), uvs, name="cylinder")


def test_mean_curvature_closed_forms(variant):
    """Vertex mean curvature: 1/r on a sphere, 1/(2r) on a cylinder's interior rows, the
    sign flipping with the orientation."""
    from mi_displace.bake.curvature import mean_curvature
    from mi_displace.bake.meshdata import weld_ids

    s = _sphere_mesh(128, 64, 0.0)
    w = weld_ids(s.positions)
    pos = np.zeros((w.max() + 1, 3), np.float32)
    pos[w] = s.positions * 2.0                      # radius 2
    H = mean_curvature(pos, w[s.faces])
    z = np.abs(pos[:, 2]) / 2
    body = z < 0.9                                   # away from the poles' fans
    assert np.all(np.isfinite(H))
    assert np.median(H[body]) == pytest.approx(0.5, rel=0.01)
    assert np.percentile(np.abs(H[body] - 0.5), 95) < 0.02
    assert np.median(mean_curvature(pos, w[s.faces][:, ::-1])[body]) == pytest.approx(-0.5, rel=0.01)
    c = _cylinder(64, 16, 0.5, 2.0, uv=False)
    w = weld_ids(c.positions)
    cpos = np.zeros((w.max() + 1, 3), np.float32)
    cpos[w] = c.positions
    Hc = mean_curvature(cpos, w[c.faces])
    inner = (cpos[:, 2] > 0.01) & (cpos[:, 2] < 1.99)
    assert np.allclose(Hc[inner], 1.0, rtol=0.01)


def test_bake_curvature_sphere_and_cylinder(variant, tmp_path):
    """The baked curvature map reads 1/r on a sphere and 1/(2r) on a cylinder; a sphere has
    no cavity; the PNG and EXR open as Mitsuba bitmaps and decode to the same values."""
    from mi_displace.bake.baker import bake
    from mi_displace.bake.formats import read_map

    high = _sphere_mesh(192, 96, 0.0)
    high.uvs = None
    r = bake(high, _sphere_mesh(48, 24, 0.0), res=64, map_formats=["curvature_float", "cavity"],
             out_dir=tmp_path / "s")
    v = (np.arange(64) + 0.5) / 64
    band = np.abs(np.cos(np.pi * v)) < 0.8         # rows away from the poles (v = polar angle)
    H = r.maps["curvature"][band][r.covered[band]]
    assert np.all(np.isfinite(r.maps["curvature"]))
    assert np.median(H) == pytest.approx(1.0, rel=0.02)
    assert np.all(r.maps["cavity"] == 0.0)
    back = read_map(tmp_path / "s" / "curvature_float.exr")["curvature"]
    assert np.array_equal(back, r.maps["curvature"])
    cyl = bake(_cylinder(128, 32, 0.5, 2.0, uv=False), _cylinder(24, 4, 0.5, 2.0), res=64,
               map_formats=["curvature"], out_dir=tmp_path / "c", curvature_range=2.0)
    rows = slice(16, 48)                           # z in [0.5, 1.5]: away from the open rims
    Hc = cyl.maps["curvature"][rows][cyl.covered[rows]]
    assert np.median(Hc) == pytest.approx(1.0, rel=0.02)
    decoded = read_map(tmp_path / "c" / "curvature.png")["curvature"][rows][cyl.covered[rows]]
    assert np.abs(decoded - Hc).max() < 2 * 2.0 / 65535 + 1e-6
    for file in ("s/cavity.png", "c/curvature.png", "s/curvature_float.exr"):
        texture = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / file), "raw": True})
        assert np.all(np.isfinite(np.asarray(mi.traverse(texture)["data"])))


def test_cavity_inside_a_sphere(variant):
    """Seen from inside (faces flipped), the sphere is a cavity: H = -1 everywhere, so with
    curvature_range 2 the cavity map reads 0.5."""
    from mi_displace.bake.baker import bake

    high = _sphere_mesh(128, 64, 0.0)
    high.uvs, high.faces = None, high.faces[:, ::-1].copy()
    low = _sphere_mesh(32, 16, 0.0)
    low.faces = low.faces[:, ::-1].copy()
    r = bake(high, low, res=32, map_formats=["cavity_float"], curvature_range=2.0)
    band = np.abs(np.cos(np.pi * (np.arange(32) + 0.5) / 32)) < 0.8
    assert np.median(r.maps["cavity"][band][r.covered[band]]) == pytest.approx(0.5, abs=0.01)


def _checker(cells, size):
    """(size, size, 3) linear RGB checker of cells x cells squares: red and blue."""
    i = (np.arange(size) * cells // size)
    odd = (i[:, None] + i[None, :]) % 2 == 1
    return np.where(odd[..., None], [0.8, 0.1, 0.1], [0.1, 0.2, 0.9]).astype(np.float32)


def test_albedo_checker_transfer(variant, tmp_path):
    """A high-poly plane whose UVs tile a 4 x 4 checker twice (u_high = 2 x, v_high = 2 y)
    over a low-poly whose UVs are (x, y): the low-poly texel at (u, v) must show checker
    cell (floor(8 u), floor(8 v)) parity; texels near cell edges (bilinear blur) skipped."""
    from mi_displace.bake.baker import bake

    high = plane(1.0, n=8)
    high.uvs = high.uvs * 2.0
    tex = _checker(4, 64)
    res = 64
    r = bake(high, plane(1.0, n=2), res=res, max_distance=0.05, high_texture=tex,
             map_formats=["albedo", "albedo_float"], out_dir=tmp_path)
    u = (np.arange(res) + 0.5) / res
    v = 1 - u
    U, V = np.meshgrid(u, v, indexing="xy")
    cu, cv = U * 8, V * 8
    # the checker's rows run top-down (row 0 at v = 1): cell row = 3 - floor(4 v_high) mod 4
    odd = (np.floor(cu) + (3 - np.floor(cv) % 4)) % 2 == 1
    away = (np.abs(cu - np.round(cu)) > 0.15) & (np.abs(cv - np.round(cv)) > 0.15)
    truth = np.where(odd[..., None], [0.8, 0.1, 0.1], [0.1, 0.2, 0.9])
    albedo = r.maps["albedo"]
    assert np.all(np.isfinite(albedo))
    assert np.abs(albedo[away] - truth[away]).max() < 1e-4
    # the sRGB 16-bit PNG read by a plain bitmap gives the linear albedo back
    texture = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / "albedo.png")})
    back = np.asarray(mi.traverse(texture)["data"])
    assert np.abs(back[away] - albedo[away]).max() < 2e-3
    exr = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / "albedo_float.exr"), "raw": True})
    assert np.abs(np.asarray(mi.traverse(exr)["data"]) - albedo).max() < 1e-6


def test_albedo_vertex_colours(variant):
    """Vertex colours linear in position interpolate exactly: albedo = (x, y, 0.5)."""
    from mi_displace.bake.baker import bake

    high = plane(1.0, n=6, uv=False)
    colours = np.concatenate([high.positions[:, :2], np.full((len(high.positions), 1), 0.5)], 1)
    r = bake(high, plane(1.0, n=1), res=16, max_distance=0.05, high_colors=colours,
             map_formats=["d16"])
    u = (np.arange(16) + 0.5) / 16
    U, V = np.meshgrid(u, 1 - u, indexing="xy")
    assert np.abs(r.maps["albedo"] - np.dstack([U, V, np.full_like(U, 0.5)])).max() < 1e-5


def test_directx_green(variant, sphere_pair, tmp_path):
    """green="-y" writes G = 1 - G of the OpenGL map (8 and 16 bit, float), R and B equal;
    mikk_normalmap told the convention (the fragment's ``green``) decodes both alike."""
    from mi_displace.bake.baker import bake
    from mi_displace.bake.formats import read_map
    from mi_displace.bake.preview import decode_errors
    from mi_displace.bake.trace import AMBIGUOUS, OK

    high, low = sphere_pair
    fmts = ["normal_tangent", "normal_tangent16", "float"]
    runs = {g: bake(high, low, res=48, map_formats=fmts, out_dir=tmp_path / g, green=g)
            for g in ("+y", "-y")}
    for fmt, levels in (("normal_tangent.png", 255), ("normal_tangent16.png", 65535)):
        gl = np.asarray(mi.Bitmap(str(tmp_path / "+y" / fmt)), np.int64)
        dx = np.asarray(mi.Bitmap(str(tmp_path / "-y" / fmt)), np.int64)
        assert np.array_equal(dx[..., 1], levels - gl[..., 1])
        assert np.array_equal(dx[..., [0, 2]], gl[..., [0, 2]])
        assert np.array_equal(read_map(tmp_path / "-y" / fmt)["normal_tangent"],
                              read_map(tmp_path / "+y" / fmt)["normal_tangent"])
    gl = read_map(tmp_path / "+y" / "float.exr")["normal_tangent"]
    dx = read_map(tmp_path / "-y" / "float.exr")["normal_tangent"]
    assert np.abs(gl - dx).max() < 1e-6
    assert '<string name="green" value="-y"/>' in (tmp_path / "-y" / "mitsuba_normalmap.xml").read_text()
    r = runs["-y"]
    measured = (r.status == OK) | (r.status == AMBIGUOUS)
    errors = {g: decode_errors(tmp_path / g, runs[g].low, runs[g].maps["normal_object"], measured)["mikk"]
              for g in runs}
    assert errors["-y"]["mean_deg"] == pytest.approx(errors["+y"]["mean_deg"], abs=1e-3)
    assert errors["-y"]["mean_deg"] < 0.5


def test_cli_surface_maps_and_green(variant, tmp_path, capsys):
    """`mi-displace bake` with the surface-map options: the files, the settings in bake.json
    and the sidecars, the fragment's green; a bad --green is refused by the parser."""
    import json

    from mi_displace.bake.meshdata import save_obj
    from mi_displace.cli import main

    high, low = _floor_and_ceiling(0.2)
    save_obj(tmp_path / "high.obj", high.positions, high.faces)
    save_obj(tmp_path / "low.obj", low.positions, low.faces, low.uvs)
    texture = tmp_path / "texture.png"
    bitmap = mi.Bitmap(np.full((4, 4, 3), 128, np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB)
    bitmap.set_srgb_gamma(True)
    bitmap.write(str(texture))
    args = ["bake", "--high", str(tmp_path / "high.obj"), "--low", str(tmp_path / "low.obj"),
            "--res", "8", "--out", str(tmp_path / "out"), "--max-distance", "0.05",
            "--formats", "ao_float,cavity,normal_tangent", "--ao-samples", "4",
            "--ao-distance", "0.4", "--ao-seed", "5", "--curvature-range", "2", "--green=-y"]
    assert main(args) == 0
    rec = json.loads((tmp_path / "out" / "bake.json").read_text())["settings"]
    assert rec["ao"] == {"samples": 4, "distance": 0.4, "seed": 5, "point": "high-poly hit"}
    assert rec["green"] == "-y" and rec["curvature_range"] == 2.0
    assert json.loads((tmp_path / "out" / "cavity.png.json").read_text())["curvature_range"] == 2.0
    assert 'value="-y"' in (tmp_path / "out" / "mitsuba_normalmap.xml").read_text()
    ao = np.asarray(mi.Bitmap(str(tmp_path / "out" / "ao_float.exr")))
    assert np.all(np.isfinite(ao)) and 0.0 <= ao.min() and ao.max() <= 1.0
    # --high-texture adds the albedo map: a uniform grey 128 (sRGB) reads back as its linear value
    save_obj(tmp_path / "high_uv.obj", high.positions, high.faces, high.positions[:, :2])
    assert main(args[:2] + [str(tmp_path / "high_uv.obj")] + args[3:8] + [str(tmp_path / "tex")]
                + args[9:] + ["--high-texture", str(texture)]) == 0
    albedo = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / "tex" / "albedo.png")})
    grey = ((128 / 255 + 0.055) / 1.055) ** 2.4
    assert np.abs(np.asarray(mi.traverse(albedo)["data"]) - grey).max() < 2e-3
    with pytest.raises(SystemExit):
        main(args[:-1] + ["--green", "z"])
    capsys.readouterr()
