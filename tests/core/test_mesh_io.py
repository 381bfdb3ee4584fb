"""Base-mesh loading: names resolve relative to the scene file; bad files are named."""
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.mesh_io import load_uv_mesh

QUAD = """v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1
f 1/1 2/2 3/3\nf 1/1 3/3 4/4
"""


def test_scene_relative_filename_from_another_cwd(variant, tmp_path, monkeypatch):
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "quad.obj").write_text(QUAD)
    (folder / "s.xml").write_text(
        '<scene version="3.0.0"><shape type="displaced">'
        '<string name="filename" value="quad.obj"/><integer name="subdivision" value="4"/>'
        '</shape></scene>')
    monkeypatch.chdir(tmp_path)          # not the scene's folder
    shape = mi.load_file(str(folder / "s.xml")).shapes()[0]
    pos = np.asarray(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)
    assert shape.face_count() == 2 * 4 ** 2
    assert np.all(np.isfinite(pos)) and np.allclose(pos.min(0), 0) and np.allclose(pos.max(0), [1, 1, 0])


def test_normals_recomputed_when_missing(variant, tmp_path):
    (tmp_path / "quad.obj").write_text(QUAD)
    pos, nrm, uvs, faces = load_uv_mesh(str(tmp_path / "quad.obj"))
    assert pos.shape == (4, 3) and uvs.shape == (4, 2) and faces.shape == (2, 3)
    assert np.allclose(nrm, [0, 0, 1], atol=1e-6)


@pytest.mark.parametrize("text, suffix, match", [
    (None, ".obj", "ddm: base mesh 'filename' not found: .*missing.obj"),
    (QUAD, ".stl", "must be .ply or .obj"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ".obj", "has no UVs"),
])
def test_bad_files_are_named(variant, tmp_path, text, suffix, match):
    path = tmp_path / ("missing" + suffix if text is None else "m" + suffix)
    if text is not None:
        path.write_text(text)
    with pytest.raises((FileNotFoundError, ValueError), match=match):
        load_uv_mesh(str(path), "ddm")
