"""The two tangent frames a baked normal map can be decoded in inside Mitsuba.

* **MikkTSpace** (the baker's frame, :mod:`mikktspace`; what Blender, Unity, Unreal and
  glTF decode in): per-vertex tangent ``t`` and bitangent sign ``s``, interpolated with the
  *unnormalised* vertex normal ``n``; ``N = normalize(x t + y s (n x t) + z n)``.  Mitsuba
  has no such frame, so :func:`add_mikktspace` computes it with our port on a loaded
  ``mi.Mesh`` and stores it in three vertex attributes (:data:`ATTR_TANGENT`,
  :data:`ATTR_SIGN`, :data:`ATTR_NORMAL`) that Mitsuba interpolates
  (``shape.eval_attribute_3``); the ``mikk_normalmap`` BSDF decodes with them.
* **Mitsuba's stock frame** (``<bsdf type="normalmap">``): per shading point the
  orthonormal ``si.sh_frame``: ``n`` = normalised interpolated vertex normal,
  ``s = normalize(dp/du - n (n . dp/du))`` with the *per-triangle* ``dp/du`` of
  ``Mesh::compute_surface_interaction``, ``t = n x s``; ``N = normalize(s x + t y + n z)``.
  :func:`stock_frame` reproduces it so the baker can write a map for it (format
  ``normal_mitsuba``).  The frame jumps across every triangle edge, so a bilinearly
  filtered map is exact only at texel centres inside one triangle.

Mitsuba's OBJ reader flips v (``v_mitsuba = 1 - v_obj``); ``dp/du`` does not depend on it.
Units: positions in the mesh's units; vectors unit length unless stated.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.mikktspace import mikktspace

#: vertex attributes :func:`add_mikktspace` adds: (V, 3) tangent, (V,) sign, (V, 3) normal
ATTR_TANGENT, ATTR_SIGN, ATTR_NORMAL = "vertex_mikk_tangent", "vertex_mikk_sign", "vertex_mikk_normal"


def stock_frame(p0, p1, p2, uv0, uv1, uv2, n) -> tuple[mi.Vector3f, mi.Vector3f]:
    """Mitsuba's shading-frame tangents ``(s, t)`` of a triangle (Dr.Jit, per lane).

    Args:
        p0, p1, p2: mi.Point3f corner positions; uv0, uv1, uv2: mi.Point2f corner UVs
            (either v convention); n: mi.Vector3f unit shading normal.

    ``dp/du`` as ``Mesh::compute_surface_interaction`` (zero UV area: ``coordinate_system``
    of the face normal), ``s`` as ``SurfaceInteraction::initialize_sh_frame``.
    """
    dp0, dp1 = p1 - p0, p2 - p0
    duv0, duv1 = uv1 - uv0, uv2 - uv0
    det = duv0.x * duv1.y - duv0.y * duv1.x
    dp_du = mi.Vector3f((duv1.y * dp0 - duv0.y * dp1) * dr.rcp(det))
    fallback, _ = mi.coordinate_system(dr.normalize(dr.cross(dp0, dp1)))
    dp_du = dr.select(det != 0, dp_du, fallback)
    s = dr.normalize(dp_du - n * dr.dot(n, dp_du))
    return s, dr.cross(n, s)


def mikk_decode(x: mi.Vector3f, t: mi.Vector3f, sign: mi.Float, n: mi.Vector3f) -> mi.Vector3f:
    """MikkTSpace's pixel shader: ``normalize(x.x t + x.y sign (n x t) + x.z n)`` with the
    interpolated, unnormalised ``t`` and ``n`` (Mikkelsen 2008, the bitangent per pixel)."""
    b = dr.sign(sign) * dr.cross(n, t)
    return dr.normalize(x.x * t + x.y * b + x.z * n)


def _column(buffer, k: int) -> np.ndarray:
    return np.asarray(buffer).reshape(-1, k)


def add_mikktspace(mesh: mi.Mesh, name: str = "mesh") -> bool:
    """Compute our MikkTSpace port on a loaded mesh (world space, as Mitsuba holds it) and
    add :data:`ATTR_TANGENT` (V, 3), :data:`ATTR_SIGN` (V,) and :data:`ATTR_NORMAL` (V, 3).

    MikkTSpace is per face corner; Mitsuba interpolates per vertex.  A vertex whose corners
    hold different spaces (a fan split by MikkTSpace's groups) is split into one vertex per
    space, so the interpolated frame is the corner-exact one everywhere.

    Returns:
        True when vertices were split (the mesh changed: rebuild the scene's acceleration
        structure, as :func:`prepare_scene` does).

    Raises:
        ValueError naming ``name`` when the mesh has no UVs or no vertex normals (the map
        was baked over smooth vertex normals and UVs).
    """
    params = mi.traverse(mesh)
    if not isinstance(mesh, mi.Mesh) or "vertex_positions" not in params:
        raise ValueError(f"mikk_normalmap: shape {name!r} is not a triangle mesh")
    if not mesh.has_vertex_texcoords():
        raise ValueError(f"mikk_normalmap: shape {name!r} has no UVs (texture coordinates)")
    if not mesh.has_vertex_normals():
        raise ValueError(f"mikk_normalmap: shape {name!r} has no vertex normals (face_normals "
                         "is set, or the file has none): the map needs the smooth normals it "
                         "was baked over")
    p = _column(params["vertex_positions"], 3)
    n = _column(params["vertex_normals"], 3)
    uv_mi = _column(params["vertex_texcoords"], 2)
    uv = np.column_stack([uv_mi[:, 0], 1.0 - uv_mi[:, 1]])   # v up (MikkTSpace's, the baker's)
    faces = _column(params["faces"], 3).astype(np.int64)
    tangents, signs = mikktspace(p, faces, n, uv)
    # one vertex per (vertex, tangent, sign) of its corners, compared bit for bit
    corner = np.column_stack([faces.reshape(-1, 1), tangents.reshape(-1, 3).view(np.int32),
                              signs.reshape(-1, 1).view(np.int32)])
    rows, first, inverse = np.unique(corner, axis=0, return_index=True, return_inverse=True)
    vertex = rows[:, 0]
    split = len(rows) != len(np.unique(faces))
    if split:
        params["vertex_positions"] = mi.Float(np.ascontiguousarray(p[vertex].ravel()))
        params["vertex_normals"] = mi.Float(np.ascontiguousarray(n[vertex].ravel()))
        params["vertex_texcoords"] = mi.Float(np.ascontiguousarray(uv_mi[vertex].ravel()))
        params["faces"] = mi.UInt32(np.ascontiguousarray(inverse.ravel(), np.uint32))
        params.update()
    else:   # the corners agree: keep Mitsuba's vertex order
        order = np.argsort(vertex)
        first, vertex = first[order], vertex[order]
        if len(vertex) != len(p):     # vertices no face uses: any frame (never interpolated)
            full = np.zeros(len(p), np.int64)
            full[vertex] = first
            first = full
    t = tangents.reshape(-1, 3)[first]
    s = signs.ravel()[first]
    mesh.add_attribute(ATTR_TANGENT, 3, mi.Float(np.ascontiguousarray(t.ravel())))
    mesh.add_attribute(ATTR_SIGN, 1, mi.Float(np.ascontiguousarray(s)))
    mesh.add_attribute(ATTR_NORMAL, 3, mi.Float(np.ascontiguousarray(n[vertex if split else
                                                                     slice(None)].ravel())))
    return split


def prepare_scene(scene: mi.Scene) -> int:
    """Give every shape whose BSDF decodes in a frame of its own (``prepare_shape``, the
    ``mikk_normalmap`` BSDF) that frame; call it after ``mi.load_file`` / ``mi.load_dict``
    (the mi-displace loader does).  Returns the number of shapes prepared."""
    count, changed = 0, False
    for shape in scene.shapes():
        prepare = getattr(shape.bsdf(), "prepare_shape", None)
        if prepare is not None:
            changed |= bool(prepare(shape))
            count += 1
    if changed:      # split vertices: the acceleration structure follows the new buffers
        scene.parameters_changed([])
    return count
