"""Smallest reproduction (docs/platform.md): a ``dr.freeze`` function given an empty
(default-constructed) Dr.Jit array among its inputs aborts the process on its first call
(``jit_var(r0): unknown variable!``); a width-1 array in its place records and replays.
Usage: ``python freeze_empty_array.py {empty,width1}``.  Worked around in one place:
``mi_displace.render.lights.area_samples`` (a scene without area lights)."""
import sys
from dataclasses import dataclass

import drjit as dr
from drjit.llvm import Float


@dataclass
class State:
    a: Float
    b: Float


print(f"drjit {dr.__version__}", flush=True)
second = Float() if sys.argv[1] == "empty" else dr.zeros(Float, 1)
frozen = dr.freeze(lambda x, state: x + state.a)
print("ok", frozen(Float(1, 2), State(Float(1), second)), flush=True)
