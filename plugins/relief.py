"""``<bsdf type="relief">``: relief / parallax occlusion mapping — a per-pixel march in the
height field (occlusion and self-shadows, no table, no silhouettes).

The adapter: :data:`SPEC` reads the parameters, :class:`mi_displace.vdm.bsdfs.Relief` is the
BSDF, :mod:`mi_displace.vdm.relief` its algorithm.
"""
from __future__ import annotations

import mitsuba as mi

from mi_displace.core.properties import Param, PluginSpec
from mi_displace.vdm import mesostructure
from mi_displace.vdm.bsdfs import Relief
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "relief", "bsdf",
    "Relief / parallax occlusion mapping, a baseline of VDM: per pixel, a linear search then "
    "a bisection along the view ray through the height field on the locally flat reference "
    "surface, and a march towards the light for self-shadows; no table, no silhouettes.  Same "
    "placement as `vdm`.",
    mesostructure.PARAMS + (
        Param("steps", "int", 32, "linear search slices of the view march", low=1, high=4096),
        Param("refine", "int", 6, "bisection steps after the linear search", low=0, high=32),
        Param("shadow_steps", "int", 16, "steps of the march towards the light (0: no self-shadows)",
              low=0, high=4096),
    ),
    example="""<shape type="vdm_mesh">
    <string name="base" value="sphere"/>
    <integer name="resolution" value="16"/>
    <bsdf type="relief">
        <texture type="cells" name="height"/>
        <float name="depth" value="0.03"/>
        <integer name="steps" value="16"/>
    </bsdf>
</shape>""",
    nested="one `bsdf` (the material; `diffuse` when none)",
    stats="steps, shadow_steps, tile_size",
    limits="The surface is taken as flat under each pixel: relief bends wrongly on curved "
           "bases and never shows a silhouette.",
)


def register():
    mi.register_bsdf("relief", constructor(SPEC, Relief))
