"""Tests written to kill mutants of the ddm/ modules that survived the other tests
(issue 19, docs/testing.md, "Remaining ddm/ and core/ modules")."""
from __future__ import annotations
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.surfaces import make_base
from mi_displace.ddm import base_maps, tiles


def _np(v):
    return np.stack([np.asarray(c) for c in v], 1)


# --- ddm/tiles.py --------------------------------------------------------------------------

@pytest.mark.parametrize("normal_axis,long_axis", [(2, 0), (1, 0), (0, 2)])
def test_stadium_is_a_closed_curve_of_evenly_spaced_distinct_points(normal_axis, long_axis):
    """The chain's links: n points at equal arc-length steps around a stadium (a segment of
    half length L along long_axis, swept by radius r in the plane normal to normal_axis,
    centred at ``center``): every point at distance r from the segment, in the plane, and
    the closing step as long as the others (no point repeated)."""
    center, half, r, n = np.array([0.5, 0.4, 0.12]), 0.22, 0.12, 32
    pts = tiles._stadium(center, half, r, normal_axis, long_axis, n)
    assert pts.shape == (n, 3)
    assert np.allclose(pts[:, normal_axis], center[normal_axis])
    other = 3 - normal_axis - long_axis
    x = pts[:, long_axis] - center[long_axis]
    y = pts[:, other] - center[other]
    dist = np.hypot(x - np.clip(x, -half, half), y)       # distance to the segment
    assert np.allclose(dist, r, atol=1e-12)
    step = np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)
    perimeter = 4 * half + 2 * np.pi * r
    assert step.min() > 0.9 * perimeter / n and step.max() <= perimeter / n + 1e-12


def test_chain_links_have_their_stated_sizes():
    """chain(): a flat link (half length 0.22, radius 0.12, in the plane z = 0.12) and a
    standing one (0.1, 0.1, in y = 0.5, centred at x = 1), both tubes of radius 0.04: the
    tile's bounding box is theirs (the polygonal tubes lie inside it, by less than the
    sagitta of 8 sides and 16 path points)."""
    p = tiles.chain().positions
    box_lo = [0.5 - 0.22 - 0.12 - 0.04, 0.5 - 0.12 - 0.04, 0.12 - 0.1 - 0.04]
    box_hi = [1.0 + 0.1 + 0.1 + 0.04, 0.5 + 0.12 + 0.04, 0.12 + 0.1 + 0.04]
    assert np.all(p.min(0) >= np.array(box_lo) - 1e-6) and np.all(p.max(0) <= np.array(box_hi) + 1e-6)
    assert np.allclose(p.min(0), box_lo, atol=6e-3) and np.allclose(p.max(0), box_hi, atol=6e-3)


# --- ddm/base_maps.py ----------------------------------------------------------------------

def test_clamped_count_on_open_axes_takes_the_nearest_texel(variant):
    """Open axes: texel i holds u = i / (r - 1); a point is clamped when its nearest texel
    (round(u (r - 1))) is invalid — texel_valid (NumPy) and clamped_count (Dr.Jit) agree
    with that rule, at both ends of the axis too."""
    maps = base_maps.build_maps(make_base("plane"), 11)
    maps.valid[:, 3] = False                 # column u = 0.3
    maps.valid[:, 10] = False                # the last column, u = 1
    u = np.array([0.3, 0.26, 0.34, 0.24, 0.36, 0.5, 0.96, 1.0, 1.5, 0.0])
    v = np.full(len(u), 0.5)
    expect = [True, True, True, False, False, False, True, True, True, False]
    assert np.array_equal(~maps.texel_valid(u, v), expect)
    assert maps.clamped_count(mi.Float(u), mi.Float(v)) == sum(expect)


