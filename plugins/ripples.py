"""``ripples`` texture: egg-crate sine height (the adapter of
:func:`mi_displace.core.heightfield.ripples`)."""
import drjit as dr
import mitsuba as mi

from mi_displace.core.properties import Param, PluginSpec
from mi_displace.plugins._height_texture import TO_UV, example, height_texture_base
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "ripples", "texture",
    "Procedural height in [0, 1]: 1/2 + 1/2 sin(2π f_u u + phase) sin(2π f_v v).  Exact uv "
    "gradient.",
    (
        Param("frequency", "float", 8.0, "periods per unit uv (default of both axes)", low=0,
              open_low=True),
        Param("frequency_u", "float", None, "periods per unit u (default: frequency)", low=0,
              open_low=True, editable=True, differentiable=True),
        Param("frequency_v", "float", None, "periods per unit v (default: frequency)", low=0,
              open_low=True, editable=True, differentiable=True),
        Param("phase", "float", 0.0, "phase along u", unit="rad", editable=True, differentiable=True),
        TO_UV,
    ),
    example=example("ripples"),
    limits="Periodic over the unit square for integer frequencies.",
)


class Ripples(height_texture_base()):
    PATTERN = "ripples"

    def flat_values(self, values):
        frequency = values["frequency"]
        return {"frequency_u": frequency if values["frequency_u"] is None else values["frequency_u"],
                "frequency_v": frequency if values["frequency_v"] is None else values["frequency_v"],
                "phase": values["phase"]}

    def pattern_params(self, flat):
        fu, fv = flat["frequency_u"], flat["frequency_v"]   # floats, or mi.Float with a gradient
        same = not (dr.is_array_v(fu) or dr.is_array_v(fv)) and fu == fv
        return {"frequency": fu if same else (fu, fv), "phase": flat["phase"]}


def register():
    mi.register_texture("ripples", constructor(SPEC, Ripples))
