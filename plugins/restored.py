"""``<shape type="restored">``: a low-poly restored with a baked displacement map (paper 003 §5).

(:data:`SPEC` declares its parameters.)

The mesh is built by :class:`mi_displace.bake.restored_mesh.RestoredSurface` (through
:func:`mi_displace.bake.restore.restore`: Dr.Jit subdivision and displacement, alias-welded
seams, recomputed normals) and uploaded into this ``mi.Mesh``.
``levels="auto"`` derives the levels from the map resolution and the projected size through
the sensors (:mod:`mi_displace.bake.levels`): the referenced ones, else the scene's, given by
``fit_to_sensors(sensors)`` (:func:`mi_displace.fit_to_sensors` calls it; so do the mi-displace loaders);
until then from the map alone.  ``build_stats`` (a dict) holds levels, why, faces,
vertices, bytes and seconds.

``displacement`` (the map's texels, a (H, W, 1) tensor [object units]) is exposed through
``mi.traverse`` as differentiable: an edit re-displaces the mesh (never stale), and with a
gradient enabled the vertex positions and normals carry it (refine a bake against images).
"""
from __future__ import annotations

import mitsuba as mi

from mi_displace.bake.restore import MAX_SPLIT
from mi_displace.bake.restored_mesh import RestoredSurface
from mi_displace.core.mesh_buffers import upload
from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.plugins._guard import constructor, take_sensors

SPEC = PluginSpec(
    "restored", "shape",
    "A low-poly restored with a baked displacement map (paper 003 §5): subdivided (1 -> 4 "
    "rounds, or a uniform 1 -> N² split), displaced along the interpolated normal by the "
    "map, seams welded across UV-chart aliases and normals recomputed.  `levels=\"auto\"` "
    "derives the rounds from the map resolution and the projected size through the sensors "
    "(those referenced with `<ref id=\"...\"/>`, else the scene's, given by "
    "`mi_displace.fit_to_sensors`).  `traverse` exposes `displacement` (the map's texels, a "
    "(H, W, 1) tensor in object units; editable, differentiable: an edit re-displaces the mesh).",
    (
        Param("map", "string", REQUIRED, "a baked map with its .json sidecar"),
        Param("low", "string", None, "the low-poly (default: the one the map's sidecar names)"),
        Param("levels", "int", 2, "subdivision rounds (1 -> 4 triangles each)", low=0, high=6, auto=True),
        Param("split", "int", None, "instead of `levels`: a uniform 1 -> N² split", low=1, high=MAX_SPLIT),
        Param("dicing_rate", "float", 1.0, "`levels=auto`: pixels per micro-edge", unit="px",
              low=0, open_low=True),
        Param("keep_holes", "bool", True, "open low-polys: drop the faces over void texels"),
    ),
    example="""<shape type="restored">
    <string name="map" value="parts/bake_bunny/d16.png"/>
    <integer name="levels" value="1"/>
    <bsdf type="diffuse"/>
</shape>""",
    nested="one `bsdf`; sensors (`<ref id=\"camera\"/>`) for `levels=auto`",
    stats="levels, split, rule (and the inputs of an auto rule), vertices, faces, bytes, "
          "restore_s, build_s and the restore report",
    limits="The map's sidecar must describe the low-poly (same UVs); `levels=auto` before "
           "`fit_to_sensors` sizes from the map alone.",
)


class Restored(mi.Mesh):
    """Low-poly + map -> subdivided, displaced triangle mesh, built by
    :class:`~mi_displace.bake.restored_mesh.RestoredSurface` (``self.surface``)."""

    def __init__(self, props: mi.Properties, values: dict):
        self.surface = RestoredSurface(values, take_sensors(props),
                                       props.get("to_world", mi.ScalarTransform4f()))
        built = self.surface.build_mesh()
        super().__init__(props.id() or "restored", built.vertex_count, built.face_count, props,
                         True, True)
        upload(self, built)

    def traverse(self, cb):
        super().traverse(cb)
        for name, value, differentiable in self.surface.parameters():
            cb.put(name, value, mi.ParamFlags.Differentiable if differentiable
                   else mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=[]):
        if self.surface.owns(keys):
            upload(self, self.surface.edit(keys))
        else:
            super().parameters_changed(keys)

    def fit_to_sensors(self, sensors) -> bool:
        """``levels="auto"``: re-derive the levels for ``sensors`` (the scene's, unless the
        shape references its own) and rebuild if they changed; True if rebuilt."""
        return upload(self, self.surface.fit_to_sensors(sensors))

    def to_string(self):
        return (f"Restored[levels={self.surface.levels}, vertices={self.build_stats['vertices']}, "
                f"faces={self.build_stats['faces']}]")


def register():
    mi.register_shape("restored", constructor(SPEC, Restored))
