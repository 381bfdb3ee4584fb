"""What a mesh-building shape plugin uploads into its ``mi.Mesh``: :class:`MeshBuffers`.

The libraries behind ``displaced`` (:mod:`mi_displace.core.displaced`) and ``restored``
(:mod:`mi_displace.bake.restored_mesh`) return one per build; the plugin
hands it to :func:`upload`.
"""
from __future__ import annotations

from dataclasses import dataclass

import mitsuba as mi


@dataclass
class MeshBuffers:
    """A finished build in world space.

    Attributes:
        positions, normals: flat (3 V,) ``mi.Float`` [world units; unit normals].
        texcoords: flat (2 V,) ``mi.Float``; faces: flat (3 F,) ``mi.UInt32``; ``None``: keep
            the mesh's (a re-displacement on the same topology).
        vertex_count, face_count: V, F.
        stats: the shape's ``build_stats`` (``None``: keep the mesh's).
    """
    positions: object
    normals: object
    texcoords: object
    faces: object
    vertex_count: int
    face_count: int
    stats: dict | None



def upload(mesh: mi.Mesh, buffers: MeshBuffers | None) -> bool:
    """Write ``buffers`` into ``mesh`` (through ``mi.traverse``, so Mitsuba updates its bounding
    box and acceleration data) and set ``mesh.build_stats``; False when ``buffers`` is
    ``None`` (nothing was rebuilt)."""
    if buffers is None:
        return False
    params = mi.traverse(mesh)
    for key, value in (("vertex_positions", buffers.positions), ("vertex_normals", buffers.normals),
                       ("vertex_texcoords", buffers.texcoords), ("faces", buffers.faces)):
        if value is not None:
            params[key] = value
    params.update()
    if buffers.stats is not None:
        mesh.build_stats = buffers.stats
    return True