def test_map_error_skips_every_lookup_that_touches_an_invalid_texel(variant):
    """A texel column marked invalid and filled with garbage (z + 10): map_error must not
    see it (it skips points whose four lookup texels are not all valid), so the error is at
    most that of the intact maps; a lookup that read it would err by about 10."""
    base = make_base("torus")
    maps = base_maps.build_maps(base, 32)
    intact = base_maps.map_error(base, maps, 0.1, samples=1 << 14)
    p = _np(maps.position).copy()
    column = np.arange(32) * 32 + 5          # texels (i = 5, every row j), row-major
    p[column, 2] += 10.0
    maps.position = mi.Vector3f(*(mi.Float(p[:, k].astype(np.float32)) for k in range(3)))
    maps.valid[:, 5] = False
    assert intact < 0.1
    assert base_maps.map_error(base, maps, 0.1, samples=1 << 14) <= intact + 1e-6


def test_geometry_image_bytes_and_resolution_halving_gives_an_int(variant):
    """nbytes: two RGB float32 maps and a 1-byte validity bitmap per texel (§3.1);
    choose_resolution halves a resolution that meets the tolerance while its half does too
    and returns a power of two as an int (an error model e = 1e-2 (32 / R)^2 of the
    diagonal, from R = 512: 128 is the smallest R with e <= 7e-4)."""
    base = make_base("plane")
    maps = base_maps.build_maps(base, 16, 8)
    assert maps.nbytes == 16 * 8 * (2 * 3 * 4 + 1) and type(maps.nbytes) is int
    base = make_base("torus")
    diagonal = base_maps.base_sample_diagonal(base)
    r, trials = base_maps.choose_resolution(
        base, 7e-4, 0.1, start=512, build=lambda r: r,
        error=lambda base, r, w: diagonal * 1e-2 * (32 / r) ** 2)
    assert r == 128 and type(r) is int
    assert [t[0] for t in trials] == [64, 128, 256, 512]


# --- ddm/footprint.py ----------------------------------------------------------------------

from mi_displace.ddm import footprint  # noqa: E402


