"""``<bsdf type="vdm">``: view-dependent displacement mapping (Wang et al. 2003).

The adapter: :data:`SPEC` declares and reads the parameters, :class:`mi_displace.vdm.bsdfs.VDM`
is the BSDF (the table policy, §3) and :mod:`mi_displace.vdm` its algorithm.
"""
from __future__ import annotations

import mitsuba as mi

from mi_displace.core.properties import Param, PluginSpec
from mi_displace.vdm import EXAMPLE_XML, build, mesostructure
from mi_displace.vdm.bsdfs import VDM
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "vdm", "bsdf",
    "View-dependent displacement mapping (§3): a 5-D table of the distance along each view "
    "ray to the height field, by texel, view direction and curvature, built by ray casting the "
    "height texture, SVD-compressed (§3.1) and looked up per pixel; silhouettes pass rays "
    "through (Null component), self-shadows are checked towards the light.  The table is built "
    "when a `vdm_mesh` attaches (curvature range and tile size measured there) or at once with "
    "`tile_size` (flat, c = 0).",
    mesostructure.PARAMS + (
        Param("res", "int", 128, "table texels per tile side (paper: 128)", low=1, high=1024, auto=True),
        Param("theta", "int", 8, "view elevation samples (paper: 8)", low=2, high=64, auto=True),
        Param("phi", "int", 32, "view azimuth samples (paper: 32)", low=4, high=256),
        Param("curvatures", "int", 16, "curvature samples (paper: 16)", low=1, high=64),
        Param("theta_oversample", "int", 1, "elevation rays cast per stored sample", low=1, high=8),
        Param("svd_terms", "int", 8, "VDM eigen-functions kept (paper: 8)", low=1, high=build.K_STORED),
        Param("mvm_terms", "int", 4, "MVM eigen-functions kept (paper: 4)", low=1, high=build.K_STORED),
        Param("shadows", "bool", True, "self-shadows from the table (§3.2)"),
        Param("shadow_bias", "float", 0.0, "shadow test bias", unit="tile depth", low=0),
        Param("shadow_slack", "float", 0.0, "shadow test slack", unit="tile depth", low=0),
        Param("shadow_verify", "int", 3, "height-field steps verifying a shadow (0: the paper)", low=0, high=64),
        Param("refine_steps", "int", 8, "steps refining T' to the ray's first hit (0: the paper)", low=0, high=256),
        Param("refine_window", "float", 0.5, "refinement window", unit="tiles", low=0, high=10),
        Param("cache", "bool", True, "keep built tables on disk (keyed by the code and the inputs)"),
        Param("curvature_percentile", "float", 0.0, "percentile of the mesh curvatures clipped off "
              "each end of the sampled range", unit="%", low=0, high=49),
        Param("curvature_min", "float", None, "fixed lower end of the curvature range (with curvature_max)",
              unit="1/world"),
        Param("curvature_max", "float", None, "fixed upper end of the curvature range", unit="1/world"),
        Param("sensor", "sensor", None, "the sensor `res`/`theta` = auto size the table for"),
    ),
    example=EXAMPLE_XML,
    nested="one `bsdf` (the material; `diffuse` when none)",
    stats="res, theta, phi, curvatures, svd_terms, mvm_terms, auto, table_bytes, compressed_bytes, "
          "build_time_s, load_time_s, cached, tile_size, depth_tile, c_range_tile, n_curvatures",
    limits="The reference surface is locally a quadric (§3.3): curvature outside the sampled "
           "range is clamped; one tile size per BSDF (a UV scale that varies by > 25 % warns).",
)


def register():
    mi.register_bsdf("vdm", constructor(SPEC, VDM))
