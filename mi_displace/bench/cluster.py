"""``mi-displace bench cluster``: one 24-point sweep run locally and on a local Dask cluster.

The sweep (:data:`FULL`) is the packaged ``scenes/tradeoff/bumpy_sphere.xml`` at 64x64:
``resolution`` (8 values) x ``ball.scale`` (3 values), each point its own job (cold + 3
warm rounds).  It runs once in this process and once on ``local:2`` (two single-threaded
worker processes on this machine), each with an empty point cache, and reports both wall
times, whether every
point's FLIP agrees exactly (raster is deterministic), and the scheduling overhead per job:
``(wall - worker start-up) * workers / jobs - mean job time on the workers``.  On a 2-core
machine the cluster cannot be faster than the local run; the point is that the numbers are
the same and what the machinery costs.

``--quick`` runs the same with :data:`QUICK` sizes (4 points at 32x32, one warm round).
"""
from __future__ import annotations

import statistics
import time
from typing import NamedTuple

from mi_displace.bench._timing import print_record
from mi_displace.core.resources import scene_path

SCENE = scene_path("tradeoff", "bumpy_sphere.xml")
WORKERS = 2


class Sizes(NamedTuple):
    """The sweep: ``knobs`` (``name=v1,v2,...``, their product is the points), images of
    ``res`` x ``res`` pixels, ``warm_rounds`` timed rounds per point after the cold one."""
    knobs: tuple
    res: int
    warm_rounds: int


FULL = Sizes(("resolution=6,8,12,16,24,32,48,64", "ball.scale=0.1,0.15,0.2"), 64, 3)
QUICK = Sizes(("resolution=6,8", "ball.scale=0.1,0.2"), 32, 1)


def _startup_s() -> float:
    """Seconds to start and stop a local cluster of :data:`WORKERS` workers (no jobs)."""
    from mi_displace.evaluate.jobs import _Cluster

    start = time.perf_counter()
    _Cluster(f"local:{WORKERS}").close()
    return time.perf_counter() - start


def run(sizes: Sizes = FULL) -> dict:
    """Both runs (module docstring); returns the JSON record."""
    import numpy as np

    from mi_displace.evaluate import compare as cmp
    from mi_displace.evaluate import tradeoff as tr
    from mi_displace.evaluate.jobs import check_cluster, run_jobs

    check_cluster(f"local:{WORKERS}")   # the [cluster] extra, before the local half runs
    knobs = [tr.parse_knob(k) for k in sizes.knobs]
    settings = cmp.protocol_settings(SCENE, {"res": str(sizes.res)})
    jobs = [tr._point_job(SCENE, settings, point, knobs, sizes.warm_rounds)
            for point in tr.sweep_points(knobs)]
    record = {"scene": SCENE.name, "knobs": list(sizes.knobs), "res": sizes.res,
              "points": len(jobs), "workers": WORKERS}
    outcomes = {}
    for name, cluster in (("local", None), ("cluster", f"local:{WORKERS}")):
        start = time.perf_counter()
        outcomes[name] = run_jobs(tr.measure_point, jobs, cluster=cluster, progress=True,
                                  desc=name)
        record[f"{name}_wall_s"] = time.perf_counter() - start
    local, remote = outcomes["local"], outcomes["cluster"]
    record["all_ok"] = all(o["ok"] for o in local + remote)
    record["identical_images"] = record["all_ok"] and all(
        np.array_equal(a["value"]["image"], b["value"]["image"]) for a, b in zip(local, remote))
    record["hosts"] = sorted({o["host"] for o in remote})
    record["cluster_startup_s"] = _startup_s()
    record["mean_job_s_local"] = statistics.mean(o["job_s"] for o in local)
    record["mean_job_s_cluster"] = statistics.mean(o["job_s"] for o in remote)
    record["overhead_per_job_s"] = ((record["cluster_wall_s"] - record["cluster_startup_s"])
                                    * WORKERS / len(jobs) - record["mean_job_s_cluster"])
    return record


def main(json: bool = False, quick: bool = False) -> int:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and print its record."""
    print_record(run(QUICK if quick else FULL), json, width=0)
    return 0
