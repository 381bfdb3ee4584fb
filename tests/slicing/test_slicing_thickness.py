"""The thickness check of ``displaced`` applied to slicing on mesh bases: a two-walled
shell whose walls both face outwards (as a modeller may leave a cup or a teapot's lip)
puts the inner wall's displacement volume through the outer wall 0.015 away; its slices
then hide the outer relief.  A scale above the gap warns naming ``scale`` (at load and
after a ``traverse`` edit, without casting the rays again); one below it is silent."""
import warnings

import numpy as np
import pytest
import mitsuba as mi

from tests.core.test_thickness import WALL, shell_mesh
from tests.plugins.test_displaced_seams import write_obj


def outward_shell(path):
    pos, _, uvs, faces = shell_mesh()
    half = len(faces) // 2
    faces = np.concatenate([faces[:half], faces[half:][:, ::-1]])   # inner wall faces out too
    return write_obj(path, pos, uvs, np.stack([faces, faces], -1))


def load(path, scale):
    return mi.load_dict({"type": "slicing", "id": "shell", "base": "mesh", "filename": path,
                         "scale": scale, "slices": 4, "direction": "a",
                         "height": {"type": "uniform", "value": 1.0}})


def test_slices_through_the_other_wall_warn_naming_scale(variant, tmp_path, monkeypatch):
    from mi_displace.core import thickness

    path = outward_shell(tmp_path / "shell.obj")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        shape = load(path, 0.5 * WALL)
    assert shape.build_stats["crossing_vertices"] == 0
    with pytest.warns(UserWarning, match="slicing 'shell'.*lower 'scale'") as record:
        deep = load(path, 2 * WALL)
    inner = len(shell_mesh()[0]) // 2
    # every inner-wall vertex reaches the outer wall (a ray meeting it exactly at a
    # vertex or an edge may slip through), twice as far as the gap
    assert deep.build_stats["crossing_vertices"] > 0.95 * inner
    assert "2.00x" in str(record[0].message)
    casts, cast = [], thickness.cast_crossing_rays
    monkeypatch.setattr(thickness, "cast_crossing_rays", lambda *a: casts.append(1) or cast(*a))
    params = mi.traverse(shape)
    params["scale"] = 2 * WALL
    with pytest.warns(UserWarning, match="slicing 'shell'"):
        params.update()
    assert not casts and shape.build_stats["crossing_vertices"] == deep.build_stats["crossing_vertices"]
