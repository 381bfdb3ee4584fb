"""Shared base of the procedural height textures (``ripples``, ``bricks``, ``cells``).

Nanobind allows a single bound base class and no mixins, and ``mi.Texture`` differs per
variant, so :func:`height_texture_base` builds the base class for the *current* variant
(cached per variant); each plugin module subclasses it at import time and is re-imported by
:func:`mi_displace.plugins.register_all` after a variant change.

A subclass sets ``PATTERN`` (a key of :data:`mi_displace.core.heightfield.PATTERNS`) and is
built from the values its plugin's spec read (:data:`TO_UV` plus the pattern's parameters,
declared in the plugin module); it may override :meth:`flat_values` and
:meth:`pattern_params` to map other properties onto the pattern's.
Every property is a number, exposed by ``traverse`` as an ``mi.Float`` and re-validated
in ``parameters_changed``: ``Differentiable`` for the continuous ones (an AD gradient
enabled on one enters the pattern's kernels as that array, so it reaches the height, its
gradient and, through ``displaced``, the image), ``NonDifferentiable`` for the integer
counts and seeds (:data:`mi_displace.core.heightfield.INTEGER_PARAMETERS`; ``displaced``
refuses a gradient on them, naming them).  Without a gradient the kernels get the plain
Python floats, exactly as before. ``to_uv`` (optional, as in
``bitmap``) is exposed as a ``mi.ScalarTransform3f``.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import heightfield as hf
from mi_displace.core.collector import collector_paused
from mi_displace.core.properties import Param

def example(plugin: str) -> str:
    """The reference's example of a height texture: bump mapping a rectangle with it."""
    return f"""<shape type="rectangle">
    <bsdf type="bumpmap">
        <texture type="{plugin}" name="arbitrary"/>
        <bsdf type="diffuse"/>
    </bsdf>
</shape>"""


#: The parameter every height texture has besides its pattern's.
TO_UV = Param("to_uv", "transform", None, "uv placement (as `bitmap`'s): the upper-left 2×2 "
              "and the translation of a 4×4 or 3×3 transform")

_BASES: dict[str, type] = {}


def height_texture_base() -> type:
    """The ``mi.Texture`` subclass shared by the height textures, for the current variant."""
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("set a Mitsuba variant before importing mi_displace.plugins modules")
    if variant not in _BASES:
        _BASES[variant] = _make_base()
    return _BASES[variant]


def _transform3(value, plugin: str) -> mi.ScalarTransform3f:
    """A ``to_uv`` property (4x4 from XML/dict, or 3x3) as the 2D ``mi.ScalarTransform3f``."""
    affine = hf.uv_affine(value, plugin)
    if affine is None:
        return mi.ScalarTransform3f()
    (a00, a01, a10, a11), (t0, t1) = affine
    return mi.ScalarTransform3f(np.array([[a00, a01, t0], [a10, a11, t1], [0.0, 0.0, 1.0]]))


def _make_base() -> type:
    class HeightTexture(mi.Texture):
        """Procedural height in ``[0, 1]`` (gray), with the exact ``uv`` gradient."""

        PATTERN = ""

        def __init__(self, props: mi.Properties, values: dict):
            super().__init__(props)
            # Python floats (exact, for the kernels) and their mi.Float mirrors (for traverse)
            self._flat = {name: hf.check_real(self.PATTERN, name, value)
                          for name, value in self.flat_values(values).items()}
            self._values = {name: mi.Float(value) for name, value in self._flat.items()}
            to_uv = values["to_uv"]
            self._to_uv = _transform3(mi.ScalarTransform4f() if to_uv is None else to_uv, self.PATTERN)
            self.parameters_changed([])

        # -- parameters ------------------------------------------------------------------
        def flat_values(self, values: dict) -> dict:
            """The flat (traversed) parameter values from the spec's ``values``."""
            return {name: values[name] for name in hf.pattern_defaults(self.PATTERN)}

        def pattern_params(self, flat: dict[str, float]) -> dict:
            """Keyword arguments of the core pattern from the flat property values."""
            return flat

        def parameters_changed(self, keys=None):
            flat = dict(self._flat)
            flat.update({k: float(dr.detach(self._values[k])[0]) for k in keys or ()
                         if k in self._values})
            _, check, mean = hf.PATTERNS[self.PATTERN]
            self._params = check(**self.pattern_params(flat))   # ValueError names the key
            self._flat = flat
            self._affine = hf.uv_affine(self._to_uv, self.PATTERN)
            self._mean = mean(**self._params)
            # the traversed arrays with a gradient enabled replace their floats in the kernels
            live = {k: self._values[k] if self.is_continuous(k) and dr.grad_enabled(
                self._values[k]) else v for k, v in flat.items()}
            self._live = self.pattern_params(live)

        def is_continuous(self, name: str) -> bool:
            """Whether the flat property ``name`` is continuous (hence differentiable)."""
            return name not in hf.INTEGER_PARAMETERS[self.PATTERN]

        def traverse(self, cb):
            for name, value in self._values.items():
                cb.put(name, value, mi.ParamFlags.Differentiable if self.is_continuous(name)
                       else mi.ParamFlags.NonDifferentiable)
            cb.put("to_uv", self._to_uv, mi.ParamFlags.NonDifferentiable)

        # -- evaluation ------------------------------------------------------------------
        @collector_paused
        def height(self, si: mi.SurfaceInteraction3f) -> tuple[mi.Float, mi.Vector2f]:
            """``(h, dh/d(si.uv))``: the pattern at ``to_uv(si.uv)`` with the chain rule."""
            return hf.evaluate(self.PATTERN, si.uv, self._affine, **self._live)

        def eval_1(self, si, active=True):
            return self.height(si)[0]

        def eval_1_grad(self, si, active=True):
            return self.height(si)[1]

        def eval(self, si, active=True):
            return mi.UnpolarizedSpectrum(self.height(si)[0])

        def eval_3(self, si, active=True):
            return mi.Color3f(self.height(si)[0])

        def mean(self):
            """Mean over the unit square of the untransformed pattern (as ``bitmap``)."""
            return mi.Float(self._mean)

        def max(self):
            """Upper bound of the height (heights lie in ``[0, 1]``)."""
            return mi.Float(1.0)

        def is_spatially_varying(self):
            return True

        def to_string(self):
            params = ", ".join(f"{k}={v}" for k, v in self._params.items())
            return f"{type(self).__name__}[{params}, to_uv={self._affine}, mean={self._mean:.6g}]"

    return HeightTexture
