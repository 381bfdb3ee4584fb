"""`mi-displace bench vdm`: VDM table build, compression, render speed and accuracy.

All on ``scenes/vdm_torus.xml`` (torus R = 1, r = 0.4, cells height field, depth 0.06):

* ``build_time_s``: the full 128^2 x 32 x 8 x 16 table built from scratch (ray casting +
  curvature resampling + MVM + SVD), warm (second build in this process; the first is
  ``build_time_cold_s``), beside ``reference_build_s`` (tessellating the displaced torus
  and Mitsuba's acceleration build over it) measured in the same process;
* ``table_mb`` / ``compressed_mb`` / ``compression_ratio`` (float32, 8 + 4 terms),
  ``reconstruction_rmse`` (VDM, tile units) and ``reconstruction_rmse_mvm`` (rad) against
  the full table, ``silhouette_mismatch`` (fraction of samples whose silhouette test flips);
* ``render_time_warm_s``: raster, 512 x 512, one sample per pixel, warm median, beside
  ``reference_render_time_s`` (the same integrator on the true displacement) and
  ``base_render_time_s`` (the coarse torus with the plain material);
* ``flip_vs_reference`` and the measured Table 1 (``methods``): every method against the
  true displacement (raster, 256 x 256, 4 x 4 samples) in the shadow / occlusion /
  silhouette masks (:mod:`mi_displace.vdm.methods`).

``--quick`` runs the same with :data:`QUICK` sizes (a 16^2 x 8 x 4 x 4 table, renders at
64^2, the Table 1 masks at 32^2, the true displacement at resolution 256).
"""
from __future__ import annotations

import gc
import json as _json
import os
import tempfile
import time
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from mi_displace.bench._timing import median_time
from mi_displace.core.resources import scene_path

SCENE = scene_path("vdm_torus.xml")
TARGETS = {"build_time_s": 10.0, "render_time_warm_s": 0.3, "compression_ratio": 10.0}


class Sizes(NamedTuple):
    """What a run renders: speed frames at ``res``² pixels (``repeats`` warm renders each),
    the Table 1 masks at ``methods_res``², and the scene's own parameters ``params`` (table
    sizes, the true displacement's resolution; :data:`mi_displace.vdm.methods.MODE_PARAMS`)."""
    res: int
    methods_res: int
    repeats: int
    params: dict


FULL = Sizes(512, 256, 5, {})
QUICK = Sizes(64, 32, 2, {"resolution": 256, "vdm_res": 16, "vdm_phi": 8, "vdm_theta": 4,
                          "vdm_curvatures": 4})


def _median_render(scene, repeats: int) -> float:
    """Warm median seconds of a raster render (one sample per pixel) of ``scene``."""
    from mi_displace.render import raster

    sensor = scene.sensors()[0]
    return median_time(lambda: dr.eval(raster.render(scene, sensor, aa=1)), repeats)


def run(sizes: Sizes = FULL) -> dict:
    from mi_displace.render import scene as scenes
    from mi_displace.vdm import build, methods, table

    def load(mode):
        return scenes.load(SCENE, mode=mode, integrator="raster", res=sizes.res,
                           **methods.params_for(mode, sizes.params))[0]

    approx = load("approximation")
    bsdf = approx.shapes()[0].bsdf()
    spec = bsdf.data.spec
    heights = table.sample_heights(bsdf.height, spec.res, bsdf.tiling)
    builds = []
    for _ in range(2):
        start = time.perf_counter()
        data = build.build(heights, spec, use_cache=False)
        builds.append(time.perf_counter() - start)
    rmse_vdm, rmse_mvm = data.reconstruction_rmse(8, 4)
    table_b, comp_b = data.table_bytes(), data.compressed.nbytes(8, 4)

    render_s = _median_render(approx, sizes.repeats)
    start = time.perf_counter()
    ref = load("reference")
    ref_build = time.perf_counter() - start
    ref_render = _median_render(ref, sizes.repeats)
    del ref
    gc.collect()
    base = load("base")
    base_render = _median_render(base, sizes.repeats)
    del base, approx
    gc.collect()

    result = methods.methods_table(SCENE, {**sizes.params, "res": str(sizes.methods_res)},
                                   repeats=min(3, sizes.repeats))
    rows = result["rows"]
    vdm_row = next(r for r in rows if r["method"] == "approximation")
    return {
        "variant": mi.variant(),
        "table_sizes": {"res": spec.res, "phi": spec.n_phi, "theta": spec.n_theta,
                        "curvatures": spec.n_curv},
        "curvature_range_tile": list(map(float, spec.c_range)),
        "build_time_s": builds[1], "build_time_cold_s": builds[0],
        "build_stages_s": {k: data.stats[k] for k in ("cast_s", "resample_s", "svd_s")},
        "reference_build_s": ref_build, "build_vs_reference_build": builds[1] / ref_build,
        "table_mb": table_b / 1e6, "compressed_mb": comp_b / 1e6,
        "compression_ratio": table_b / comp_b,
        "reconstruction_rmse": rmse_vdm, "reconstruction_rmse_mvm": rmse_mvm,
        "silhouette_mismatch": data.silhouette_mismatch(4),
        "render_time_warm_s": render_s, "reference_render_time_s": ref_render,
        "base_render_time_s": base_render, "render_speedup_vs_reference": ref_render / render_s,
        "flip_vs_reference": vdm_row["flip"],
        "methods": [{k: v for k, v in r.items()} for r in rows],
        "mask_pixels": result["mask_pixels"],
        "targets": TARGETS,
    }


def main(json: bool = False, quick: bool = False) -> dict:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and print its record."""
    # a private table cache, so that the bench never reads a stale one
    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get("MI_DISPLACE_CACHE")
        os.environ["MI_DISPLACE_CACHE"] = tmp
        try:
            record = run(QUICK if quick else FULL)
        finally:
            if old is None:
                del os.environ["MI_DISPLACE_CACHE"]
            else:
                os.environ["MI_DISPLACE_CACHE"] = old
    if json:
        print(_json.dumps(record, indent=2))
    else:
        from mi_displace.vdm.methods import markdown

        for key, value in record.items():
            if key == "methods":
                print(markdown(value))
            else:
                print(f"{key:>28}: {value:.4g}" if isinstance(value, float) else f"{key:>28}: {value}")
    return record
