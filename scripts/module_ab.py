"""A/B of library modules in ONE process: the modules as they are in the work tree against
the same modules as of a git commit, swapped in by name (their functions and constants, the
methods of their classes, and what they import from one another),
on one scene's raster frame.  Prints whether the two images are identical (and finite),
then ROUNDS x (median wall seconds of REPS frames drawn alternately, old and new) and their
ratio: both versions see the same moments of a shared machine.

    ./.venv/bin/python scripts/module_ab.py BASE MODULES SCENE [name=value ...]

    BASE     a commit (e.g. c154be8)
    MODULES  comma-separated paths under mi_displace/ without .py
             (e.g. render/zbuffer,slicing/rasterised,render/raster)
    SCENE    a file in scenes/ (e.g. slicing_plane_grazing.xml); name=value: its defaults
             (mode=approximation integrator=raster are set unless given)

Environment: REPS (7), ROUNDS (3), AA (unset: the scene's integrator renders both frames;
a number: ``raster`` with that ``aa`` at one sample a pixel, as ``mi-displace bench frames``
draws with AA=1).  The modules' other users in the process see the swap too (a module's
functions look up its globals, so the old functions call the old helpers)."""
import importlib
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np

from ab_timing import alternate

ROOT = Path(__file__).resolve().parents[1]


def old_module(name: str, path: str, base: str) -> types.ModuleType:
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{base}:mi_displace/{path}.py"],
                            capture_output=True, text=True, check=True).stdout
    module = types.ModuleType(name + "_old")
    sys.modules[module.__name__] = module   # dataclasses look their module up
    module.__file__ = str(ROOT / "mi_displace" / f"{path}.py")
    exec(compile(source, module.__name__, "exec"), module.__dict__)
    return module


def main(base: str, modules: str, scene: str, *params: str) -> None:
    import drjit as dr
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    swaps = []
    for path in modules.split(","):
        name = "mi_displace." + path.replace("/", ".")
        new = importlib.import_module(name)
        own = {k: v for k, v in vars(new).items()
               if (callable(v) and getattr(v, "__module__", None) == name) or isinstance(v, (int, float))}
        swaps.append((new, own, old_module(name, path, base)))
    old_of = {new.__name__: old for new, _, old in swaps}
    for _, _, old in swaps:   # the old modules call each other's old functions
        for k, v in list(vars(old).items()):
            source = old_of.get(getattr(v, "__module__", None))
            if callable(v) and source is not None and source is not old and k in vars(source):
                setattr(old, k, vars(source)[k])

    def members(cls) -> dict:
        return {k: v for k, v in vars(cls).items()
                if isinstance(v, (types.FunctionType, staticmethod, classmethod, property))}

    # methods of the modules' classes, swapped on the class itself: the scene's objects
    # were made from the new class and keep it
    methods = [(cls, members(cls), members(vars(old)[k]))
               for new, own, old in swaps for k, cls in own.items()
               if isinstance(cls, type) and isinstance(vars(old).get(k), type)]
    imported = [(new, k, v, vars(old_of[v.__module__]).get(k, v)) for new, _, _ in swaps
                for k, v in vars(new).items()
                if callable(v) and getattr(v, "__module__", None) in old_of and v.__module__ != new.__name__]

    def use(which: str) -> None:
        for new, own, old in swaps:
            for k, v in own.items():
                setattr(new, k, v if which == "new" else vars(old).get(k, v))
        for cls, now, before in methods:
            for k in now.keys() | before.keys():
                value = (now if which == "new" else before).get(k)
                if value is not None:
                    setattr(cls, k, value)
                elif k in vars(cls):   # a method only one version has
                    delattr(cls, k)
        for module, k, now, before in imported:
            setattr(module, k, now if which == "new" else before)

    defaults = {"mode": "approximation", "integrator": "raster"}
    defaults.update(p.split("=", 1) for p in params)
    loaded = mi.load_file(str(ROOT / "scenes" / scene), **defaults)
    integrator = mi.load_dict({"type": "raster", "aa": int(os.environ["AA"])}) if "AA" in os.environ else None

    def frame(which: str) -> np.ndarray:
        use(which)
        return np.asarray(mi.render(loaded, integrator=integrator, spp=1 if integrator else 0), np.float32)

    a, b = frame("old"), frame("new")
    print(f"identical: {np.array_equal(a, b)}, max |difference| {float(np.abs(a - b).max()):.3g}, "
          f"finite: {bool(np.isfinite(b).all())}, mean {float(b.mean()):.4f}")
    alternate(frame, ("old", "new"))
    use("new")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
