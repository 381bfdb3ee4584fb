"""The benchmarks' peers: other renderers and bakers measured beside ours (the lab, not the
library: nothing in ``mi_displace`` outside ``mi_displace.bench`` imports them).

* :mod:`.llvmpipe` — Mesa's llvmpipe (OpenGL on the CPU, headless EGL) through ``moderngl``:
  a mesh draw (``bench raster``) and the slicing paper's algorithm (``bench slicing``);
* :mod:`.vtk_volume` — VTK's CPU volume ray caster (``bench volume``);
* :mod:`.blender` — Cycles' bakes in a Python that has ``bpy`` (``bench bake_blender``).

Their Python packages are the ``peers`` extra (``pip install 'mi-displace[peers]'``, except
``bpy``, which needs its own Python 3.11); the system libraries (Mesa's EGL) are installed
by ``scripts/setup_peers.sh``.  Nothing here installs anything: a missing piece raises
:class:`PeerUnavailable` (an ``ImportError``) on first use, with the line that installs it,
and a benchmark records ``"peer unavailable: <why>"`` in its place (:func:`measure`).
"""
from __future__ import annotations

from types import ModuleType

from mi_displace.core.extras import MissingExtraError
from mi_displace.core.extras import require as require_extra

INSTALL = "pip install 'mi-displace[peers]'"
SYSTEM = "scripts/setup_peers.sh (Debian: apt-get install libegl1 libgl1-mesa-dri libegl-mesa0)"


class PeerUnavailable(ImportError):
    """A peer cannot run here; the message says why and what installs it."""


def require(module_name: str, extra: str = "peers") -> ModuleType:
    """Import ``module_name``, or raise :class:`PeerUnavailable` naming the install line of
    the extra ``extra`` that provides it (:func:`mi_displace.core.extras.require`)."""
    try:
        return require_extra(module_name, extra)
    except MissingExtraError as error:
        raise PeerUnavailable(str(error)) from error


def measure(fn, *args, **kwargs) -> tuple[object, str | None]:
    """``(fn(*args, **kwargs), None)``, or ``(None, "peer unavailable: <why>")`` when the
    peer cannot run here; any other error is a bug and propagates."""
    try:
        return fn(*args, **kwargs), None
    except PeerUnavailable as error:
        return None, f"peer unavailable: {error}"
