"""A textured high-poly's own UV seams, restoration of closed low-polys, the low.obj layout."""
import numpy as np
from conftest import AMPLITUDE, _sphere_mesh

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
