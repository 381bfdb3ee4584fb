"""``bricks`` texture: running-bond bricks with smoothstep bevels, height 0 in the mortar and
1 on the stone tops.

Properties: ``rows``, ``columns`` (integer counts per unit uv, default 8 and 4),
``mortar`` (full joint width as a fraction of the brick height, ``[0, 0.5)``, default 0.1),
``bevel`` (ramp width, same unit, > 0, ``mortar + 2 bevel <= 1``, default 0.15), ``to_uv``.
See :func:`mi_displace.core.heightfield.bricks`.
"""
import mitsuba as mi

from mi_displace.plugins._height_texture import height_texture_base
from mi_displace.plugins._guard import constructor


class Bricks(height_texture_base()):
    PATTERN = "bricks"


def register():
    mi.register_texture("bricks", constructor("bricks", Bricks))
