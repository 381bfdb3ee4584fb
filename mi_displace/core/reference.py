"""The plugin reference (``docs/plugins.md``) generated from the plugins' declarations.

One source of truth: each plugin module holds a
:class:`~mi_displace.core.properties.PluginSpec` named ``SPEC`` (``SPECS``: a tuple, for a module
registering several plugins); this module renders them in
the form of Mitsuba's own plugin reference (Parameter / Type / Default / Range / Unit /
Description, plus the ``traverse`` flags).  ``python -m mi_displace.core.reference`` rewrites
the file; the test suite fails when it and the declarations disagree.
"""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

from mi_displace.core.properties import REQUIRED, PluginSpec


def declared_specs() -> list[PluginSpec]:
    """The declarations of every plugin module, in registration order: its ``SPECS`` (a
    module registering several plugins) or its ``SPEC``."""
    from mi_displace.plugins import PLUGIN_MODULES

    specs = []
    for name in PLUGIN_MODULES:
        module = importlib.import_module(name)
        spec = getattr(module, "SPEC", None)
        specs.extend(getattr(module, "SPECS", () if spec is None else (spec,)))
    return specs


def _default(value) -> str:
    if value is REQUIRED:
        return "*required*"
    if value is None:
        return "—"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    return f"`{value}`"


def _flags(param) -> str:
    return ", ".join(f for f, on in (("editable", param.editable),
                                    ("differentiable", param.differentiable)) if on) or ""


def plugin_markdown(spec: PluginSpec) -> str:
    """One plugin's section: summary, XML example, parameter table, stats, limits."""
    lines = [f"## `{spec.plugin}` ({spec.kind})", "", spec.summary, ""]
    if spec.example:
        lines += ["```xml", spec.example, "```", ""]
    lines += ["| Parameter | Type | Default | Range | Unit | `traverse` | Description |",
              "|---|---|---|---|---|---|---|"]
    for p in spec.all_params():
        lines.append(f"| `{p.name}` | {p.type} | {_default(p.default)} | {p.range_text()} | "
                     f"{p.unit} | {_flags(p)} | {p.doc} |")
    lines.append("")
    for title, text in (("Nested", spec.nested), ("`build_stats`", spec.stats),
                        ("Limits", spec.limits)):
        if text:
            lines += [f"**{title}:** {text}", ""]
    return "\n".join(lines)


def markdown(specs: list[PluginSpec]) -> str:
    """The whole reference page."""
    head = ["# Plugin reference", "",
            "Generated from the plugins' declarations by `python -m mi_displace.core.reference`; "
            "do not edit by hand.  Every parameter is checked when the plugin is built: a wrong "
            "type or a value out of range is a one-line error naming the plugin and the parameter.  "
            "A name with placeholders is a family: `map<i>_type` stands for `map0_type`, "
            "`map1_type`, …, and `map<i>_<parameter>` for any parameter name in that place.",
            "", "Plugins: " + ", ".join(f"`{s.plugin}`" for s in specs) + ".", ""]
    return "\n".join(head + [plugin_markdown(s) for s in specs])


def reference_path() -> Path:
    """``docs/plugins.md`` of the source checkout."""
    return Path(__file__).resolve().parents[2] / "docs" / "plugins.md"


def main() -> int:
    import mi_displace

    mi_displace.init()
    reference_path().write_text(markdown(declared_specs()))
    print(f"wrote {reference_path()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
