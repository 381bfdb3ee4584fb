"""A clean low-poly: faces no 2-manifold has (duplicate, back-to-back, zero-area) are found,
removed from a generated low-poly and named in a warning for a user's one."""
from pathlib import Path

import numpy as np
import pytest
from bake_meshes import plane

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData, edge_counts, face_defects, load_mesh, weld_ids
from mi_displace.bake.unwrap import make_low_poly

DATA = Path(__file__).resolve().parents[2] / "data"


def _with_defects():
    """A 2 x 2 plane (faces 0-7) plus a duplicate of face 0 (8), a flap (9, 10: both windings
    of a triangle on a tip vertex only they use, like the issue's blub pair) and a sliver (11:
    three collinear corners, one a twin of vertex 1)."""
    m = plane(n=2)
    p = np.vstack([m.positions, [[0.25, 0.25, 0.3]], [[0.5, 0.0, 0.0]]]).astype(np.float32)
    tip, twin = len(m.positions), len(m.positions) + 1        # twin: vertex 1's position again
    extra = [m.faces[0], [0, 1, tip], [1, 0, tip], [0, twin, 2]]
    faces = np.vstack([m.faces, extra]).astype(np.int64)
    uv = np.vstack([m.uvs, [[0.25, 0.25], [0.5, 0.0]]]).astype(np.float32)
    return MeshData(p, faces, uv, name="defects")


def test_face_defects_are_found_exactly():
    m = _with_defects()
    d = face_defects(m.positions, m.faces)
    assert d["duplicate"].tolist() == [8]
    assert d["back_to_back"].tolist() == [9, 10]
    assert d["zero_area"].tolist() == [11]          # (0, twin of 1, 2): collinear corners
    clean = plane(n=3)
    assert not any(len(v) for v in face_defects(clean.positions, clean.faces).values())


def test_a_user_low_poly_with_defects_is_named_in_a_warning(variant):
    high = plane(n=8, z=0.01)
    with pytest.warns(UserWarning, match=r"not a 2-manifold: 1 duplicate \(faces 8\); "
                                         r"2 back-to-back \(faces 9, 10\); 1 zero-area \(faces 11\)"):
        bake(high, _with_defects(), res=16, max_distance=0.1)


@pytest.mark.parametrize("mesh", ["spot/spot_triangulated.obj", "bunny/stanford-bunny.obj"])
def test_the_generated_low_poly_is_manifold_where_the_high_poly_is(variant, mesh):
    high = load_mesh(DATA / mesh)
    low = make_low_poly(high, min(3000, len(high.faces) // 2))
    assert not any(len(v) for v in face_defects(low.positions, low.faces).values())
    e_high = edge_counts(high.faces, weld_ids(high.positions))
    e_low = edge_counts(low.faces, weld_ids(low.positions))
    assert e_low["non_manifold_edges"] == 0
    if e_high["boundary_edges"] == 0:                 # closed: closed, same Euler characteristic
        def euler(m):
            w = weld_ids(m.positions)[m.faces]
            edges = np.unique(np.sort(np.stack([w, np.roll(w, -1, axis=1)], 2).reshape(-1, 2), axis=1), axis=0)
            return len(np.unique(w)) - len(edges) + len(m.faces)
        assert e_low["boundary_edges"] == 0 and euler(low) == euler(high)


def test_make_low_poly_drops_the_faces_a_decimation_leaves(variant, monkeypatch):
    """fast-simplification returning a duplicate, a flap and a sliver: they are removed (with
    the tip only the flap used) and said in the notes."""
    import fast_simplification

    m = _with_defects()
    monkeypatch.setattr(fast_simplification, "simplify",
                        lambda points, faces, target_reduction: (m.positions.astype(np.float64), m.faces))
    low = make_low_poly(plane(n=8), 12, 0)
    assert len(low.faces) == 8 and len(low.positions) == 9          # tip and twin are gone
    assert not any(len(v) for v in face_defects(low.positions, low.faces).values())
    assert "removed 1 duplicate (faces 8); 2 back-to-back (faces 9, 10); 1 zero-area (faces 11)" in low.notes[-1]
