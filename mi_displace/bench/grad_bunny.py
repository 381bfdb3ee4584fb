"""`mi-displace bench grad_bunny`: seconds per iteration of the bunny recovery (issue 14).

The setting of :func:`mi_displace.inverse.bunny.recover_bunny` (4 views x 2 lights, 96^2,
8 spp, ``prb_projective``, 64^2 map on the 19,424-triangle ``displaced`` low-poly), 3 Adam
steps at a time, alternating twice between the plugin as it is and the plugin redoing its
per-load work (thin-shell rays, topology, vertex frames) on every edit
(:func:`mi_displace.bench.grad.redo_per_load_work`, what every edit did before), same
process; plus :func:`mi_displace.bench.grad.mesh_redisplacement` (one edit alone).
Prints medians and ratios; writes nothing.  ``--quick``: :data:`QUICK` sizes (one view x 2
lights at 32^2, a 16^2 map, one step at a time, one timed edit).
"""
from __future__ import annotations

import json as _json
import warnings
from typing import NamedTuple

import mitsuba as mi
import numpy as np

from mi_displace.bench import grad
from mi_displace.inverse import bunny, recover


class Sizes(NamedTuple):
    """What a run renders: ``views`` views x 2 lights at ``image``² pixels, ``spp``
    (targets at ``target_spp``), a ``map_size``² map, ``steps`` Adam steps per timed run,
    ``edits`` timed edits of :func:`mi_displace.bench.grad.mesh_redisplacement`."""
    views: int
    image: int
    spp: int
    target_spp: int
    map_size: int
    steps: int
    edits: int


FULL = Sizes(4, 96, 8, 64, 64, 3, 5)
QUICK = Sizes(1, 32, 2, 8, 16, 1, 1)


def run(sizes: Sizes = FULL) -> dict:
    baked, _, scale = bunny.baked_map(sizes.map_size)
    views, spp, target_spp, steps = sizes.views, sizes.spp, sizes.target_spp, sizes.steps
    common = (bunny.origins(views), bunny.CENTRE, bunny.UP, 30, sizes.image)
    targets, scenes = [], []
    for light in recover.LIGHTS:
        lit = [light[0], light[2], light[1]]   # as recover_bunny: the z-up directions, y-up
        scan = mi.load_dict(recover.lit_scene({"type": "obj", "filename": str(bunny.SCAN)},
                                              "prb_projective", lit, *common, target_spp))
        targets += [mi.render(scan, sensor=i, spp=target_spp, seed=1000 + i)
                    for i in range(views)]
        scenes.append(mi.load_dict(recover.lit_scene(
            bunny._model(np.full_like(baked, 0.5), scale), "prb_projective", lit, *common, spp)))
    shapes = [sc.shapes()[0] for sc in scenes]
    cls = type(shapes[0])
    kept = cls.parameters_changed

    def again(self, keys=[]):
        grad.redo_per_load_work(self)
        kept(self, keys)

    seconds = {"kept": [], "per_load_again": []}
    try:
        for mode in ("kept", "per_load_again") * 2:
            cls.parameters_changed = kept if mode == "kept" else again
            run_ = recover.optimise(scenes, targets, recover.KEY, np.full_like(baked, 0.5),
                                    steps, views, spp, 0.002, 0, lambda h: 0.0)
            seconds[mode] += run_["seconds"]
    finally:
        cls.parameters_changed = kept
    kept_s, again_s = (float(np.median(seconds[k])) for k in ("kept", "per_load_again"))
    return {"faces": shapes[0].face_count(), "seconds_per_iteration": kept_s,
            "seconds_per_iteration_per_load_work_again": again_s,
            "iteration_ratio": again_s / kept_s, "edit": grad.mesh_redisplacement(sizes.edits)}


def main(json: bool = False, quick: bool = False) -> int:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and print its record."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the bunny's ears: 2 vertices cross the base
        result = run(QUICK if quick else FULL)
    print(_json.dumps(result, indent=2) if json else "\n".join(
        f"{k}: {v}" for k, v in result.items()))
    return 0
