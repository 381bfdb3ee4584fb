"""``ripples`` texture: egg-crate sine height ``1/2 + 1/2 sin(2 pi f_u u + phase) sin(2 pi f_v v)``.

Properties: ``frequency`` (periods per unit uv, default 8), ``frequency_u`` /
``frequency_v`` (per-axis overrides), ``phase`` (radians, default 0), ``to_uv`` (optional
transform). See :func:`mi_displace.core.heightfield.ripples`.
"""
import drjit as dr
import mitsuba as mi

from mi_displace.core.heightfield import check_real, pattern_defaults
from mi_displace.plugins._height_texture import height_texture_base
from mi_displace.plugins._guard import constructor


class Ripples(height_texture_base()):
    PATTERN = "ripples"

    def read_properties(self, props):
        defaults = pattern_defaults("ripples")
        # checked under its own name: it is only the default of the two per-axis values
        frequency = check_real("ripples", "frequency", props.get("frequency", defaults["frequency"]))
        return {"frequency_u": props.get("frequency_u", frequency),
                "frequency_v": props.get("frequency_v", frequency),
                "phase": props.get("phase", defaults["phase"])}

    def pattern_params(self, flat):
        fu, fv = flat["frequency_u"], flat["frequency_v"]   # floats, or mi.Float with a gradient
        same = not (dr.is_array_v(fu) or dr.is_array_v(fv)) and fu == fv
        return {"frequency": fu if same else (fu, fv), "phase": flat["phase"]}


def register():
    mi.register_texture("ripples", constructor("ripples", Ripples))
