"""A/B in ONE process: a mesostructure BSDF's preparation (``_prepare``: the relief march,
the VDM footprint) made once per interaction and shared by the queries of one sample (the
candidate, defined here: a ``MesostructureBSDF._state`` that keeps the last interaction's
preparation, as ``SlicingBSDF._prepare`` does) against the library's one preparation per
query, drawn by ``raster`` (aa=1).  Prints per row whether the two images are identical
(and finite), the launches and IR operations of one frame (``dr.kernel_history``), and the
median wall seconds of REPS frames drawn alternately (library, shared) and their ratio.

    ./.venv/bin/python scripts/once_per_sample_ab.py [RES] [ROW ...]

    RES   film side in pixels (256)
    ROW   ``relief``, ``horizon``, ``vdm`` (the ``bench frames`` rows on the torus, with
          their ``--quick`` parameters), ``relief_textured``, ``vdm_textured`` (a plane whose
          nested diffuse has a checkerboard albedo, which reads the marched uv)

Environment: REPS (9)."""
import os
import statistics
import sys
import time

import numpy as np


def textured_plane(technique: str, res: int):
    """A plane under ``technique`` (tile 0.5) with a checkerboard albedo, a point light and
    a constant ambient."""
    import mitsuba as mi
    checks = lambda n: {"type": "checkerboard", "to_uv": mi.ScalarTransform4f().scale([n, n, 1])}
    bsdf = {"type": technique, "height": checks(2), "depth": 0.05, "tile_size": 0.5,
            "nested": {"type": "diffuse", "reflectance": checks(8)}}
    if technique == "vdm":
        bsdf.update(res=16, phi=8, theta=8, curvatures=1)
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at([0, -2.2, 1.6], [0, 0, 0], [0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res}},
        "plane": {"type": "rectangle", "bsdf": bsdf},
        "light": {"type": "point", "position": [1.5, 1.0, 0.4], "intensity": 5.0},
        "ambient": {"type": "constant", "radiance": 0.1}})


def main(res: int = 256, *names: str) -> None:
    import drjit as dr
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    from mi_displace.bench.frames import ROWS
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load
    from mi_displace.vdm.mesostructure import MesostructureBSDF

    library = MesostructureBSDF._state

    def shared(self, si, active):
        """One preparation per interaction, for all valid lanes (any query's mask)."""
        if self._unused():
            return None, dr.zeros(mi.Bool, dr.width(si.t)), si
        key = (si.t.index, si.p.x.index, si.wi.x.index)
        cache = getattr(self, "_ab_cache", None)
        if cache is None or cache[0] != key:
            cache = self._ab_cache = (key, (si.t, si.p, si.wi), self._prepare(si, si.is_valid()))
        return cache[2]

    reps = int(os.environ.get("REPS", 9))
    rows = {row.name: row for row in ROWS}
    integrator = mi.load_dict({"type": "raster", "aa": 1})
    for name in names or ("relief", "horizon", "vdm", "relief_textured", "vdm_textured"):
        if name.endswith("_textured"):
            scene = textured_plane(name.split("_")[0], res)
        else:
            row = rows[name]
            scene, _ = load(scene_path(row.scene), **{**row.params, **row.quick_params}, res=res)

        def frame(which):
            MesostructureBSDF._state = library if which == "library" else shared
            start = time.perf_counter()
            image = mi.render(scene, integrator=integrator, spp=1)
            dr.eval(image)
            return np.array(image), time.perf_counter() - start

        images, ops = {}, {}
        for which in ("library", "shared"):
            frame(which)   # compile
            dr.kernel_history()   # clear
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            images[which], _ = frame(which)
            dr.set_flag(dr.JitFlag.KernelHistory, False)
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            ops[which] = f"{len(jit)}/{sum(k['operation_count'] for k in jit)}"
        times = {"library": [], "shared": []}
        for _ in range(reps):
            for which in times:
                times[which].append(frame(which)[1])
        old, new = (statistics.median(times[w]) for w in times)
        same = np.array_equal(images["library"], images["shared"])
        finite = all(np.isfinite(i).all() for i in images.values())
        print(f"{name:15s} {res}^2 identical={same} finite={finite} launches/ops library "
              f"{ops['library']} shared {ops['shared']}; frame library {1e3 * old:.1f} ms "
              f"shared {1e3 * new:.1f} ms shared/library {new / old:.3f}", flush=True)
    MesostructureBSDF._state = library


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 256, *sys.argv[2:])
