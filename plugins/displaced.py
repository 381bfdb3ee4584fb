"""``<shape type="displaced">``: a base surface displaced along its normal by a height texture.

(:data:`SPEC` declares its parameters.)

Mesh bases: ``base="mesh"`` with ``filename`` (PLY/OBJ with UVs) and ``subdivision`` (edge
splits per triangle) or ``edge_length``.  Meshes without UVs are refused (unwrap them
first, e.g. with ``mi_displace.bake.unwrap.unwrap`` (xatlas)).  Every copy of a position (UV seams, hard edges) moves by one vector:
along the angle-weighted normal of the welded surface, by the mean of the copies' heights,
so closed meshes stay closed; ``split_normals="true"`` instead moves each copy along its own
vertex normal (cracks open where they differ; warns at load).
``scale``, ``midlevel`` and the height texture's parameters are editable through
``mi.traverse`` (re-displacement keeps the topology) and differentiable (issue 14: the
vertices and shading normals are recomputed with the AD graph attached; integer texture
parameters and the dicing rates refuse a gradient, naming it).

Screen-adaptive dicing (:mod:`mi_displace.core.dicing`, Cycles' meaning): ``dicing_rate``
(pixels per micro-edge, instead of ``resolution`` / ``subdivision`` / ``edge_length``;
``tessellation`` = ``uniform`` / ``dicing`` chooses when a scene gives both) and
``offscreen_dicing_scale`` (default 4, coarser outside the view frustum and behind the
camera).  The sensors are those referenced in the shape (``<ref id="camera"/>``, any number:
the finest need wins); without one the shape dices coarsely and warns until
:func:`mi_displace.fit_to_sensors` gives it the scene's sensors (the mi-displace loaders
do).  ``dicing_rate`` and ``offscreen_dicing_scale`` are editable through ``mi.traverse``;
every edit (and ``fit_to_sensors`` after a camera edit) recomputes the edge rates and rebuilds
only what changed: the topology is kept when no edge rate moved.

``build_stats`` (a dict attribute, printed by ``mi-displace render --explain``): mode, rate,
patches, edge segments, vertices, faces, bytes, seconds per stage, what was rebuilt, and
``warnings`` (displacement deeper than the base's thickness, pending dicing).
"""
from __future__ import annotations

import mitsuba as mi

from mi_displace.core import surfaces
from mi_displace.core.displaced import DisplacedSurface
from mi_displace.core.mesh_buffers import upload
from mi_displace.core.properties import Param, PluginSpec
from mi_displace.plugins._guard import constructor, take_sensors

SPEC = PluginSpec(
    "displaced", "shape",
    "True displacement: a base surface (parametric, or a mesh with UVs) tessellated and "
    "displaced along its normal, P = S + scale (h - midlevel) n, by a height texture.  Every "
    "copy of a mesh position (UV seams, hard edges) moves by one vector, so closed meshes stay "
    "closed.  Tessellation is uniform (`resolution` / `edge_length` / `subdivision`) or "
    "screen-adaptive (`dicing_rate`, Cycles' meaning) for the sensors referenced in the shape "
    "(`<ref id=\"camera\"/>`), else the scene's once `mi_displace.fit_to_sensors` runs.  Edits "
    "through `mi.traverse` re-displace the mesh (keeping its topology when no edge rate moved); "
    "the height texture's own parameters are editable and differentiable too.",
    (
        surfaces.base_param("sphere"), *surfaces.BASE_DIMENSIONS,
        surfaces.resolution_param(None, "uniform: grid cells along u (default 64; v keeps the "
                                  "base's aspect ratio)"),
        surfaces.EDGE_LENGTH, surfaces.BASE_FILENAME,
        Param("subdivision", "int", 1, "uniform, mesh base: edge splits per triangle", low=1),
        Param("split_normals", "bool", False, "mesh base: move each copy of a position along "
              "its own normal (cracks open where they differ; warns)"),
        Param("height", "texture", None, "the height h (none: the undisplaced base)",
              unit="texture", editable=True, differentiable=True),
        Param("scale", "float", 0.1, "displacement per unit height", unit="object",
              editable=True, differentiable=True),
        Param("midlevel", "float", 0.0, "height with zero displacement", unit="texture",
              editable=True, differentiable=True),
        Param("tessellation", "string", None, "uniform or dicing (default: dicing when "
              "`dicing_rate` is given)", choices=("uniform", "dicing")),
        Param("dicing_rate", "float", None, "dicing: pixels per micro-edge", unit="px",
              low=0, open_low=True, editable=True),
        Param("offscreen_dicing_scale", "float", 4.0, "dicing: rate multiplier outside the view "
              "frustum and behind the camera", low=1, editable=True),
    ),
    example="""<shape type="displaced">
    <string name="base" value="sphere"/>
    <texture type="ripples" name="height"/>
    <float name="scale" value="0.1"/>
    <integer name="resolution" value="32"/>
    <bsdf type="diffuse"/>
</shape>""",
    nested="the `height` texture, one `bsdf`; sensors (`<ref id=\"camera\"/>`) for dicing",
    stats="mode, tessellate_s, vertices, faces, bytes, crossing_vertices, warnings; dicing: "
          "dicing_rate, offscreen_dicing_scale, sensors, bound, patches, patch_grid, "
          "edge_segments_min/max, rebuilt, rates_s, topology_s, displace_s",
    limits="Displacement deeper than the base's thickness crosses the other side (warns); "
           "meshes need UVs; integer texture parameters and the dicing rates take no gradient "
           "(refused by name).",
)


class Displaced(mi.Mesh):
    """True displacement: a tessellated mesh P = S + scale (h - midlevel) n, built by
    :class:`~mi_displace.core.displaced.DisplacedSurface` (``self.surface``)."""

    def __init__(self, props: mi.Properties, values: dict):
        given = {p.name for p in SPEC.all_params() if p.name in props}
        self.surface = DisplacedSurface(values, given, take_sensors(props),
                                        props.get("to_world", mi.ScalarTransform4f()), props.id())
        built = self.surface.build_mesh()
        super().__init__(props.id() or "displaced", built.vertex_count, built.face_count, props,
                         True, True)
        upload(self, built)

    def fit_to_sensors(self, sensors) -> bool:
        """Dice for ``sensors`` (the scene's) unless the shape references its own; True if
        anything was rebuilt.  Called by :func:`mi_displace.core.dicing.fit_to_sensors`."""
        return upload(self, self.surface.fit_to_sensors(sensors))

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

    def to_string(self):
        s, base = self.build_stats, self.surface.base
        return (f"Displaced[base={base.name if base else 'mesh'}, "
                f"vertices={s.get('vertices')}, faces={s.get('faces')}]")


def register():
    mi.register_shape("displaced", constructor(SPEC, Displaced))
