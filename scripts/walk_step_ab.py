"""A/B in ONE process of the slice walks' closed-form step
(:class:`mi_displace.slicing.geometry.LayerStack`): a slicing scene's frame with every
family's step table (as the library walks) against the same frame with the tables removed
(every polygon found by a BVH query, the walk before the step).  Prints how many pixels
differ and by how much (and whether the images are finite), then ROUNDS x (median wall
seconds of REPS frames drawn alternately, BVH-only and stepped) and their ratio.

    ./.venv/bin/python scripts/walk_step_ab.py SCENE [name=value ...]

    SCENE        a file in scenes/ with a slicing shape (e.g. slicing_donut.xml); name=value:
                 its defaults, loaded by :func:`mi_displace.render.scene.load` (integrator=raster
                 res=512 mode=approximation unless given)

``raster`` frames are drawn with aa=1 at one sample a pixel, as ``mi-displace bench frames``
draws them; another integrator (e.g. integrator=path) renders with the scene's own at SPP
samples a pixel (environment, default 16), seed 0, or with the Mitsuba integrator named by
INTEGRATOR (e.g. volpath, ptracer; max_depth 3).  Environment: REPS (7), ROUNDS (3)."""
import os
import sys

import numpy as np

from ab_timing import alternate


def main(scene_file: str, *params: str) -> None:
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    defaults = {"integrator": "raster", "res": 512, "mode": "approximation"}
    defaults.update(p.split("=", 1) for p in params)
    scene, _ = load(scene_path(scene_file), **defaults)
    volumes = [s.volume for s in scene.shapes() if hasattr(getattr(s, "volume", None), "families")]
    if not volumes:
        sys.exit(f"{scene_file}: no slicing shape with slice polygons (direction screen has none)")
    stepped = [dict(v.families) for v in volumes]
    queried = [{f: (slices, bound, None) for f, (slices, bound, _) in v.families.items()} for v in volumes]
    if "INTEGRATOR" in os.environ:
        integrator = mi.load_dict({"type": os.environ["INTEGRATOR"], "max_depth": 3})
        spp = int(os.environ.get("SPP", 16))
    elif defaults["integrator"] == "raster":
        integrator, spp = mi.load_dict({"type": "raster", "aa": 1}), 1
    else:
        integrator, spp = scene.integrator(), int(os.environ.get("SPP", 16))

    def frame(which: str) -> np.ndarray:
        for volume, families in zip(volumes, stepped if which == "stepped" else queried):
            volume.families = families
        try:
            return np.asarray(mi.render(scene, integrator=integrator, spp=spp, seed=0), np.float32)
        finally:
            for volume, families in zip(volumes, stepped):
                volume.families = families

    old, new = frame("BVH-only"), frame("stepped")
    diff = np.abs(old - new).max(-1)
    finite = bool(np.isfinite(old).all() and np.isfinite(new).all())
    print(f"{scene_file} {' '.join(params)}: identical {bool(np.array_equal(old, new))}, pixels "
          f"differing {int((diff > 0).sum())} (> 1e-3: {int((diff > 1e-3).sum())}, > 1e-2: "
          f"{int((diff > 1e-2).sum())}) of {diff.size}, max |difference| {float(diff.max()):.3g}, "
          f"finite {finite}, mean {float(new.mean()):.4f}")
    alternate(frame, ("BVH-only", "stepped"))


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(*sys.argv[1:])
