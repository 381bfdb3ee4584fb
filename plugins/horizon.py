"""``<bsdf type="horizon">``: horizon mapping (Max 1988) — bump shading + self-shadows.

The adapter: :data:`SPEC` reads the parameters, :class:`mi_displace.vdm.bsdfs.Horizon` is the
BSDF, :mod:`mi_displace.vdm.horizon` its algorithm.
"""
from __future__ import annotations

import mitsuba as mi

from mi_displace.core.properties import Param, PluginSpec
from mi_displace.vdm import mesostructure
from mi_displace.vdm.bsdfs import Horizon
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "horizon", "bsdf",
    "Horizon mapping, a baseline of VDM: bump-mapped shading plus self-shadows from a table "
    "of horizon angles per texel and azimuth (no occlusion, no silhouettes).  Same placement "
    "as `vdm` (inside a `vdm_mesh`, or with `tile_size`).",
    mesostructure.PARAMS + (
        Param("res", "int", 128, "horizon map texels per tile side", low=1, high=2048),
        Param("azimuths", "int", 16, "horizon directions", low=4, high=256),
        Param("max_distance", "float", 0.5, "horizon march length", unit="tiles", low=1e-3, high=16),
    ),
    example="""<shape type="vdm_mesh">
    <string name="base" value="sphere"/>
    <integer name="resolution" value="16"/>
    <bsdf type="horizon">
        <texture type="cells" name="height"/>
        <float name="depth" value="0.03"/>
        <integer name="res" value="32"/>
    </bsdf>
</shape>""",
    nested="one `bsdf` (the material; `diffuse` when none)",
    stats="res, azimuths, build_time_s, table_bytes, tile_size",
    limits="No parallax, occlusion or silhouettes: only the shading normal and self-shadows.",
)


def register():
    mi.register_bsdf("horizon", constructor(SPEC, Horizon))
