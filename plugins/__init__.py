"""Mitsuba plugin adapters (installed as ``mi_displace.plugins``).

Each module declares its plugin's parameters (``SPEC``: a
:class:`~mi_displace.core.properties.PluginSpec`; ``SPECS`` where it registers several) and has a
``register()`` function; :func:`register_all`
(re)imports them after a variant change, after the library modules of
:data:`VARIANT_MODULES`, whose classes derive from the variant's Mitsuba types.
"""
import importlib
import sys

import mitsuba as mi

PLUGIN_MODULES = [
    "mi_displace.plugins.ripples",
    "mi_displace.plugins.bricks",
    "mi_displace.plugins.cells",
    "mi_displace.plugins.displaced",
    "mi_displace.plugins.raster",
    "mi_displace.plugins.ddm",
    "mi_displace.plugins.vdm",
    "mi_displace.plugins.vdm_mesh",
    "mi_displace.plugins.horizon",
    "mi_displace.plugins.relief",
    "mi_displace.plugins.restored",
    "mi_displace.plugins.mikk_normalmap",
    "mi_displace.plugins.slicing",
    "mi_displace.plugins.depth_object",
    "mi_displace.plugins.displaced_volume",
    "mi_displace.plugins.volume_slicer",
    "mi_displace.plugins.volume_isosurface",
    "mi_displace.plugins.volume_proxy",
]

#: Library modules defining subclasses of variant-specific Mitsuba classes (``mi.BSDF``),
#: reloaded (in this order) before the plugins when the variant changes.
VARIANT_MODULES = [
    "mi_displace.vdm.mesostructure",
    "mi_displace.vdm.bsdfs",
    "mi_displace.slicing.bsdf",
    "mi_displace.bake.normalmap_bsdf",
]

_registered_for: str | None = None


def registered_variant() -> str | None:
    """The variant the plugins were last registered for (``None``: not yet)."""
    return _registered_for


def register_all() -> None:
    """Import (or re-import for a new variant) every plugin module and register it."""
    global _registered_for
    variant = mi.variant()
    if _registered_for not in (None, variant):
        for name in VARIANT_MODULES:
            if name in sys.modules:
                importlib.reload(sys.modules[name])
    for name in PLUGIN_MODULES:
        module = sys.modules.get(name)
        if module is None:
            module = importlib.import_module(name)
        elif _registered_for != variant:
            module = importlib.reload(module)
        module.register()
    _registered_for = variant
