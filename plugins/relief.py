"""``<bsdf type="relief">``: parallax occlusion / relief mapping — a per-pixel march in the
height field (occlusion and self-shadows, no table, no silhouettes).

.. code-block:: xml

    <bsdf type="relief">
        <texture type="cells" name="height"/>   <!-- H in [0, 1], 1 = reference surface -->
        <float name="depth" value="0.03"/>        <!-- world units -->
        <float name="tiling_u" value="24"/>  <float name="tiling_v" value="8"/>
        <integer name="steps" value="32"/>        <!-- linear search slices -->
        <integer name="refine" value="6"/>        <!-- bisection steps -->
        <integer name="shadow_steps" value="16"/> <!-- 0: no self-shadows -->
        <bsdf type="diffuse"/>
    </bsdf>

Same placement rules as ``vdm``.  Algorithm: :mod:`mi_displace.vdm.relief`.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mi_displace.plugins.vdm import MesostructureBSDF, _number
from mi_displace.vdm import table
from mi_displace.vdm.frame import TiledHeight, TileFrame, shading_interaction
from mi_displace.vdm.relief import march_shadow, march_view
from mi_displace.plugins._guard import constructor


class Relief(MesostructureBSDF):
    """Relief mapping on the (locally flat) reference surface."""

    PLUGIN = "relief"

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.steps = _number(self.PLUGIN, props, "steps", 32, 1, 4096, True)
        self.refine = _number(self.PLUGIN, props, "refine", 6, 0, 32, True)
        self.shadow_steps = _number(self.PLUGIN, props, "shadow_steps", 16, 0, 4096, True)
        self.tiled = TiledHeight(self.height, self.tiling, 1e-3)
        self.used_tile = None
        if self.tile_size is not None:
            self._setup(self.tile_size, None)

    def _setup(self, tile_size, meshes):
        self.used_tile = float(tile_size)
        self._check_periodic(table.sample_heights(self.height, 64, self.tiling, self.PLUGIN))
        self.stats.update(tile_size=self.used_tile, table_bytes=0)

    def _ready(self) -> bool:
        return self.used_tile is not None

    def _prepare(self, si, active):
        D = self.depth / self.used_tile
        frame = TileFrame(si, self.tiling)
        ct, _, _, step = frame.direction(si.to_world(si.wi))
        tile = self._world_tile(si, self.used_tile, active)
        T = mi.Point2f(si.uv.x * self.tiling[0], si.uv.y * self.tiling[1])
        if D > 0:
            T, h = march_view(self.tiled, T, ct, step * tile, D, self.steps, self.refine)
        else:
            h = dr.zeros(mi.Float, dr.width(T.x))
        _, grad = self.tiled(T)
        normal = frame.meso_normal(grad, D * tile)
        uv = self.tiled.uv(T)
        return (frame, T, h, D, tile), dr.zeros(mi.Bool, dr.width(T.x)), shading_interaction(si, uv, normal, frame.a)

    def _lit(self, state, wo_world, active):
        frame, T, h, D, tile = state
        ct, _, _, step = frame.direction(wo_world)
        if self.shadow_steps == 0 or D == 0:
            return ct > 0
        return (ct > 0) & ~march_shadow(self.tiled, T, h, ct, step * tile, D,
                                        self.shadow_steps)

    def _sizes(self) -> dict:
        return {"steps": self.steps, "shadow_steps": self.shadow_steps}

    def to_string(self):
        return f"Relief[steps={self.steps}, refine={self.refine}, depth={self.depth}]"


def register():
    mi.register_bsdf("relief", constructor("relief", Relief))