def test_pixels_per_uv_is_the_projected_step_of_a_pinhole(variant):
    """A perspective sensor at the origin looking along +z (camera space = world space):
    pixels per unit u / v = |d(pixel)/du| of the pinhole x / z, y / z scaled by
    width / (2 tan(fov / 2)), against central differences of that projection."""
    width, height, fov = 64, 48, 40.0
    sensor = mi.load_dict({"type": "perspective", "fov": fov, "fov_axis": "x",
                           "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0],
                                                                      target=[0, 0, 1], up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": width, "height": height}})
    rng = np.random.default_rng(3)
    p = np.stack([rng.uniform(-0.3, 0.3, 50), rng.uniform(-0.2, 0.2, 50), rng.uniform(1, 3, 50)], 1)
    du, dv = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    px, visible = footprint.pixels_per_uv(sensor, p, du, dv)
    scale = width / (2 * np.tan(np.radians(fov) / 2))

    def pixel(x):
        return x[:, :2] / x[:, 2:] * scale

    h = 1e-5
    fd = [np.linalg.norm(pixel(p + h * d) - pixel(p - h * d), axis=1) / (2 * h) for d in (du, dv)]
    assert visible.all()
    assert np.allclose(px, np.maximum(*fd), rtol=1e-5)


def test_orthographic_visibility_needs_front_and_frustum(variant):
    """An orthographic sensor (camera space [-1, 1] across the film width, MARGIN 1.1): a
    point is seen when it is in front of the near plane *and* inside the frame."""
    sensor = mi.load_dict({"type": "orthographic",
                           "film": {"type": "hdrfilm", "width": 40, "height": 20}})
    p = np.array([[0.5, 0.2, 2.0],      # seen
                  [0.5, 0.2, -2.0],     # behind the sensor
                  [1.5, 0.2, 2.0],      # beyond the frame along x
                  [0.5, 0.6, 2.0]])     # beyond it along y (0.55 = 1.1 x 20 / 40)
    d = np.tile([[1.0, 0.0, 0.0]], (4, 1))
    px, visible = footprint.pixels_per_uv(sensor, p, d, 2 * d)
    assert visible.tolist() == [True, False, False, False]
    assert np.allclose(px, 40 / 2 * 2)


def test_auto_resolution_on_the_plane(variant):
    """Found by a mutant's test: base_sample_diagonal stacked the plane's constant z (a
    width-1 array) with n^2-wide x, y, so map_resolution="auto" failed on the plane.  The
    plane [-1, 1]^2 has diagonal 2 sqrt 2, and its bilinear maps are exact: the coarsest R allowed (choose_resolution halved down to
    R = 2, which check_resolution refuses: the plane failed there too)."""
    import warnings

    from mi_displace.ddm.model import DDMConfig, DDMModel

    assert base_maps.base_sample_diagonal(make_base("plane")) == pytest.approx(2 * np.sqrt(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="plane", tile="stone:1", tiles_u=4, tiles_v=4,
                               map_resolution="auto"))
    assert m.maps.ru == base_maps.MIN_MAP_RESOLUTION and m.resolution_rule.startswith("auto: tolerance")


def test_weighted_quantile_ends():
    """_weighted_quantile: the smallest x whose cumulative weight reaches q of the total;
    all the weight on the largest x gives it, and zero total weight gives the largest x."""
    x = np.array([3.0, 1.0, 2.0])
    assert footprint._weighted_quantile(x, np.array([1.0, 0.0, 0.0]), 0.99) == 3.0
    assert footprint._weighted_quantile(x, np.array([0.0, 1.0, 1.0]), 0.99) == 2.0
    assert footprint._weighted_quantile(x, np.array([0.0, 1.0, 1.0]), 0.4) == 1.0
    assert footprint._weighted_quantile(x, np.zeros(3), 0.99) == 3.0


# --- ddm/layout.py -------------------------------------------------------------------------

from mi_displace.ddm.layout import make_layout  # noqa: E402


def test_one_cell_layout_and_one_entry_pattern():
    lay = make_layout("rect", 1, 1)
    assert lay.count == 1 and lay.size == (1.0, 1.0) and lay.offsets.tolist() == [[0.0, 0.0]]
    alt = make_layout("alternate", 3, 2, n_tiles=2, pattern=[[1]])
    assert alt.tile_index.tolist() == [1] * 6


def test_hex_rows_alternate_their_shift_and_gaps_shrink_hexagons():
    """Row j of a hex layout is shifted by half a cell when j is odd (every row, not only
    row 1); gaps shrink each hexagon inside its cell, centred: su = cu (1 - gap_u),
    sv = (4/3) cv (1 - gap_v), the cell's centre kept."""
    n, m, gu, gv = 5, 6, 0.2, 0.1
    lay = make_layout("hex", n, m, gap_u=gu, gap_v=gv)
    cu, cv = 1 / n, 1 / m
    su, sv = lay.size
    assert su == pytest.approx(cu * (1 - gu)) and sv == pytest.approx(cv * 4 / 3 * (1 - gv))
    o = lay.offsets.reshape(m, n, 2)
    for j in range(m):
        centre_u = (np.arange(n) + 0.5 + 0.5 * (j % 2)) * cu
        assert np.allclose(o[j, :, 0] + su / 2, centre_u), j
        assert np.allclose(o[j, :, 1] + sv / 2, (j + 0.5) * cv), j


# --- ddm/charts.py -------------------------------------------------------------------------

from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

from mi_displace.ddm import charts  # noqa: E402

GENUS1 = str(Path(__file__).resolve().parents[2] / "scenes" / "parts" / "ddm_genus1" / "genus1.obj")


def test_tile_reach_is_the_cell_or_the_overhang():
    """tile_reach: how far (uv) a tile's vertices reach from its cell origin — the cell itself
    (max(su, sv)) for a tile inside [0, 1]^2 wherever it sits, the overhang beyond it else."""
    inside = SimpleNamespace(positions=np.array([[0.2, 0.3, 0.0], [0.8, 0.7, 0.1]]))
    over = SimpleNamespace(positions=np.array([[-0.5, 0.1, 0.0], [1.2, 0.9, 0.1]]))
    assert charts.tile_reach([inside], (0.1, 0.25)) == pytest.approx(0.25)
    assert charts.tile_reach([over], (0.1, 0.05)) == pytest.approx(0.1 * 1.7)
    assert charts.tile_reach([inside, over], (0.1, 0.25)) == pytest.approx(0.25)


def test_chart_maps_bytes_and_stats_and_pruned_count(variant):
    """ChartMaps stores two RGB float32 maps and a validity byte per window texel and five
    int32 per chart; its stats count its texels and those off their chart; assign_charts
    prunes exactly the tiles it does not keep (clamp mode keeps straddling tiles)."""
    from mi_displace.ddm.layout import make_layout
    from mi_displace.ddm.tiles import get_tile

    from mi_displace.ddm.model import make_base as make_ddm_base

    base = make_ddm_base("mesh", GENUS1)
    maps = charts.ChartMaps(base, 32, 0.02)
    g = maps.grid
    texels = int(np.sum(g.width * g.height))
    assert maps.nbytes == texels * (2 * 3 * 4 + 1) + base.chart_count * 5 * 4
    assert maps.stats["map_texels"] == texels == len(maps.valid)
    assert maps.stats["clamped_texels"] == int((~maps.valid).sum()) > 0
    assert maps.stats["charts"] == base.chart_count
    layout = make_layout("rect", 12, 12)
    kept, stats = charts.assign_charts(layout, [get_tile("thorn")], base)
    assert 0 < stats["tiles_pruned"] == layout.count - kept.count
    assert stats["tiles_dropped"] == 0 and stats["charts"] == base.chart_count
    dropped, s2 = charts.assign_charts(layout, [get_tile("thorn")], base, "drop")
    assert s2["tiles_dropped"] == s2["tiles_straddling"] == kept.count - dropped.count > 0


# --- ddm/mesh_base.py ----------------------------------------------------------------------

def _cap(radius=2.0):
    """A spherical cap (z > 0.3 of an icosphere) of ``radius`` with exact normals p / r and a
    one-to-one planar UV layout (x, y) / 2 + 1/2: (positions, normals, uvs, faces)."""
    import trimesh

    ico = trimesh.creation.icosphere(3)
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1, keepdims=True)
    faces = ico.faces[np.all(v[ico.faces][:, :, 2] > 0.3, axis=1)]
    used, faces = np.unique(faces, return_inverse=True)
    v = v[used]
    return radius * v, v, v[:, :2] / 2 + 0.5, faces.reshape(-1, 3)


def test_mesh_curvature_bound_is_the_normal_turn_per_length(variant):
    """On a sphere of radius r with exact normals n = p / r, |n_a - n_b| = |p_a - p_b| / r
    on every edge: the bound is exactly +-1 / r."""
    from mi_displace.ddm.mesh_base import MeshBase

    base = MeshBase(*_cap(2.0))
    lo, hi = base.curvature_bounds()
    assert hi == pytest.approx(0.5, rel=1e-4) and lo == -hi
    assert len(base.edge_kappa) == 3 * base.face_count


def test_mesh_sample_is_differentiable_in_uv(variant):
    """With a gradient on (u, v) the barycentrics are recomputed in uv (the ray's carry
    none): the same S as without, and forward-mode dS/du, dS/dv = the triangle's S_u, S_v
    (inside the layout) — also for points outside it, clamped to the boundary (where the
    derivative is that of the clamped point, a boundary edge's direction)."""
    from mi_displace.ddm.mesh_base import MeshBase

    base = MeshBase(*_cap(2.0))
    rng = np.random.default_rng(4)
    r, phi = np.sqrt(rng.uniform(0, 0.16, 200)), rng.uniform(0, 2 * np.pi, 200)
    u0, v0 = 0.5 + r * np.cos(phi), 0.5 + r * np.sin(phi)       # inside the cap's layout (uv radius < 0.46)
    plain = base.sample(mi.Float(u0), mi.Float(v0))
    for axis, expect in ((0, plain.dp_du), (1, plain.dp_dv)):
        u, v = mi.Float(u0), mi.Float(v0)
        dr.enable_grad(u, v)
        s = base.sample(u, v)
        dr.forward(u if axis == 0 else v)
        assert np.allclose(_np(s.p), _np(plain.p), atol=1e-5)
        assert np.allclose(_np(dr.grad(s.p)), _np(expect), atol=1e-3 * np.abs(_np(expect)).max())
    # outside the layout: the clamped point moves along the boundary, so dS/du is a
    # boundary edge's S direction: orthogonal to n and finite
    u, v = mi.Float([0.5, 0.02]), mi.Float([0.999, 0.5])
    dr.enable_grad(u)
    s = base.sample(u, v)
    dr.forward(u)
    g = _np(dr.grad(s.p))
    assert np.all(np.isfinite(g)) and np.abs(g).max() > 0


def test_chart_maps_lookup_reproduces_every_stored_texel(variant):
    """Bilinear interpolation through the texels: a lookup at a texel's own (u, v) in its
    chart returns that texel's P and N — the last row and column of every window too."""
    from mi_displace.ddm.model import make_base as make_ddm_base

    maps = charts.ChartMaps(make_ddm_base("mesh", GENUS1), 16, 0.02)
    g = maps.grid
    chart = mi.UInt32(g.chart_of.astype(np.uint32))
    p, n = maps.lookup(mi.Float(g.u.astype(np.float32)), mi.Float(g.v.astype(np.float32)),
                       False, chart)
    assert np.allclose(_np(p), _np(maps.position), atol=1e-5)
    assert np.allclose(_np(n), _np(maps.normal), atol=1e-5)


def test_model_size_check_for_one_column_and_no_refit_without_auto(variant):
    """A single column of 2^40 cells is refused by the cell-count bound, before any layout
    array is allocated (8 TiB); a model with a given map_resolution does not change its
    maps for sensors (fit_to_sensors: True only when the maps changed)."""
    import warnings

    from mi_displace.ddm.model import DDMConfig, DDMModel

    with pytest.raises(ValueError, match="tiles_u"):
        DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=1, tiles_v=2 ** 40))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="sphere", tile="stone:1", tiles_u=4, tiles_v=4,
                               map_resolution=16))
    maps = m.maps
    assert m.fit_to_sensors([], None) is False and m.maps is maps


