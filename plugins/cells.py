"""``cells`` texture: round C1 bumps ``(1 - r^2/radius^2)^2`` on a hashed, jittered grid.

Properties: ``cells`` (integer count per unit uv, default 8), ``radius`` (cell units,
``(0, 1]``, default 0.5), ``jitter`` (``[0, 1]``, default 1), ``seed`` (integer >= 0,
default 0), ``to_uv``. See :func:`mi_displace.core.heightfield.cells`.
"""
import mitsuba as mi

from mi_displace.plugins._height_texture import height_texture_base
from mi_displace.plugins._guard import constructor


class Cells(height_texture_base()):
    PATTERN = "cells"


def register():
    mi.register_texture("cells", constructor("cells", Cells))
