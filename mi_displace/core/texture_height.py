"""Height h(u, v) and its uv gradient from any Mitsuba texture.

Textures with an ``eval_1_grad`` (Mitsuba's ``bitmap``, our procedural ``ripples`` /
``bricks`` / ``cells``) give the gradient directly; others fall back to central
differences with a step of half a tessellation cell.
"""
from __future__ import annotations

import re
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np


def _interaction(uv: mi.Point2f) -> mi.SurfaceInteraction3f:
    si = dr.zeros(mi.SurfaceInteraction3f, dr.width(uv))
    si.uv = uv
    return si


def has_gradient(texture: mi.Texture) -> bool:
    """Whether ``texture.eval_1_grad`` is implemented (probed on one point)."""
    try:
        texture.eval_1_grad(_interaction(mi.Point2f(0.5, 0.5)))
    except Exception:  # Mitsuba raises "not implemented" for textures without it
        return False
    return True


def check_texture_finite(texture: mi.Texture, name: str = "height") -> None:
    """Raise ValueError if a bitmap-like texture stores NaN/Inf texels.

    Reads the texture's stored ``data`` (no kernel); procedural textures have none.
    """
    params = mi.traverse(texture)
    for key in params.keys():
        if key == "data" or key.endswith(".data"):
            values = np.asarray(params[key])
            if not np.all(np.isfinite(values)):
                bad = int(np.count_nonzero(~np.isfinite(values)))
                raise ValueError(
                    f"'{name}' texture {texture.id() or type(texture).__name__!r} holds "
                    f"{bad} NaN/Inf texel value(s); clean the height map first"
                )


#: Image formats Mitsuba's bitmap reads as sRGB-encoded colour unless ``raw`` is set.
SRGB_FORMATS = (".png", ".jpg", ".jpeg", ".bmp", ".tga", ".ppm")


def bitmap_decodes_srgb(texture: mi.Texture) -> bool:
    """Whether ``texture`` is a ``bitmap`` of an 8/16-bit image file read without
    ``raw="true"`` (its texels are sRGB-decoded to linear values before use).

    Platform workaround (``docs/platform.md``): Mitsuba 3.9.1's bitmap texture has no
    accessor for its ``raw`` flag or its file name; both are read from its description.
    Any other texture, a Python one without ``to_string`` included, is not a bitmap."""
    if not texture.class_name().startswith("BitmapTexture"):
        return False
    text = str(texture)
    raw = re.search(r"^\s*raw = (\d)", text, re.M)
    name = re.search(r'^\s*name = "(.*)"', text, re.M)
    return (raw is not None and raw[1] == "0" and name is not None
            and name[1].lower().endswith(SRGB_FORMATS))


def warn_if_srgb(texture: mi.Texture, plugin: str, name: str = "height") -> None:
    """Warn (naming the parameter and the fix) for a height bitmap that is gamma-decoded:
    a height map stores numbers, not colours, so its values shift (a JPEG height map by
    about a fifth of its range on average)."""
    if bitmap_decodes_srgb(texture):
        message = (f"{plugin}: parameter '{name}' is a bitmap read as sRGB colour, so its "
                   f"heights are gamma-decoded; add <boolean name=\"raw\" value=\"true\"/> "
                   f"to the bitmap ('raw': True in load_dict)")
        warnings.warn(message)
        mi.Log(mi.LogLevel.Warn, message)


def height_function(texture: mi.Texture, fd_step: float):
    """A callable uv -> (h, grad) over ``texture``.

    Args:
        texture: any Mitsuba texture; h is its ``eval_1`` (unitless).
        fd_step: uv step for central differences when the texture has no gradient.

    Returns:
        callable(uv: mi.Point2f) -> (h: mi.Float, grad: mi.Vector2f [per unit uv]).
    """
    analytic = has_gradient(texture)

    def height(uv: mi.Point2f):
        h = texture.eval_1(_interaction(uv))
        if analytic:
            return h, mi.Vector2f(texture.eval_1_grad(_interaction(uv)))
        du, dv = mi.Vector2f(fd_step, 0), mi.Vector2f(0, fd_step)
        g_u = texture.eval_1(_interaction(uv + du)) - texture.eval_1(_interaction(uv - du))
        g_v = texture.eval_1(_interaction(uv + dv)) - texture.eval_1(_interaction(uv - dv))
        return h, mi.Vector2f(g_u, g_v) / (2 * fd_step)

    return height