def test_plate_is_an_n_by_n_grid_over_the_unit_square():
    """plate(n): (n + 1)^2 vertices, 2 n^2 triangles facing +z, every vertex used, covering
    [0, 1]^2 once (total area 1)."""
    p, f = tiles.plate(4)
    assert p.shape == (25, 3) and f.shape == (32, 3)
    assert f.max() == 24 and len(np.unique(f)) == 25
    cross = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    assert np.all(cross[:, 2] > 0) and 0.5 * cross[:, 2].sum() == pytest.approx(1.0)


def test_diffusion_takes_the_first_texel_as_a_source():
    """Texel 0 (flat index 0) is a valid source like any other: with only the two corners
    valid, every texel nearer to (0, 0) takes texel 0."""
    valid = np.zeros((9, 9), bool)
    valid[0, 0] = valid[8, 8] = True
    src, _ = base_maps.diffuse_fill(valid, False, False)
    yy, xx = np.mgrid[0:9, 0:9]
    near = yy + xx < 6
    assert np.all(src[near] == 0) and np.all(src[yy + xx > 10] == 80)


def test_prune_reads_the_tile_footprint_in_v(variant):
    """A tile covering only the upper part of its cell (y in [0.6, 1]) over maps whose rows
    v >= 0.5 are invalid is pruned; with only rows v >= 0.7 invalid it keeps the valid
    texels at v = 0.5, 0.6 inside its footprint grown by one texel."""
    layout = make_layout("rect", 1, 1)
    bounds = np.array([[0.0, 0.6, 1.0, 1.0]])
    maps = base_maps.build_maps(make_base("plane"), 11)
    maps.valid[5:, :] = False
    assert base_maps.prune(layout, bounds, maps)[1] == 1
    maps.valid[:] = True
    maps.valid[7:, :] = False
    kept, pruned = base_maps.prune(layout, bounds, maps)
    assert pruned == 0 and kept.count == 1


