"""Smallest reproduction (docs/platform.md): what one replay of a ``dr.freeze`` function
costs beyond its kernel, as its inputs grow.  The function is trivial (``x * 2``, one
element); its inputs also carry state it never reads.

* ``leaves N``: a dict of N leaves, Dr.Jit arrays or Python values (int, str, NumPy) —
  what a Python plugin's ``__dict__`` holds, which a frozen function traverses.
* ``registry N``: one Mitsuba scene of one rectangle as the input, while N other such
  scenes are alive in the process but not passed: a scene's shape pointers make the call
  traverse every registered shape (and its BSDF) in the process.

Prints the median wall microseconds of a replay (the recording excluded) and the cost per
leaf / per scene alive.  Usage: ``python freeze_call_overhead.py {leaves,registry} [N]``."""
import statistics
import sys
import time

import drjit as dr
import numpy as np
from drjit.llvm import Float

REPS = 300


def per_call(state) -> float:
    """Median wall seconds of a replay of a frozen ``x * 2`` given ``state`` besides x."""
    frozen = dr.freeze(lambda x, state: x * 2)
    for _ in range(3):   # recorded, then replayed
        dr.eval(frozen(Float(1.0), state))
    times = []
    for _ in range(REPS):
        start = time.perf_counter()
        dr.eval(frozen(Float(1.0), state))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def leaves(n: int) -> None:
    empty = per_call({})
    print(f"no leaves: {1e6 * empty:.1f} us a call")
    for name, make in (("drjit Float", lambda i: dr.full(Float, i, 16)), ("int", lambda i: i),
                       ("str", lambda i: f"value {i}"), ("numpy", lambda i: np.zeros(4))):
        t = per_call({f"leaf{i}": make(i) for i in range(n)})
        print(f"{n} {name} leaves: {1e6 * t:8.1f} us a call, {1e6 * (t - empty) / n:.2f} us a leaf")


def registry(n: int) -> None:
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    make = lambda: mi.load_dict({"type": "scene", "r": {"type": "rectangle"}})
    scene = make()
    alone = per_call(scene)
    others = [make() for _ in range(n)]   # kept alive (registered), never passed
    crowded = per_call(scene)
    print(f"one scene as input, nothing else alive: {1e6 * alone:.1f} us a call; with {len(others)} "
          f"other scenes alive: {1e6 * crowded:.1f} us a call, {1e6 * (crowded - alone) / n:.2f} us per scene alive")


if __name__ == "__main__":
    print(f"drjit {dr.__version__}")
    {"leaves": leaves, "registry": registry}[sys.argv[1]](int(sys.argv[2]) if len(sys.argv) > 2 else 200)
