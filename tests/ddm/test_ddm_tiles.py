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