def test_layout_messages_and_the_default_seed():
    """The messages name the parameter whole; ``random`` draws with seed 0 by default (the
    documented default of ``seed``)."""
    import re

    for name in ("u0", "v0"):
        with pytest.raises(ValueError, match=f"^ddm: '{name}' must be finite, got nan$"):
            make_layout("rect", 2, 2, **{name: float("nan")})
    with pytest.raises(ValueError, match="'tiles_v'"):
        make_layout("rect", 2, 0)
    with pytest.raises(ValueError, match="^" + re.escape(
            "ddm: 'pattern' must be rows of tile indices in 0..1") + "$"):
        make_layout("alternate", 2, 2, n_tiles=2, pattern=[[0, 2]])
    a = make_layout("random", 8, 8, n_tiles=3)
    assert np.array_equal(a.tile_index, make_layout("random", 8, 8, n_tiles=3, seed=0).tile_index)
    assert not np.array_equal(a.tile_index, make_layout("random", 8, 8, n_tiles=3, seed=1).tile_index)


def test_footprint_samples_of_mesh_and_analytic_bases(variant):
    """base_samples: a mesh base gives its face centroids with their UV areas as weights
    (Heron's formula here), an analytic base an n x n grid of equal weights with S and its
    derivatives at the grid points; the quantile ignores zero-weight samples below it."""
    from mi_displace.ddm.mesh_base import MeshBase

    pos, nrm, uvs, faces = _cap(2.0)
    base = MeshBase(pos, nrm, uvs, faces)
    p, du, dv, w = footprint.base_samples(base)
    t = uvs[faces]
    a, b, c = (np.linalg.norm(t[:, i] - t[:, j], axis=1) for i, j in ((0, 1), (1, 2), (2, 0)))
    s = (a + b + c) / 2
    assert np.allclose(w, np.sqrt(np.maximum(s * (s - a) * (s - b) * (s - c), 0)), atol=1e-9)
    assert np.allclose(p, pos[faces].mean(1))
    sphere = make_base("sphere")
    p, du, dv, w = footprint.base_samples(sphere, 9)
    assert p.shape == du.shape == dv.shape == (81, 3) and np.array_equal(w, np.ones(81))
    u, v = base_maps.texel_coordinates(9, 9, False, False)
    ref = sphere.sample(u, v)
    assert np.allclose(p, _np(ref.p), atol=1e-6) and np.allclose(dv, _np(ref.dp_dv), atol=1e-5)
    assert np.allclose(np.linalg.norm(p, axis=1), 1, atol=1e-6)
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert footprint._weighted_quantile(x, np.array([0.0, 0.0, 1.0, 1.0]), 0.4) == 3.0


