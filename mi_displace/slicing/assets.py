"""Test objects of the depth-object scenes: a procedural cup (concave, a visual hull cannot
hollow it) and mesh sources for :func:`mi_displace.slicing.depth_object.capture`."""
from __future__ import annotations

import os

import numpy as np


def cup_mesh(radius: float = 0.5, height: float = 0.8, wall: float = 0.06, segments: int = 96):
    """A closed, watertight cup (trimesh.Trimesh): a lathe of the profile outer wall ->
    rim -> inner wall -> inner floor, about the z axis, bottom at z = 0."""
    import trimesh

    profile = np.array([[0.0, 0.0], [radius, 0.0], [radius, height], [radius - wall, height],
                        [radius - wall, wall], [0.0, wall]])
    # refine the walls so that the lathe's quads stay small
    pts = [profile[0]]
    for a, b in zip(profile[:-1], profile[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / (radius / 12))))
        pts += [a + (b - a) * (k / n) for k in range(1, n + 1)]
    pts = np.array(pts)
    ring = len(pts)
    phi = 2 * np.pi * np.arange(segments) / segments
    verts = np.stack([np.outer(np.cos(phi), pts[:, 0]).ravel(), np.outer(np.sin(phi), pts[:, 0]).ravel(),
                      np.tile(pts[:, 1], segments)], 1)
    faces = []
    for s in range(segments):
        t = (s + 1) % segments
        for k in range(ring - 1):
            a, b, c, d = s * ring + k, s * ring + k + 1, t * ring + k + 1, t * ring + k
            faces += [[a, d, c], [a, c, b]]
    mesh = trimesh.Trimesh(verts, np.array(faces), process=True)  # merges the axis points
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(mesh)
    return mesh


def source_shape(source: str, color) -> dict:
    """A ``load_dict`` shape dict of a mesh file (or ``"cup"``) with a diffuse albedo."""
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(color)}}
    if source == "cup":
        import tempfile

        path = os.path.join(tempfile.mkdtemp(prefix="mi_displace_cup_"), "cup.ply")
        cup_mesh().export(path)
        source = path
    if not os.path.isfile(source):
        raise FileNotFoundError(f"slicing-capture: source mesh {source!r} does not exist")
    ext = os.path.splitext(source)[1].lower()
    if ext not in (".ply", ".obj"):
        raise ValueError(f"slicing-capture: source {source!r} must be .ply or .obj")
    return {"type": ext[1:], "filename": source, "bsdf": bsdf}
