"""``bricks`` texture: running-bond bricks with smoothstep bevels (the adapter of
:func:`mi_displace.core.heightfield.bricks`)."""
import mitsuba as mi

from mi_displace.core.properties import Param, PluginSpec
from mi_displace.plugins._height_texture import TO_UV, example, height_texture_base
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "bricks", "texture",
    "Procedural height in [0, 1]: bricks in running bond, `rows` × `columns` per unit uv, odd "
    "rows shifted by half a brick; 0 in the mortar, 1 on the stone tops, C1 smoothstep bevels. "
    "Exact uv gradient (`eval_1_grad`), so Mitsuba's `bumpmap` uses it too.",
    (
        Param("rows", "int", 8, "brick rows per unit v", low=1, editable=True),
        Param("columns", "int", 4, "bricks per row per unit u", low=1, editable=True),
        Param("mortar", "float", 0.1, "full joint width", unit="brick heights", low=0, high=0.5,
              open_high=True, editable=True, differentiable=True),
        Param("bevel", "float", 0.15, "bevel ramp width (mortar + 2 bevel <= 1)", unit="brick heights",
              low=0, open_low=True, editable=True, differentiable=True),
        TO_UV,
    ),
    example=example("bricks"),
    limits="Periodic over the unit square (integer counts), so it tiles across closed surfaces' seams.",
)


class Bricks(height_texture_base()):
    PATTERN = "bricks"


def register():
    mi.register_texture("bricks", constructor(SPEC, Bricks))