def test_model_w_max_rule_and_memory_ratio(variant):
    """_w_max is the largest |w| of the mapped tiles (exact mode on the plane: the mapped z),
    an offset below the surface included; the rule of a given map_resolution is "given";
    mesh_over_hddm is the ratio of the two byte counts; an unknown base is named."""
    import warnings

    from mi_displace.ddm.model import DDMConfig, DDMModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="plane", tile="thorn", tiles_u=2, tiles_v=2, height=0.1,
                               w_offset=-0.5, mode="exact"))
        maps = DDMModel(DDMConfig(base="sphere", tile="stone:1", tiles_u=4, tiles_v=4,
                                  map_resolution=16))
    p, _, _ = m.map()
    assert m._w_max() == pytest.approx(np.abs(np.asarray(p.z)).max(), rel=1e-5)
    assert maps.resolution_rule == "given" and maps.stats()["map_resolution_rule"] == "given"
    r = maps.memory_report()
    assert r["mesh_over_hddm"] == pytest.approx(r["mesh_bytes"] / r["hddm_bytes"])
    with pytest.raises(ValueError, match=r"^ddm: unknown 'base' 'cube'; expected one of .* or 'mesh'$"):
        DDMConfig(base="cube").check()


def test_chart_map_error_is_zero_on_a_flat_mesh_and_falls_with_resolution(variant):
    """charts.map_error: per-chart bilinear maps of a flat mesh are exact (error ~ 0, normal
    offset included); on a sphere cap (a piecewise-linear mesh: creases make the order about
    1, docs/ddm.md) it is positive and falls with the resolution."""
    from mi_displace.ddm.mesh_base import MeshBase

    flat = MeshBase(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]),
                    np.tile([0, 0, 1.0], (4, 1)),
                    np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]]),
                    np.array([[0, 1, 2], [0, 2, 3]]))
    maps = charts.ChartMaps(flat, 16, 0.0)
    assert "map_build_s" in maps.stats and maps.stats["map_build_s"] >= 0
    assert charts.map_error(flat, maps, 0.3, samples=4096) < 1e-5
    cap = MeshBase(*_cap(2.0))
    e16, e32 = (charts.map_error(cap, charts.ChartMaps(cap, r, 0.0), 0.0, samples=4096)
                for r in (16, 32))
    assert 0 < e32 < e16 / 1.5


