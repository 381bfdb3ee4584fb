"""Optional dependencies: imported on first use, or a one-line error with the install line.

The runtime needs only the core dependencies; the Dask cluster (``[cluster]``) and the peer
renderers of the benches (``[peers]``) are extras of ``pyproject.toml``.  Code that needs one
calls :func:`require` where it first uses it (the pattern of trimesh's ray back-ends).
"""
from __future__ import annotations

import importlib
from types import ModuleType


class MissingExtraError(ImportError):
    """An optional dependency is not installed; the message names the ``pip install`` line."""


def require(module: str, extra: str, feature: str | None = None) -> ModuleType:
    """Import ``module``, or raise :class:`MissingExtraError` naming the extra that brings it.

    Args:
        module: the module to import, e.g. ``"distributed"``.
        extra: the ``pyproject.toml`` extra that installs it, e.g. ``"cluster"``.
        feature: what needs it, for the message, e.g. ``"--cluster"`` (``None``: the
            message names the module only).

    Returns:
        The imported module.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name != module.partition(".")[0] and e.name != module:
            raise  # the module is there but one of its own imports is broken
        what = (f"{feature} needs {module!r}, which is not installed" if feature
                else f"{module} is not installed")
        raise MissingExtraError(f"{what}: pip install 'mi-displace[{extra}]'") from None
