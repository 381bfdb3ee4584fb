"""Plugin constructors whose bad-input errors name the plugin and the property.

Every plugin module registers ``constructor(NAME, Class)`` instead of a bare
``lambda props: Class(props)``.  The wrapper

* refuses a non-finite ``float`` property (NaN, +-Inf) before the class sees it, so no
  kernel runs on it: ``displaced: parameter 'scale' must be finite, got nan``;
* turns Python's own conversion errors, which name neither (``could not convert string to
  float: 'big'``, ``invalid literal for int() with base 10: 'many'``, ``float() argument must
  be ... not 'Texture'``), into ``ValueError("displaced: parameter 'scale' must be a number,
  got 'big'")`` by finding the property that holds the offending value.

Shapes and BSDFs report their build as a :func:`mi_displace.core.progress.stage` line
(``displaced 'rock': building: 11.02 s (8,388,608 faces, 4,196,353 vertices)``), shown on a
terminal only.  Everything else passes through unchanged (a plugin's own ``ValueError`` /
``FileNotFoundError`` already names what is wrong).  Reading properties here keeps their
"queried" state, so Mitsuba's "unreferenced property" check of typos still works.
"""
from __future__ import annotations

import linecache
import math
import re
from typing import Callable

import mitsuba as mi

from mi_displace.core.progress import stage
from mi_displace.core.properties import Param, PluginSpec

_STRING_CONVERSION = re.compile(
    r"^(?:could not convert string to float|invalid literal for int\(\) with base \d+): '(.*)'$", re.S)
_TYPE_CONVERSION = re.compile(r"^(float|int)\(\) argument must be .*, not '(\w+)'$", re.S)


def check_finite_floats(plugin: str, props: mi.Properties) -> None:
    """Raise ``ValueError`` naming the first non-finite ``float`` property of ``props``."""
    for key in props.keys():
        if props.type(key) != mi.Properties.Type.Float:
            continue
        queried = props.was_queried(key)
        value = props[key]
        props.mark_queried(key, queried)
        if not math.isfinite(value):
            raise ValueError(f"{plugin}: parameter {key!r} must be finite, got {value}")


def boolean(plugin: str, props: mi.Properties, name: str, default: bool) -> bool:
    """Property ``name`` as a bool (a ``<boolean>``, 0 / 1, or true/false, yes/no, on/off in
    any case), else a ``ValueError`` naming ``plugin`` and the property: the typed reader's
    rule (:class:`~mi_displace.core.properties.Param`) for plugins not yet declared."""
    return Param(name, "bool", default, "").convert(plugin, props.get(name, default))


def _named_in_traceback(error: Exception, keys: list[str]) -> str | None:
    """The key of ``keys`` that the failing code names, innermost frame first: as a string
    literal in the failing line, or as the value of one of the frame's local variables."""
    frames = []
    tb = error.__traceback__
    while tb is not None:
        frames.append((tb.tb_frame, tb.tb_lineno))
        tb = tb.tb_next
    for frame, line_number in reversed(frames):
        line = linecache.getline(frame.f_code.co_filename, line_number)
        for key in keys:
            if f'"{key}"' in line or f"'{key}'" in line:
                return key
        named = [key for key in keys if any(v == key for v in frame.f_locals.values()
                                            if isinstance(v, str))]
        if len(named) == 1:
            return named[0]
    return None


def _offending_property(props: mi.Properties, error: Exception) -> tuple[str, str] | None:
    """``(quoted name(s), what was expected)`` of the property behind a Python conversion
    error, or ``None`` when no property holds the offending value."""
    message = str(error)
    string_match = _STRING_CONVERSION.match(message)
    type_match = _TYPE_CONVERSION.match(message)
    found = {}
    for key in props.keys():
        value = props[key]
        if string_match and isinstance(value, str) and value.strip() == string_match.group(1).strip():
            found[key] = f"a number, got {value!r}"
        if type_match and type(value).__name__ == type_match.group(2):
            kind = "an integer" if type_match.group(1) == "int" else "a number"
            found[key] = f"{kind}, got a {type(value).__name__} object"
    if not found:
        return None
    # several properties hold such a value (a texture as 'height' and as 'scale'): ask the code
    key = next(iter(found)) if len(found) == 1 else _named_in_traceback(error, list(found))
    if key is None:
        return " or ".join(repr(k) for k in found), next(iter(found.values()))
    return repr(key), found[key]


def _summary(stats) -> str:
    """Closing-line note of a plugin build from its ``build_stats``: faces / vertices."""
    if not isinstance(stats, dict):
        return ""
    return ", ".join(f"{stats[k]:,} {k}" for k in ("faces", "vertices")
                     if isinstance(stats.get(k), int))


def constructor(plugin: str | PluginSpec, cls: type) -> Callable[[mi.Properties], object]:
    """A factory for ``mi.register_*`` that builds the plugin with clear input errors.

    Args:
        plugin: the plugin's :class:`~mi_displace.core.properties.PluginSpec` (its
            parameters are read and checked before ``cls(props, values)`` runs), or, for a
            plugin not yet declared, its XML name (``cls(props)`` reads its own properties).
        cls: the plugin class.
    """
    spec = plugin if isinstance(plugin, PluginSpec) else None
    plugin = spec.plugin if spec is not None else plugin
    # shapes and BSDFs build geometry or tables a user may wait for: report them
    reported = issubclass(cls, (mi.Shape, mi.BSDF))

    def make(props: mi.Properties):
        check_finite_floats(plugin, props)
        name = f"{plugin} {props.id()!r}" if props.id() else plugin
        args = (props,) if spec is None else (props, spec.read(props))
        try:
            with stage(f"{name}: building", enabled=None if reported else False) as s:
                made = cls(*args)
                s.note = _summary(getattr(made, "build_stats", None))
            return made
        except (ValueError, TypeError) as error:
            found = None if spec is not None else _offending_property(props, error)
            if found is None:
                raise
            names, expected = found
            raise ValueError(f"{plugin}: parameter {names} must be {expected}") from None

    return make


def take_sensors(props: mi.Properties) -> list:
    """Remove and return the sensors a plugin references (``<ref id="camera"/>``), to size
    itself for them (Mitsuba's Shape would take one as its own child sensor).

    Looks at every property without marking the others as used, so a misspelt parameter
    still gets Mitsuba's "unreferenced property" error.
    """
    keys = []
    for key in props.keys():
        queried = props.was_queried(key)
        if isinstance(props[key], mi.Sensor):
            keys.append(key)
        props.mark_queried(key, queried)
    sensors = [props.get(key) for key in keys]
    for key in keys:
        del props[key]
    return sensors