def test_mesh_curvature_bound_reads_every_edge_of_a_triangle(variant):
    """One triangle whose normals turn only along its edge (0, 1): the bound is that edge's
    |n_0 - n_1| / |p_0 - p_1| (the other edges turn less per length)."""
    from mi_displace.ddm.mesh_base import MeshBase

    pos = np.array([[0, 0, 0], [0.5, 0, 0], [0, 2, 0.0]])
    n1 = np.array([np.sin(0.3), 0, np.cos(0.3)])
    nrm = np.array([[0, 0, 1.0], n1, [0, 0, 1.0]])
    base = MeshBase(pos, nrm, np.array([[0, 0], [0.25, 0], [0, 1.0]]), np.array([[0, 1, 2]]))
    lo, hi = base.curvature_bounds()
    assert hi == pytest.approx(np.linalg.norm(n1 - [0, 0, 1]) / 0.5, rel=1e-5) and lo == -hi
    assert base.name == "mesh"


def test_hexagon_covers_its_hexagon_once_and_zero_normals_become_up(tmp_path):
    """hexagon(): a height field whose faces all face up and cover the regular hexagon
    inscribed in [0, 1]^2 exactly once (area 3/4 of the square: (3 sqrt 3 / 2) / (2 sqrt 3));
    make_tile: a vanishing given normal becomes +z; a file of another suffix is refused by
    name."""
    t = tiles.hexagon()
    p, f = t.positions.astype(np.float64), t.faces.astype(np.int64)
    a, b = p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]
    signed = 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    assert np.all(signed > 0) and signed.sum() == pytest.approx(0.75, rel=1e-5)
    tri = tiles.make_tile("t", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]],
                           normals=[[0, 0, 0], [0, 0, 2.0], [1e-13, 0, 0]])
    assert np.array_equal(tri.normals, [[0, 0, 1], [0, 0, 1], [0, 0, 1]])
    bad = tmp_path / "tile.txt"
    bad.write_text("x")
    with pytest.raises(ValueError, match=r"^ddm: tile file '.*tile\.txt' must be \.obj or \.ply$"):
        tiles.load_tile_file(bad)


def test_prune_grows_the_footprint_by_one_texel_and_auto_starts_at_a_power_of_two(variant):
    """prune: a tile over y in [0, 0.3] reads rows up to 0.3 (r - 1) + 1 = row 4 of an
    11-row map: pruned when rows 0..4 are invalid although row 5 is valid.
    choose_resolution from its default start: with an error model met by R = 32 and not by
    16 the answer is 32 (a power of two)."""
    layout = make_layout("rect", 1, 1)
    maps = base_maps.build_maps(make_base("plane"), 11)
    maps.valid[:5, :] = False
    assert base_maps.prune(layout, np.array([[0.0, 0.0, 1.0, 0.3]]), maps)[1] == 1
    base = make_base("torus")
    diagonal = base_maps.base_sample_diagonal(base)
    r, _ = base_maps.choose_resolution(base, 1.5e-2, 0.1, build=lambda r: r,
                                       error=lambda base, r, w: diagonal * 1e-2 * (32 / r) ** 2)
    assert r == 32


