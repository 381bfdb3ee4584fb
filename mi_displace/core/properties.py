"""Typed, declarative plugin properties: one reader for every plugin, one source for the docs.

A plugin declares its parameters once, as a :class:`PluginSpec` of :class:`Param`; the
declaration both reads a ``mi.Properties`` (converting and range-checking each value, with a
one-line ``ValueError`` naming the plugin and the parameter) and generates the plugin's
reference table (:func:`mi_displace.core.reference.markdown`).  Only declared names are read,
so Mitsuba's own "unreferenced property" check still catches a misspelt parameter.

.. code-block:: python

    SPEC = PluginSpec("relief", "bsdf", "Relief / parallax occlusion mapping.", (
        Param("steps", "int", 32, "linear search slices", low=1, high=4096),
        Param("depth", "float", 0.05, "relief depth below the surface", unit="world", low=0),
    ))
    values = SPEC.read(props)          # {"steps": 32, "depth": 0.05}
"""
from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field

import mitsuba as mi

#: Marks a parameter without a default; reading fails when it is missing.
REQUIRED = type("Required", (), {"__repr__": lambda self: "required"})()

_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")

#: Parameter types and the Mitsuba object class a nested object must be.
TYPES = {"float": None, "int": None, "bool": None, "string": None, "rgb": None,
         "transform": None, "float|volume": None, "texture": "Texture", "bsdf": "BSDF",
         "sensor": "Sensor", "volume": "Volume", "shape": "Shape", "emitter": "Emitter"}


@dataclass(frozen=True)
class Param:
    """One plugin parameter.

    Attributes:
        name: the XML / ``load_dict`` name; a *family* of parameters when it holds the
            placeholders ``<i>`` (an index: digits) and optionally one other ``<word>`` (any
            lower-case name), e.g. ``map<i>_type``, ``map<i>_<parameter>`` (see
            :meth:`PluginSpec.read`).
        type: one of :data:`TYPES` (``float`` accepts integers; ``int`` accepts integral floats;
            ``float|volume`` a number or a nested / referenced volume).
        default: the value when absent (:data:`REQUIRED`: it must be given; ``None``: optional).
        doc: one line for the reference.
        unit: e.g. ``"world"``, ``"px"``, ``"rad"`` (empty: dimensionless).
        low, high: bounds of a number (``None``: none), inclusive unless ``open_low`` /
            ``open_high``.
        choices: the strings a ``string`` parameter accepts.
        auto: also accepts the string ``"auto"`` (sized from the scene).
        editable, differentiable: its ``mi.traverse`` flags (reference only).
    """
    name: str
    type: str
    default: object
    doc: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple[str, ...] | None = None
    auto: bool = False
    editable: bool = False
    differentiable: bool = False

    def __post_init__(self):
        if self.type not in TYPES:
            raise TypeError(f"Param {self.name!r}: unknown type {self.type!r}")

    def pattern(self) -> re.Pattern | None:
        """The regular expression of a family's names (``None``: a single parameter)."""
        if "<" not in self.name:
            return None
        parts = re.split(r"(<\w+>)", self.name)
        return re.compile("".join(r"(\d+)" if part == "<i>" else r"([a-z][a-z0-9_]*)"
                                  if part.startswith("<") else re.escape(part) for part in parts))

    def range_text(self) -> str:
        """The accepted values, as the reference prints them."""
        if self.choices:
            text = ", ".join(self.choices)
        elif self.low is not None or self.high is not None:
            lo = "(-inf" if self.low is None else f"{'(' if self.open_low else '['}{self.low:g}"
            hi = "inf)" if self.high is None else f"{self.high:g}{')' if self.open_high else ']'}"
            text = f"{lo}, {hi}"
        else:
            text = ""
        return f"{text} or auto" if self.auto and text else ("auto" if self.auto else text)

    def convert(self, plugin: str, value):
        """``value`` checked and converted to this parameter's type (ValueError naming it)."""
        where = f"{plugin}: parameter {self.name!r}"
        if self.auto and isinstance(value, str) and value.strip().lower() == "auto":
            return "auto"
        kind = self.type
        if kind == "float|volume":     # a number, or a <ref> to a volume
            kind = "volume" if isinstance(value, mi.Volume) else "float"
        if kind in ("float", "int"):
            if isinstance(value, bool) or not isinstance(value, (int, float, str)):
                raise ValueError(f"{where} must be a number, got {_shown(value)}")
            try:
                x = float(value)
            except ValueError:
                raise ValueError(f"{where} must be a number, got {value!r}") from None
            if not math.isfinite(x):
                raise ValueError(f"{where} must be finite, got {value!r}")
            if kind == "int":
                if x != int(x):
                    raise ValueError(f"{where} must be an integer, got {value!r}")
                x = int(x)
            below = self.low is not None and (x <= self.low if self.open_low else x < self.low)
            above = self.high is not None and (x >= self.high if self.open_high else x > self.high)
            if below or above:
                raise ValueError(f"{where} must lie in {self.range_text().removesuffix(' or auto')}"
                                 f"{' ' + self.unit if self.unit else ''}, got {value!r}")
            return x
        if kind == "bool":
            if isinstance(value, bool):
                return value
            if isinstance(value, (int, float)) and value in (0, 1):
                return bool(value)
            if isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
                return value.strip().lower() in _TRUE
            raise ValueError(f"{where} must be a boolean (true or false), got {value!r}")
        if kind == "string":
            if not isinstance(value, str):
                raise ValueError(f"{where} must be a string, got {_shown(value)}")
            if self.choices and value not in self.choices:
                raise ValueError(f"{where} must be one of {', '.join(self.choices)}, got {value!r}")
            return value
        if kind == "rgb":
            try:
                return tuple(float(c) for c in mi.ScalarColor3f(value))
            except (TypeError, ValueError):
                raise ValueError(f"{where} must be an RGB colour, got {_shown(value)}") from None
        if kind == "transform":
            if not hasattr(value, "matrix"):     # Scalar(Affine)Transform4f/4d/3f
                raise ValueError(f"{where} must be a <transform>, got {_shown(value)}")
            return value
        cls = getattr(mi, TYPES[kind])
        if not isinstance(value, cls):
            raise ValueError(f"{where} must be a nested {kind} ({cls.__name__}), got {_shown(value)}")
        return value


