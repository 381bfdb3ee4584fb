"""Height h(u, v) and its uv gradient from any Mitsuba texture.

Textures with an ``eval_1_grad`` (Mitsuba's ``bitmap``, our procedural ``ripples`` /
``bricks`` / ``cells``) give the gradient directly; others fall back to central
differences with a step of half a tessellation cell.
"""
from __future__ import annotations

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