def test_model_stats_clamped_mask_and_fold_message(variant):
    """An exact-mode model prunes nothing (tiles_pruned 0); on a mesh base (a sphere cap
    with a disc-shaped UV layout) a mapped vertex is clamped exactly when its uv lies off the
    layout (the disc of radius ~0.47 about (0.5, 0.5)); the fold warning of an analytic base
    counts "sampled points of the base"."""
    import warnings

    from mi_displace.ddm.mesh_base import MeshBase
    from mi_displace.ddm.model import DDMConfig, DDMModel, FoldingWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="mesh", tile="stone:1", tiles_u=6, tiles_v=6, height=0.05,
                               mode="exact"), base=MeshBase(*_cap(2.0)))
    assert m.stats()["tiles_pruned"] == m.pruned
    _, _, uv = m.map()
    clamped = m.clamped_mask(uv)
    radius = np.hypot(np.asarray(uv.x) - 0.5, np.asarray(uv.y) - 0.5)
    assert clamped.shape == radius.shape and clamped.any() and not clamped.all()
    assert not clamped[radius < 0.44].any() and clamped[radius > 0.48].all()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exact = DDMModel(DDMConfig(base="sphere", tile="stone:1", tiles_u=4, tiles_v=4,
                                   mode="exact"))
    assert exact.stats()["tiles_pruned"] == 0
    with pytest.warns(FoldingWarning, match=r" of [0-9,]+ sampled points of the base \(det"):
        DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=4, tiles_v=4, height=-4.0,
                           mode="exact"))


def test_mesh_normal_derivatives_match_finite_differences_inside_a_face(variant):
    """dn/du, dn/dv of the unit interpolated normal inside one triangle whose vertex normals
    differ by up to ~70 degrees (|interpolated n| ~ 0.8 at the centre), against central
    differences of n in uv."""
    from mi_displace.ddm.mesh_base import MeshBase

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    nrm = np.array([[0, 0, 1.0], [np.sin(1.2), 0, np.cos(1.2)], [0, np.sin(0.8), np.cos(0.8)]])
    base = MeshBase(pos, nrm, np.array([[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]]), np.array([[0, 1, 2]]))
    u, v, h = mi.Float([0.35, 0.3]), mi.Float([0.35, 0.25]), 1e-3
    s = base.sample(u, v)
    for d, (du, dv) in ((s.dn_du, (h, 0)), (s.dn_dv, (0, h))):
        fd = (_np(base.sample(u + du, v + dv).n) - _np(base.sample(u - du, v - dv).n)) / (2 * h)
        assert np.allclose(_np(d), fd, atol=2e-3 * np.abs(fd).max())


def test_perspective_visibility_needs_front_and_both_frame_axes(variant):
    """Perspective (64 x 48, x_fov 40 degrees, MARGIN 1.1): seen when in front of the near
    plane and |x / z| <= 1.1 t and |y / z| <= 1.1 t (48 / 64), t = tan(20 degrees)."""
    sensor = mi.load_dict({"type": "perspective", "fov": 40.0, "fov_axis": "x",
                           "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0],
                                                                      target=[0, 0, 1], up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 64, "height": 48}})
    t = np.tan(np.radians(20.0))
    p = np.array([[0.1, 0.1, 1.0],                      # seen
                  [0.1, 0.1, -1.0],                     # behind
                  [1.2 * t, 0.0, 1.0],                  # beyond the frame along x
                  [0.0, 0.9 * t, 1.0],                  # beyond it along y (> 1.1 t 0.75)
                  [0.0, 0.8 * t, 1.0]])                 # inside (< 0.825 t)
    d = np.tile([[1.0, 0.0, 0.0]], (5, 1))
    _, visible = footprint.pixels_per_uv(sensor, p, d, d)
    assert visible.tolist() == [True, False, False, False, True]
