"""Python's cyclic collector paused around plugin methods that Dr.Jit traces.

The one workaround of this package for a Mitsuba / Dr.Jit behaviour: a vectorised call
traces every live instance of its domain through plain pointers, and a collection started
inside that trace can free a dropped scene's instance before its turn (a segfault).  What
happens, the smallest script that shows it and the versions: ``docs/platform.md``.
"""
from __future__ import annotations

import functools
import gc


def collector_paused(method):
    """``method`` run with Python's cyclic garbage collector paused.

    Dr.Jit traces a vectorised call over *every* live instance of its domain (all BSDFs,
    all textures), holding plain pointers to them.  A Python plugin method called in that
    trace allocates, which may start the collector, which may free an instance of a dropped
    scene still waiting in a reference cycle before its turn to be traced: a segfault (seen
    with tests/vdm/test_vdm_plugin.py then tests/vdm/test_vdm_scene_sequence.py run without
    a collection between tests).  The plugin methods such a trace calls, and the raster
    integrator's whole frame (its vectorised calls are launched from Python), run with it
    paused.  Allocations in Dr.Jit's own code between two instances remain uncovered.
    """
    @functools.wraps(method)
    def paused(*args, **kwargs):
        if not gc.isenabled():
            return method(*args, **kwargs)
        gc.disable()
        try:
            return method(*args, **kwargs)
        finally:
            gc.enable()

    return paused
