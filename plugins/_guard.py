"""Plugin constructors whose bad-input errors name the plugin and the property.

Every plugin module declares its parameters (a
:class:`~mi_displace.core.properties.PluginSpec`) and registers ``constructor(SPEC, Class)``
instead of a bare ``lambda props: Class(props)``.  The wrapper

* refuses a non-finite ``float`` property (NaN, +-Inf) before the class sees it, so no
  kernel runs on it: ``displaced: parameter 'scale' must be finite, got nan``;
* reads and checks the declared parameters (``SPEC.read``: a one-line ``ValueError`` naming
  the plugin and the parameter) and builds ``Class(props, values)``.

Shapes and BSDFs report their build as a :func:`mi_displace.core.progress.stage` line
(``displaced 'rock': building: 11.02 s (8,388,608 faces, 4,196,353 vertices)``), shown on a
terminal only.  Reading properties here keeps their "queried" state, so Mitsuba's
"unreferenced property" check of typos still works.
"""
from __future__ import annotations

import math
from typing import Callable

import mitsuba as mi

from mi_displace.core.progress import stage
from mi_displace.core.properties import PluginSpec


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


def _summary(stats) -> str:
    """Closing-line note of a plugin build from its ``build_stats``: faces / vertices."""
    if not isinstance(stats, dict):
        return ""
    return ", ".join(f"{stats[k]:,} {k}" for k in ("faces", "vertices")
                     if isinstance(stats.get(k), int))


def constructor(spec: PluginSpec, cls: type) -> Callable[[mi.Properties], object]:
    """A factory for ``mi.register_*`` that builds the plugin with clear input errors.

    Args:
        spec: the plugin's declaration; its parameters are read and checked before
            ``cls(props, values)`` runs.
        cls: the plugin class.
    """
    # shapes and BSDFs build geometry or tables a user may wait for: report them
    reported = issubclass(cls, (mi.Shape, mi.BSDF))

    def make(props: mi.Properties):
        check_finite_floats(spec.plugin, props)
        name = f"{spec.plugin} {props.id()!r}" if props.id() else spec.plugin
        values = spec.read(props)
        with stage(f"{name}: building", enabled=None if reported else False) as s:
            made = cls(props, values)
            s.note = _summary(getattr(made, "build_stats", None))
        return made

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
