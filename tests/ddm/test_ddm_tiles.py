"""Detail tiles: validity, normals and tangent frames, the shapes the paper needs."""
import numpy as np
import pytest
import trimesh

from mi_displace.ddm import tiles

BUILTIN = ["thorn", "flower", "chain", "hair", "hexagon", "stone", "stone:5"]


@pytest.mark.parametrize("name", BUILTIN)
def test_builtin_tiles_are_valid(name):
    t = tiles.get_tile(name)
    assert t.vertex_count > 0 and t.face_count > 0
    assert np.all(np.isfinite(t.positions)) and np.all(np.isfinite(t.tangents))
    assert np.allclose(np.linalg.norm(t.normals, axis=1), 1, atol=1e-5)
    t1, t2 = t.tangents[:, 0], t.tangents[:, 1]
    assert np.allclose(np.einsum("ij,ij->i", t1, t.normals), 0, atol=1e-5)
    assert np.allclose(np.cross(t1, t2), t.normals, atol=1e-5)
    assert t.faces.max() < t.vertex_count
    # tiles live over the unit square (a chain link may reach into the next tile)
    assert t.positions[:, :2].min() > -0.3 and t.positions[:, :2].max() < 1.3


def _vertical_hits(tile, x, y):
    mesh = trimesh.Trimesh(tile.positions, tile.faces, process=False)
    loc, _, _ = mesh.ray.intersects_location([[x, y, 5.0]], [[0, 0, -1.0]], multiple_hits=True)
    return len(loc)


def test_thorn_is_not_a_height_field():
    t = tiles.thorn()
    tip = t.positions[np.argmax(t.positions[:, 0] * (t.positions[:, 2] > 0.05))]
    # a vertical line just inside the curled tip meets the horn twice, plus the plate
    assert tip[2] < t.positions[:, 2].max() - 0.05
    assert _vertical_hits(t, tip[0] - 0.05, 0.5) >= 3


def test_chain_is_not_homeomorphic_to_the_plane():
    t = tiles.chain()
    mesh = trimesh.Trimesh(t.positions, t.faces, process=False)
    assert mesh.is_watertight
    assert mesh.euler_number == 0          # two tori: genus 1 each
    assert len(mesh.split(only_watertight=False)) == 2


def test_hair_threads_are_open_and_paper_sized():
    t = tiles.hair()
    assert t.face_count == 384             # 8 threads, as the paper's hair tile
    mesh = trimesh.Trimesh(t.positions, t.faces, process=False)
    assert not mesh.is_watertight
    assert len(mesh.split(only_watertight=False)) == 8


def test_hexagon_outline_is_a_regular_hexagon():
    t = tiles.hexagon()
    ground = t.positions[t.positions[:, 2] < 1e-6]
    w, h = np.ptp(ground[:, 0]), np.ptp(ground[:, 1])
    assert w == pytest.approx(1.0, abs=1e-6) and h == pytest.approx(1.0, abs=1e-6)
    assert t.positions[:, 2].max() == pytest.approx(1.0)


def test_stones_share_topology_but_differ():
    a, b = tiles.get_tile("stone:1"), tiles.get_tile("stone:2")
    assert a.compatible_with(b)
    assert not np.allclose(a.positions, b.positions)


def test_thorn_and_flower_are_metamorphosis_partners():
    assert tiles.thorn().compatible_with(tiles.flower())
    assert not tiles.thorn().compatible_with(tiles.chain())


def test_mesh_file_tile_round_trip(tmp_path):
    t = tiles.hexagon()
    path = tmp_path / "hex.obj"
    trimesh.Trimesh(t.positions, t.faces, process=False).export(path)
    loaded = tiles.get_tile(str(path))
    assert loaded.vertex_count == t.vertex_count
    assert np.allclose(loaded.positions, t.positions, atol=1e-5)


def test_empty_and_zero_size_tiles_are_refused(tmp_path):
    with pytest.raises(ValueError, match="empty"):
        tiles.make_tile("nothing", np.zeros((0, 3)), np.zeros((0, 3), int))
    with pytest.raises(ValueError, match="zero size"):
        tiles.make_tile("dot", np.zeros((3, 3)), [[0, 1, 2]])
    with pytest.raises(ValueError, match="NaN"):
        tiles.make_tile("nan", [[0, 0, 0], [1, 0, np.nan], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(ValueError, match="face indices"):
        tiles.make_tile("bad", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(ValueError, match="empty"):
        tiles.get_tile(str(empty))


def test_bad_tile_names_and_files():
    with pytest.raises(ValueError, match="unknown tile 'spiky'"):
        tiles.get_tile("spiky")
    with pytest.raises(ValueError, match="stone:SEED"):
        tiles.get_tile("thorn:3")
    with pytest.raises(FileNotFoundError, match="missing.obj"):
        tiles.get_tile("/nowhere/missing.obj")


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


def test_plate_is_an_n_by_n_grid_over_the_unit_square():
    """plate(n): (n + 1)^2 vertices, 2 n^2 triangles facing +z, every vertex used, covering
    [0, 1]^2 once (total area 1)."""
    p, f = tiles.plate(4)
    assert p.shape == (25, 3) and f.shape == (32, 3)
    assert f.max() == 24 and len(np.unique(f)) == 25
    cross = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    assert np.all(cross[:, 2] > 0) and 0.5 * cross[:, 2].sum() == pytest.approx(1.0)


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
