"""Base meshes with UVs (PLY/OBJ) for the shapes that displace or tile over a mesh.

File names resolve like Mitsuba's own plugins: through ``mi.file_resolver()``, which holds
the scene file's folder while an XML scene loads, so a scene works from any working
directory; a name the resolver does not know stays relative to the current directory.
"""
from __future__ import annotations

import os
import re

import mitsuba as mi
import numpy as np


def resolve_path(name: str) -> str:
    """``name`` resolved like Mitsuba's own plugins do (relative to the scene file)."""
    return str(mi.file_resolver().resolve(str(name)))


def _mitsuba_reason(error: RuntimeError) -> str:
    """The last sentence of a Mitsuba error, without its ``[file.cpp:line]`` tags."""
    return " ".join(re.sub(r"\[[\w.]+(?::\d+)?\]\s*", "", str(error)).split()).rsplit(": ", 1)[-1]


def load_uv_mesh(filename: str, owner: str = "displaced"):
    """Load a PLY/OBJ mesh with vertex UVs.

    Args:
        filename: path, resolved with :func:`resolve_path`.
        owner: plugin name used in error messages (``"displaced"``, ``"ddm"`` ...).

    Returns:
        ``(positions (V, 3) float32, normals (V, 3) float32, uvs (V, 2) float32,
        faces (F, 3) int64)`` in object space; normals are recomputed (area-weighted) when
        the file has none.

    Raises:
        FileNotFoundError / ValueError naming ``filename`` before any kernel runs.
    """
    path = resolve_path(filename)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{owner}: base mesh 'filename' not found: {filename}")
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".ply", ".obj"):
        raise ValueError(f"{owner}: base mesh {filename!r} must be .ply or .obj")
    try:
        mesh = mi.load_dict({"type": ext[1:], "filename": path, "face_normals": False})
    except RuntimeError as e:  # Mitsuba's reader: a malformed file
        raise ValueError(f"{owner}: base mesh {filename!r} is not a valid "
                         f"{ext[1:].upper()} mesh: {_mitsuba_reason(e)}") from None
    if mesh.face_count() == 0 or mesh.vertex_count() < 3:
        raise ValueError(f"{owner}: base mesh {filename!r} has no triangles "
                         f"({mesh.vertex_count()} vertices, {mesh.face_count()} faces)")
    if not mesh.has_vertex_texcoords():
        raise ValueError(
            f"{owner}: base mesh {filename!r} has no UVs (vertex texture coordinates); "
            "unwrap it first (e.g. xatlas or Blender's Smart UV Project)")
    if not mesh.has_vertex_normals():
        try:
            mesh.recompute_vertex_normals()
        except RuntimeError as e:
            raise ValueError(f"{owner}: base mesh {filename!r} has no usable vertex normals "
                             f"and none can be computed: {_mitsuba_reason(e)}") from None
    params = mi.traverse(mesh)
    pos = np.asarray(params["vertex_positions"], np.float32).reshape(-1, 3)
    nrm = np.asarray(params["vertex_normals"], np.float32).reshape(-1, 3)
    uvs = np.asarray(params["vertex_texcoords"], np.float32).reshape(-1, 2)
    faces = np.asarray(params["faces"], np.int64).reshape(-1, 3)
    return pos, nrm, uvs, faces
