"""The maps of the high-poly's surface beyond its shape: ambient occlusion, mean curvature
(and the cavity map made from it) and albedo, each evaluated per bake sample at the point
where the sample's projection ray hit the high-poly, then averaged per texel with the other
channels (:func:`mi_displace.bake.baker._texel_average`).

=============  ========  =========  ==================================================
map            channels  no hit     evaluated by
=============  ========  =========  ==================================================
``ao``         1         1 (open)   :func:`occlusion.ambient_occlusion`
``curvature``  1         0 (flat)   :func:`curvature.mean_curvature` per vertex, interpolated
``albedo``     3         0 (black)  :class:`albedo.HighPolyColour`
=============  ========  =========  ==================================================

Texels without a hit keep these values until the edge padding fills them from their nearest
measured texel, like the displacement.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake import occlusion
from mi_displace.bake.albedo import HighPolyColour
from mi_displace.bake.curvature import mean_curvature

#: map -> (channel count, value of a texel without a hit)
CHANNELS = {"ao": (1, 1.0), "curvature": (1, 0.0), "albedo": (3, 0.0)}


@dataclass
class SurfaceSettings:
    """What to evaluate.  ``ao_distance`` [object units], ``ao_samples`` directions per bake
    sample, ``ao_seed`` the random streams' seed; ``colour`` set for albedo."""

    ao: bool = False
    ao_samples: int = 64
    ao_distance: float = 1.0
    ao_seed: int = 0
    curvature: bool = False
    colour: HighPolyColour | None = None

    def names(self) -> list[str]:
        """The maps these settings produce, in channel order."""
        return [name for name, on in (("ao", self.ao), ("curvature", self.curvature),
                                      ("albedo", self.colour is not None)) if on]


class SurfaceMaps:
    """Device state of the surface maps for one high-poly (curvature per welded vertex)."""

    def __init__(self, high_dev, settings: SurfaceSettings):
        self.high, self.settings = high_dev, settings
        self.vertex_curvature = None
        if settings.curvature:
            positions, faces = high_dev.welded
            self.vertex_curvature = mi.Float(mean_curvature(positions, faces.astype(np.int64)))

    def evaluate(self, r, key: mi.UInt64, offset) -> list:
        """Per-sample values (a list of mi.Float, the channels of :meth:`SurfaceSettings.names`)
        for the trace result ``r``; ``key``: per-sample random stream id."""
        s, high, found = self.settings, self.high, r.found
        out = []
        if s.ao:
            x = high.point(r.prim_high, r.bary_high, found)
            ng = gather_face_normal(high, r.prim_high, found)
            ng = dr.select(dr.dot(ng, r.normal_object) < 0, -ng, ng)
            ao = occlusion.ambient_occlusion(high.scene, x, ng, r.normal_object, key,
                                             s.ao_samples, dr.opaque(mi.Float, s.ao_distance),
                                             offset, s.ao_seed)
            out.append(dr.select(found, ao, 1.0))
        if s.curvature:
            f = [dr.gather(mi.UInt32, high.faces[k], r.prim_high, found) for k in range(3)]
            b = r.bary_high
            h = (dr.gather(mi.Float, self.vertex_curvature, f[0], found) * (1.0 - b.x - b.y)
                 + dr.gather(mi.Float, self.vertex_curvature, f[1], found) * b.x
                 + dr.gather(mi.Float, self.vertex_curvature, f[2], found) * b.y)
            out.append(h)
        if s.colour is not None:
            out += list(s.colour.evaluate(r.prim_high, r.bary_high, found))
        return out


def gather_face_normal(high, prim: mi.UInt32, active: mi.Bool) -> mi.Vector3f:
    """The (unnormalised) geometric normal of high-poly triangle ``prim``."""
    return mi.Vector3f(*(dr.gather(mi.Float, c, prim, active) for c in high.face_normals))


def fallbacks(settings: SurfaceSettings) -> list[float]:
    """Per channel, the value a texel without a hit holds."""
    return [CHANNELS[name][1] for name in settings.names() for _ in range(CHANNELS[name][0])]
