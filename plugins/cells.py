"""``cells`` texture: round C1 bumps on a hashed, jittered grid (the adapter of
:func:`mi_displace.core.heightfield.cells`)."""
import mitsuba as mi

from mi_displace.core.heightfield import MAX_CELLS
from mi_displace.core.properties import Param, PluginSpec
from mi_displace.plugins._height_texture import TO_UV, example, height_texture_base
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "cells", "texture",
    "Procedural height in [0, 1]: round C1 bumps (1 - r²/radius²)² on a `cells` × `cells` grid "
    "per unit uv, each jittered by a hash of its cell and `seed`.  Exact uv gradient.",
    (
        Param("cells", "int", 8, "cells per unit u and v", low=1, high=MAX_CELLS, editable=True),
        Param("radius", "float", 0.5, "bump radius", unit="cells", low=0, high=1, open_low=True,
              editable=True, differentiable=True),
        Param("jitter", "float", 1.0, "bump centre jitter", unit="cells", low=0, high=1,
              editable=True, differentiable=True),
        Param("seed", "int", 0, "jitter hash seed", low=0, high=2**31 - 1, editable=True),
        TO_UV,
    ),
    example=example("cells"),
    limits="Periodic over the unit square, so it tiles across closed surfaces' seams.",
)


class Cells(height_texture_base()):
    PATTERN = "cells"


def register():
    mi.register_texture("cells", constructor(SPEC, Cells))
