"""``<bsdf type="mikk_normalmap">``: the adapter of
:class:`mi_displace.bake.normalmap_bsdf.MikkNormalMap` (:data:`SPEC` declares its parameters)."""
from __future__ import annotations

import mitsuba as mi

from mi_displace.bake.normalmap_bsdf import MikkNormalMap
from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "mikk_normalmap", "bsdf",
    "Mitsuba's `normalmap`, decoding the tangent-space map in the MikkTSpace frame that "
    "bakers (ours, Blender, Unity, Unreal) write it in, with per-vertex tangents and bitangent "
    "signs from our MikkTSpace port on the shape itself.  Mitsuba's stock `normalmap` decodes in "
    "its own per-triangle dp/du frame, where a MikkTSpace map shows seams (or bake with the "
    "`normal_mitsuba` format for the stock BSDF).  The mi-displace loaders prepare the shapes; "
    "after `mi.load_file` call `mi_displace.bake.mitsuba_frames.prepare_scene(scene)`.",
    (Param("normalmap", "texture", REQUIRED, "the tangent-space map, (n + 1) / 2 — a `bitmap` "
           "with raw=\"true\""),
     Param("green", "string", "+y", "the map's green-channel convention: `+y` OpenGL (Blender, "
           "Mitsuba, Unity), `-y` DirectX (Unreal; G = 1 - G)", choices=("+y", "-y"))),
    example="""<shape type="obj">
    <string name="filename" value="parts/bake_bunny/low.obj"/>
    <bsdf type="mikk_normalmap">
        <texture type="bitmap" name="normalmap">
            <string name="filename" value="parts/flat_normal.png"/>
            <boolean name="raw" value="true"/>
        </texture>
        <bsdf type="diffuse"/>
    </bsdf>
</shape>""",
    nested="exactly one `bsdf` (the material under the perturbed normal)",
    limits="Unprepared shapes (no `prepare_scene`) render without the map after one warning; "
           "a PLY low-poly's v is not flipped by Mitsuba's reader: use the bake's `low.obj`.",
)


def register():
    mi.register_bsdf("mikk_normalmap", constructor(SPEC, MikkNormalMap))