def _shown(value) -> str:
    return repr(value) if isinstance(value, (str, int, float, bool)) else f"a {type(value).__name__}"


@dataclass(frozen=True)
class PluginSpec:
    """A plugin's declaration: name, kind (``shape``, ``bsdf``, ``texture``, ``integrator``,
    ``volume``), a one-paragraph summary, its parameters, a minimal XML example the test
    suite loads, what ``build_stats`` reports and its known limits."""
    plugin: str
    kind: str
    summary: str
    params: tuple[Param, ...]
    example: str = ""
    stats: str = ""
    limits: str = ""
    nested: str = ""
    extends: tuple["PluginSpec", ...] = field(default=())

    def all_params(self) -> tuple[Param, ...]:
        """Own parameters after those of the specs it extends (their order kept)."""
        inherited = tuple(p for spec in self.extends for p in spec.all_params())
        return inherited + self.params

    def read(self, props: mi.Properties) -> dict:
        """Every declared parameter's value from ``props`` (defaults filled in).

        A family (:class:`Param` ``name`` with placeholders) reads every property whose name
        fits it and that no single parameter or earlier family claims, as a dict keyed by
        the index (``<i>`` alone) or by ``(index, word)``: ``{0: "peel"}``,
        ``{(0, "angle"): 60.0}``; its errors name the property (``'map0_angle'``).

        Raises:
            ValueError: one line, ``"<plugin>: parameter '<name>' must be ..."``, for the
                first missing required, mistyped or out-of-range parameter.
        """
        out = {}
        claimed = {p.name for p in self.all_params() if p.pattern() is None}
        for p in self.all_params():
            pattern = p.pattern()
            if pattern is not None:
                out[p.name] = {}
                for key in props.keys():
                    found = None if key in claimed else pattern.fullmatch(key)
                    if found:
                        claimed.add(key)
                        index = tuple(int(g) if g.isdigit() else g for g in found.groups())
                        value = dataclasses.replace(p, name=key).convert(self.plugin, props.get(key))
                        out[p.name][index[0] if len(index) == 1 else index] = value
            elif p.name in props:
                out[p.name] = p.convert(self.plugin, props.get(p.name))
            elif p.default is REQUIRED:
                raise ValueError(f"{self.plugin}: parameter {p.name!r} is required ({p.doc})")
            else:
                out[p.name] = p.default
        return out
