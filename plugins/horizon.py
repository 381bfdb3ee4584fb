"""``<bsdf type="horizon">``: horizon mapping (Max 1988) — bump shading + self-shadows.

.. code-block:: xml

    <bsdf type="horizon">
        <texture type="cells" name="height"/>   <!-- H in [0, 1], 1 = reference surface -->
        <float name="depth" value="0.03"/>        <!-- world units -->
        <float name="tiling_u" value="24"/>  <float name="tiling_v" value="8"/>
        <integer name="res" value="128"/>         <!-- horizon map texels per tile side -->
        <integer name="azimuths" value="16"/>     <!-- horizon directions -->
        <float name="max_distance" value="0.5"/>  <!-- march length [tiles] -->
        <bsdf type="diffuse"/>
    </bsdf>

Same placement rules as ``vdm`` (inside a ``vdm_mesh``, or with ``tile_size``).
Algorithm: :mod:`mi_displace.vdm.horizon`.
"""
from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi

from mi_displace.plugins.vdm import MesostructureBSDF, _number
from mi_displace.vdm import table
from mi_displace.vdm.frame import TiledHeight, TileFrame, shading_interaction
from mi_displace.vdm.horizon import HorizonLookup, horizon_table
from mi_displace.plugins._guard import constructor


class Horizon(MesostructureBSDF):
    """Bump mapping with horizon-map self-shadows (no occlusion, no silhouettes)."""

    PLUGIN = "horizon"

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.res = _number(self.PLUGIN, props, "res", 128, 1, 2048, True)
        self.azimuths = _number(self.PLUGIN, props, "azimuths", 16, 4, 256, True)
        self.max_distance = _number(self.PLUGIN, props, "max_distance", 0.5, 1e-3, 16.0)
        self.lookup = None
        self.tiled = TiledHeight(self.height, self.tiling, 0.25 / self.res)
        if self.tile_size is not None:
            self._setup(self.tile_size, None)

    def _setup(self, tile_size, meshes):
        start = time.perf_counter()
        self.used_tile = float(tile_size)
        heights = table.sample_heights(self.height, self.res, self.tiling, self.PLUGIN)
        self._check_periodic(heights)
        self.D = self.depth / self.used_tile
        self.lookup = HorizonLookup(horizon_table(heights, self.D, self.azimuths, self.max_distance))
        self.stats.update(build_time_s=time.perf_counter() - start, table_bytes=self.lookup.nbytes,
                          tile_size=self.used_tile)

    def _ready(self) -> bool:
        return self.lookup is not None

    def _prepare(self, si, active):
        frame = TileFrame(si, self.tiling)
        T = mi.Point2f(si.uv.x * self.tiling[0], si.uv.y * self.tiling[1])
        _, grad = self.tiled(T)
        normal = frame.meso_normal(grad, self.D * self._world_tile(si, self.used_tile, active))
        return (frame, T), dr.zeros(mi.Bool, dr.width(T.x)), shading_interaction(si, si.uv, normal, frame.a)

    def _lit(self, state, wo_world, active):
        frame, T = state
        ct, theta, phi, _ = frame.direction(wo_world)
        return (ct > 0) & (dr.pi / 2 - theta > self.lookup.beta(T, phi))

    def _sizes(self) -> dict:
        return {"res": self.res, "azimuths": self.azimuths}

    def to_string(self):
        return f"Horizon[res={self.res}, azimuths={self.azimuths}, depth={self.depth}]"


def register():
    mi.register_bsdf("horizon", constructor("horizon", Horizon))
