"""A/B in ONE process of a module constant: the raster frame with ``MODULE.NAME`` = A against
the same frame with it = B (e.g. a lever whose old behaviour is one value of a constant).
Prints whether the images are identical (and finite), then ROUNDS x (median wall seconds of
REPS frames drawn alternately, A and B) and their ratio B/A: both see the same moments of a
shared machine.

    ./.venv/bin/python scripts/constant_ab.py MODULE.NAME A B SCENE [name=value ...]

    MODULE.NAME  a constant under mi_displace (e.g. slicing.sliced.SHADOW_REACH)
    A, B         Python literals (e.g. None 1.5)
    SCENE        a file in scenes/ (e.g. slicing_donut.xml); name=value: its defaults, loaded
                 by :func:`mi_displace.render.scene.load` as ``mi-displace bench frames`` does
                 (integrator=raster res=512 mode=approximation unless given)

Frames are drawn by ``raster`` with aa=1 at one sample per pixel, as ``mi-displace bench
frames`` draws them.  Environment: REPS (7), ROUNDS (3), ORBIT (unset: the loaded view; a
number n: each round's frames cycle through n camera positions of the bench's orbit,
:func:`mi_displace.bench.frames._orbit` over +-ORBIT_DEG, the images of both compared at
every one)."""
import ast
import importlib
import os
import sys

import numpy as np

from ab_timing import alternate


def main(constant: str, a: str, b: str, scene_file: str, *params: str) -> None:
    import drjit as dr
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    path, name = constant.rsplit(".", 1)
    module = importlib.import_module("mi_displace." + path)
    if not hasattr(module, name):
        sys.exit(f"mi_displace.{path} has no {name}")
    values = {"A": ast.literal_eval(a), "B": ast.literal_eval(b)}
    kept = getattr(module, name)
    defaults = {"integrator": "raster", "res": 512, "mode": "approximation"}
    defaults.update(p.split("=", 1) for p in params)
    scene, _ = load(scene_path(scene_file), **defaults)
    integrator = mi.load_dict({"type": "raster", "aa": 1})
    views = [None]
    if "ORBIT" in os.environ:
        from mi_displace.bench.frames import ORBIT_DEG, _orbit
        from mi_displace.core.dicing import fit_to_sensors
        count = int(os.environ["ORBIT"])
        views = _orbit(scene, np.linspace(-ORBIT_DEG, ORBIT_DEG, count))
        sensor = mi.traverse(scene.sensors()[0])

    def look(view) -> None:
        if view is not None:
            sensor["to_world"] = view
            sensor.update()
            fit_to_sensors(scene)

    def frame(which: str) -> np.ndarray:
        setattr(module, name, values[which])
        try:
            return np.asarray(mi.render(scene, integrator=integrator, spp=1), np.float32)
        finally:
            setattr(module, name, kept)

    same, worst, finite = True, 0.0, True
    for view in views:
        look(view)
        img_a, img_b = frame("A"), frame("B")
        same &= bool(np.array_equal(img_a, img_b))
        worst = max(worst, float(np.abs(img_a - img_b).max()))
        finite &= bool(np.isfinite(img_a).all() and np.isfinite(img_b).all())
    print(f"{scene_file} {' '.join(params)}: {constant} {a} -> {b}, {len(views)} view(s): identical "
          f"{same}, max |difference| {worst:.3g}, finite {finite}, mean {float(img_b.mean()):.4f}")
    alternate(frame, ("A", "B"), lambda rep: look(views[rep % len(views)]))

if __name__ == "__main__":
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    main(*sys.argv[1:])
