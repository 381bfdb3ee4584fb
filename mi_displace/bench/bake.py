"""`mi-displace bench bake`: the baker's timing table, restoration error and compression.

Pair: the Stanford bunny (``data/bunny/stanford-bunny.obj``, 69,451 faces, the paper's
"Rabbit") and a low-poly of 4,857 faces (the paper's count, Fig. 15) simplified from it with
fast-simplification and unwrapped with xatlas (preparation, not timed).

* timing table (Fig. 13/14/17): warm bake time at 512..4096 texels, aa 1 and 2 (2x2 = 4
  samples, the paper's 4x AA), each *including* the acceleration structures (high-poly BVH and
  UV layout) and edge padding; beside it the naive per-texel baker
  (:mod:`mi_displace.bake.naive`, trimesh + Embree) on the same rays where it runs in
  reasonable time (up to 2048^2 without AA, 1024^2 with);
* restoration at 1024^2 with two levels of 1->4 subdivision, restored from the 16-bit map:
  meshdiff against the original (written to ``docs/figures/bake_meshdiff.json``);
* compression (Fig. 21) at 1024^2 and 512^2 for PNG-16, EXR-zip and JPEG 2000 (at 60, 50
  and 45 dB PSNR) with their restoration error (``docs/figures/bake_compression.json``);
* the spot cow (``data/spot``, 5,856 faces) over three low-polys: the baker's own
  (Taubin smoothing + fast-simplification to 1,000 and 2,000 faces, xatlas UVs) and Crane's
  372-face Catmull-Clark control cage (its own UVs): seconds of the whole ``bake()`` call at
  1024^2 (simplification, unwrapping and files included), ambiguous texels
  (diagnostics mode) and the restoration error at 1..3 levels (``docs/figures/bake_spot.json``);
* multistep displacement (§4, Fig. 9): a sphere with a horn leaning 80 degrees (an overhang,
  not a height field over the sphere) restored from one map vs two maps (intermediate: the
  horn leaning 40 degrees), same final triangle count (``docs/figures/bake_multistep.json``).

* cold start (issue 16 item 7): fresh processes bake the bunny at 1024^2 twice, then 2048^2
  twice, once with the kernel cache on disk (a user's later runs) and once with an empty
  one (``HOME`` pointed at a new folder: a user's very first run); the first bake against
  the second of the same size is the cold-start cost, the first 2048^2 bake against the
  second shows whether a new resolution compiles new kernels (``bake_cold_start.json``).

Only the timing table and the cold start hold the shared timing lock
(``/tmp/mi_displace_timing.lock``), and only in a full run.  ``--quick`` runs every part
with :data:`QUICK` sizes (64^2 timing table, cold start at 128^2 / 256^2 with an empty
kernel cache only, everything else at 64^2 to 128^2, 2,500 mesh-distance samples), without
the lock.

Every figure is written as JSON (and the plot as PNG) under ``--out`` (default: a folder
``mi_displace_bench/bake`` in the system's temporary directory, never inside the checkout);
the documentation's figures are refreshed only by naming them: ``mi-displace bench bake
--out docs/figures``.
"""
from __future__ import annotations

import contextlib
import json as _json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import drjit as dr
import numpy as np

from mi_displace.bench._timing import output_dir
from mi_displace.core.resources import data_path

HIGH = data_path("bunny", "stanford-bunny.obj")
LOW_FACES = 4857
SPOT = data_path("spot", "spot_triangulated.obj")
SPOT_CAGE = data_path("spot", "spot_control_mesh.obj")


class Sizes(NamedTuple):
    """Map sides (texels) of each part: the timing table's ``table`` (aa 1 and 2; the naive
    baker where res x aa <= ``naive_max``), the cold start's ``cold`` pair (first and new
    resolution), ``multistep``, ``spot``, the restoration ``sweep``, and ``compression``
    (the first also gives the record's meshdiff and compression ratio); ``headline``: the
    table row of ``bake_time_warm_s``; ``timing_lock``: hold the shared timing lock;
    ``cold_cases``: the cold start's (label, empty kernel cache) cases; ``samples``: points
    per direction of the restoration errors (twice that for the meshdiff and Spot's);
    ``spot_faces``: Spot's simplified low-polys (faces), beside its control cage."""
    table: tuple
    naive_max: int
    headline: int
    cold: tuple
    multistep: int
    spot: int
    sweep: tuple
    compression: tuple
    timing_lock: bool
    cold_cases: tuple
    samples: int
    spot_faces: tuple


COLD_CASES = (("kernel_cache_on_disk", False), ("empty_kernel_cache", True))
FULL = Sizes((512, 1024, 2048, 4096), 2048, 2048, (1024, 2048), 512, 1024,
             (256, 512, 1024, 2048), (1024, 512), True, COLD_CASES, 50_000, (1000, 2000))
QUICK = Sizes((64,), 128, 64, (128, 256), 64, 128, (64,), (128,), False, COLD_CASES[1:],
              2_500, (1000,))


def _distance(a, b, samples: int) -> dict:
    """:func:`mi_displace.evaluate.metrics.mesh_distance` of two meshes with ``positions``
    and ``faces`` (``a``: the reference)."""
    from mi_displace.evaluate.metrics import mesh_distance

    return mesh_distance((a.positions, a.faces), (b.positions, b.faces), samples=samples)


def _pair():
    from mi_displace.bake.meshdata import load_mesh
    from mi_displace.bake.unwrap import make_low_poly, unwrap

    high = load_mesh(HIGH, "high-poly")
    low = unwrap(make_low_poly(high, LOW_FACES, smoothing_iterations=0))
    return high, low


def bake_warm(high, low, res: int, aa: int, max_distance: float, delta: float) -> float:
    """Seconds of one in-memory bake: acceleration structures + raster/trace + padding."""
    from mi_displace.bake import padding
    from mi_displace.bake.baker import Baker
    from mi_displace.bake.trace import EMPTY, OK

    start = time.perf_counter()
    baker = Baker(high, low)
    image, _ = baker.run(res, res, aa, max_distance, delta, False)
    status = image[..., Baker.CHANNELS["status"][0]]
    padding.pad(image, status == OK, 8)
    padding.pad((status == OK).astype(np.float32), status != EMPTY, 8)
    dr.sync_thread()
    return time.perf_counter() - start


def _median(fn, repeats: int) -> float:
    return statistics.median(fn() for _ in range(repeats))


def timing_table(high, low, max_distance, delta, sizes: Sizes = FULL) -> list[dict]:
    from mi_displace.bake.naive import naive_bake

    rows = []
    bake_warm(high, low, 256, 1, max_distance, delta)  # cold: JIT compilation
    bake_warm(high, low, 256, 2, max_distance, delta)
    for res in sizes.table:
        for aa in (1, 2):
            reps = 3 if res * aa <= 2048 else 1
            ours = _median(lambda: bake_warm(high, low, res, aa, max_distance, delta), reps)
            naive = None
            if res * aa <= sizes.naive_max:
                start = time.perf_counter()
                naive_bake(high, low, res, max_distance, delta, aa)
                naive = time.perf_counter() - start
            rows.append({"res": res, "aa": aa, "samples_per_texel": aa * aa, "ours_s": ours,
                         "naive_s": naive, "speedup": None if naive is None else naive / ours})
    return rows


_COLD_SCRIPT = """
import json, sys, time
import drjit as dr
import mi_displace
mi_displace.init()
from mi_displace.bench.bake import _pair, bake_warm
from mi_displace.bake.baker import DEFAULT_DELTA_REL, default_max_distance
high, low = _pair()
dist, _ = default_max_distance(high, low)
delta = DEFAULT_DELTA_REL * high.diagonal
dr.set_flag(dr.JitFlag.KernelHistory, True)
rows = []
first, new = int(sys.argv[1]), int(sys.argv[2])
for res in (first, first, new, new):
    dr.kernel_history_clear()
    seconds = bake_warm(high, low, res, 1, dist, delta)
    jit = [k for k in dr.kernel_history([dr.KernelType.JIT])]
    new = [k for k in jit if not k.get("cache_hit") and not k.get("cache_disk")]
    rows.append({"res": res, "s": seconds, "kernels": len(jit), "compiled": len(new),
                 "compile_s": sum(k.get("codegen_time", 0) + k.get("backend_time", 0) for k in new) / 1e3})
print(json.dumps(rows))
"""


def cold_start(sizes: Sizes = FULL) -> dict:
    """First vs later bakes in fresh processes (see the module docstring; :data:`FULL`:
    1024^2 then 2048^2); seconds.  The field names keep the full run's sizes."""
    script = [sys.executable, "-c", _COLD_SCRIPT, *map(str, sizes.cold)]
    out = {}
    for label, empty in sizes.cold_cases:
        with tempfile.TemporaryDirectory() as home:
            env = dict(os.environ)
            if empty:
                env["HOME"] = home          # Dr.Jit keeps its kernel cache in ~/.drjit
            else:   # fill the cache first, so the measured process finds every kernel on disk
                subprocess.run(script, env=env, check=True, capture_output=True)
            run = subprocess.run(script, env=env, check=True, capture_output=True, text=True)
        r = _json.loads(run.stdout.strip().splitlines()[-1])
        out[label] = {"first_1024_s": r[0]["s"], "warm_1024_s": r[1]["s"],
                      "cold_ratio_1024": r[0]["s"] / r[1]["s"],
                      "first_2048_s": r[2]["s"], "warm_2048_s": r[3]["s"],
                      "new_resolution_ratio": r[2]["s"] / r[3]["s"],
                      "kernels_per_bake": r[0]["kernels"],
                      "compiled_first_1024": r[0]["compiled"], "compile_s_first_1024": r[0]["compile_s"],
                      "compiled_first_2048": r[2]["compiled"], "compile_s_first_2048": r[2]["compile_s"]}
    return out


def restoration_and_compression(high, low, sizes: Sizes = FULL) -> tuple[dict, list[dict]]:
    from mi_displace.bake import compression
    from mi_displace.bake.baker import bake
    from mi_displace.bake.restore import restore

    original = compression.mesh_bytes(high, with_uvs=False)
    low_b = compression.mesh_bytes(low, with_uvs=True)
    rows, meshdiff = [], None
    for res in sizes.compression:
        with tempfile.TemporaryDirectory() as tmp:
            result = bake(high, low, res=res, out_dir=tmp, map_formats=["d16"])
            if res == sizes.compression[0]:
                restored = restore(Path(tmp) / "low.obj", Path(tmp) / "d16.png", levels=2)
                diff = _distance(high, restored, 2 * sizes.samples)
                low_only = _distance(high, low, 2 * sizes.samples)
                meshdiff = {"a": "data/bunny/stanford-bunny.obj",
                            "b": f"restored ({res}^2 d16.png, levels 2)",
                            "restored_faces": int(len(restored.faces)), "restore_s": restored.seconds,
                            **diff, "low_poly_only": {k: low_only[k] for k in ("rms_rel", "hausdorff_rel")}}
        mask_b = compression.mask_bytes(result.maps["valid"])
        for codec, level in (("png16", None), ("exr_zip", None), ("jpeg2k", 60.0), ("jpeg2k", 50.0),
                             ("jpeg2k", 45.0)):
            size, decoded = compression.encode_map(result.maps["displacement"], codec,
                                                   jpeg2k_level=level or 60.0)
            r = restore(low, {"displacement": decoded, "valid": result.maps["valid"]}, levels=2)
            d = _distance(high, r, sizes.samples)
            total = low_b + size + mask_b
            rows.append({"res": res, "codec": codec, "jpeg2k_psnr_db": level, "map_bytes": size,
                         "low_bytes": low_b, "mask_bytes": mask_b, "original_bytes": original,
                         "ratio": original / total, "hausdorff_rel": d["hausdorff_rel"],
                         "rms_rel": d["rms_rel"]})
    return meshdiff, rows


def restoration_sweep(high, low, sizes: Sizes = FULL) -> list[dict]:
    """Restoration error against map resolution and subdivision levels (16-bit maps)."""
    from mi_displace.bake.baker import bake
    from mi_displace.bake.restore import restore
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for res in sizes.sweep:
            bake(high, low, res=res, out_dir=tmp, map_formats=["d16"])
            for levels in (1, 2, 3):
                r = restore(Path(tmp) / "low.obj", Path(tmp) / "d16.png", levels=levels)
                d = _distance(high, r, sizes.samples)
                rows.append({"res": res, "levels": levels, "faces": int(len(r.faces)),
                             "restore_s": r.seconds, "hausdorff_rel": d["hausdorff_rel"],
                             "rms_rel": d["rms_rel"]})
    return rows


def spot_pairs(sizes: Sizes = FULL) -> list[dict]:
    """Spot over its simplified low-polys and over its control cage (see the docstring)."""
    from mi_displace.bake.baker import bake
    from mi_displace.bake.meshdata import load_mesh
    from mi_displace.bake.restore import restore

    high = load_mesh(SPOT, "high-poly")
    res = sizes.spot
    pairs = [(f"simplified to {n:,} faces", None, n) for n in sizes.spot_faces]
    pairs.append(("control cage (Catmull-Clark)", load_mesh(SPOT_CAGE, "low-poly"), 0))
    rows = []
    for label, low, faces in pairs:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            result = bake(high, low, res=res, out_dir=tmp, map_formats=["d16"], diagnostics=True,
                          target_faces=faces or 5000)
            seconds = time.perf_counter() - start
            low_used = result.low
            counts = result.record["counts"]
            low_only = _distance(high, low_used, 2 * sizes.samples)
            row = {"low": label, "low_faces": int(len(low_used.faces)), "res": res,
                   "bake_call_s": seconds, "ambiguous_fraction": counts["ambiguous"] / counts["covered"],
                   "low_only": {k: low_only[k] for k in ("rms_rel", "hausdorff_rel")}, "levels": []}
            for levels in (1, 2, 3):
                r = restore(Path(tmp) / "low.obj", Path(tmp) / "d16.png", levels=levels)
                d = _distance(high, r, 2 * sizes.samples)
                row["levels"].append({"levels": levels, "faces": int(len(r.faces)),
                                      "rms_rel": d["rms_rel"], "hausdorff_rel": d["hausdorff_rel"]})
            rows.append(row)
    return rows


def multistep_example(sizes: Sizes = FULL) -> dict:
    """One map vs two maps on the leaning-horn sphere (see the module docstring)."""
    from mi_displace.bake.baker import bake
    from mi_displace.bake.multistep import leaning_horn_sphere, multistep_bake, multistep_restore
    from mi_displace.bake.restore import restore

    res = sizes.multistep
    high = leaning_horn_sphere(256, 128, height=0.6, width=0.2, tilt_deg=80)
    inter = leaning_horn_sphere(128, 64, height=0.6, width=0.2, tilt_deg=40)
    high.uvs = inter.uvs = None
    low = leaning_horn_sphere(32, 16, height=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        one = bake(high, low, res=res, out_dir=Path(tmp) / "one", map_formats=["float"],
                   max_distance=0.8, diagnostics=True)
        r1 = restore(Path(tmp) / "one" / "low.obj", Path(tmp) / "one" / "float.exr", levels=3)
        two = multistep_bake(high, inter, low, Path(tmp) / "two", res=res, levels1=2,
                             max_distance1=0.8, diagnostics=True)
        r2 = multistep_restore(Path(tmp) / "two" / "stage1" / "low.obj",
                               Path(tmp) / "two" / "stage1" / "float.exr",
                               Path(tmp) / "two" / "stage2" / "float.exr", 2, 1)
    d1, d2 = _distance(high, r1, sizes.samples), _distance(high, r2, sizes.samples)
    return {"res": res, "one_step": {"faces": int(len(r1.faces)), "ambiguous_texels": one.record["counts"]["ambiguous"],
                                     "hausdorff_high_to_restored": d1["hausdorff_ab"],
                                     "hausdorff_rel": d1["hausdorff_rel"], "rms_rel": d1["rms_rel"]},
            "two_step": {"faces": int(len(r2.faces)), "hausdorff_high_to_restored": d2["hausdorff_ab"],
                         "ambiguous_texels_stage1": two.stage1["counts"]["ambiguous"],
                         "ambiguous_texels_stage2": two.stage2["counts"]["ambiguous"],
                         "hausdorff_rel": d2["hausdorff_rel"], "rms_rel": d2["rms_rel"]}}


class _TimingLock:
    """The shared timing lock of the project (flock on /tmp/mi_displace_timing.lock)."""

    def __enter__(self):
        import fcntl

        self.f = open("/tmp/mi_displace_timing.lock", "a")
        fcntl.flock(self.f, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc):
        import fcntl

        fcntl.flock(self.f, fcntl.LOCK_UN)
        self.f.close()


def run(out=None, sizes: Sizes = FULL) -> dict:
    """Every part at ``sizes``; JSON and the plot are written under ``out``."""
    from mi_displace.bake.baker import DEFAULT_DELTA_REL, default_max_distance

    out = output_dir("bake", out)
    high, low = _pair()
    max_distance, _ = default_max_distance(high, low)
    delta = DEFAULT_DELTA_REL * high.diagonal
    with _TimingLock() if sizes.timing_lock else contextlib.nullcontext():
        table = timing_table(high, low, max_distance, delta, sizes)
        cold = cold_start(sizes)
    multistep = multistep_example(sizes)
    spot = spot_pairs(sizes)
    sweep = restoration_sweep(high, low, sizes)
    meshdiff, comp = restoration_and_compression(high, low, sizes)
    headline = next(r for r in table if r["res"] == sizes.headline and r["aa"] == 1)
    png16 = next(r for r in comp if r["codec"] == "png16" and r["res"] == sizes.compression[0])
    record = {
        "high_faces": int(len(high.faces)), "low_faces": int(len(low.faces)),
        "bake_time_warm_s": headline["ours_s"], "naive_time_s": headline["naive_s"],
        "speedup_vs_naive": headline["speedup"],
        "restore_hausdorff_rel": meshdiff["hausdorff_rel"], "restore_rms_rel": meshdiff["rms_rel"],
        "compression_ratio": png16["ratio"],
        "compression_ratio_best": max((r["ratio"] for r in comp if r["hausdorff_rel"] <= 0.005),
                                      default=None),
        "timing_table": table, "compression": comp, "meshdiff": meshdiff, "multistep": multistep,
        "restoration_sweep": sweep, "spot": spot, "cold_start": cold,
        "search_distance": max_distance,
        "targets": {"bake_time_warm_s": 1.5, "speedup_vs_naive": 3.0, "restore_hausdorff_rel": 0.005},
    }
    for name, value in (("bake_meshdiff", meshdiff), ("bake_compression", comp),
                        ("bake_multistep", multistep), ("bake_bench", record),
                        ("bake_restore_error", sweep), ("bake_spot", spot), ("bake_cold_start", cold)):
        (out / f"{name}.json").write_text(_json.dumps(value, indent=2))
    _plot(table, comp, sweep, out)
    record["out"] = str(out)
    return record


def _plot(table, comp, sweep, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    for aa in (1, 2):
        rows = [r for r in table if r["aa"] == aa]
        ax[0].plot([r["res"] for r in rows], [r["ours_s"] for r in rows], "o-", label=f"ours, aa {aa}")
        nv = [r for r in rows if r["naive_s"] is not None]
        ax[0].plot([r["res"] for r in nv], [r["naive_s"] for r in nv], "s--", label=f"naive, aa {aa}")
    ax[0].set(xscale="log", yscale="log", xlabel="map side [texels]", ylabel="bake time [s]",
              title="bunny 69k -> 4.9k faces (2 cores)")
    ax[0].legend()
    for r in comp:
        label = f"{r['codec']}{'' if r['jpeg2k_psnr_db'] is None else ' %g dB' % r['jpeg2k_psnr_db']}, {r['res']}"
        ax[1].scatter(r["ratio"], r["hausdorff_rel"] * 100, label=label,
                      marker="o" if r["res"] == 1024 else "^")
    ax[1].set(xscale="log", xlabel="compression ratio (original / (low + map + mask))",
              ylabel="Hausdorff [% of diagonal]", title="restoration, 2 levels (Fig. 21)")
    ax[1].legend(fontsize=6)
    for levels in (1, 2, 3):
        rows = [r for r in sweep if r["levels"] == levels]
        ax[2].plot([r["res"] for r in rows], [r["hausdorff_rel"] * 100 for r in rows], "o-",
                   label=f"Hausdorff, {levels} levels")
        ax[2].plot([r["res"] for r in rows], [r["rms_rel"] * 100 for r in rows], "s--",
                   label=f"RMS, {levels} levels")
    ax[2].axhline(0.5, color="grey", lw=0.8)
    ax[2].set(xscale="log", yscale="log", xlabel="map side [texels]", ylabel="% of diagonal",
              title="restoration error (16-bit map)")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "bake_bench.png", dpi=100)
    plt.close(fig)


def main(json: bool = False, quick: bool = False, out=None) -> int:
    """Run everything (:data:`QUICK` sizes with ``quick``); figures go to ``out`` (default:
    :func:`~mi_displace.bench._timing.output_dir`, outside the repository)."""
    record = run(out, QUICK if quick else FULL)
    if json:
        print(_json.dumps(record, indent=2))
    else:
        for key in ("bake_time_warm_s", "naive_time_s", "speedup_vs_naive", "restore_hausdorff_rel",
                    "restore_rms_rel", "compression_ratio"):
            print(f"{key:>24}: {record[key]:.4g}")
        for r in record["timing_table"]:
            print(r)
        for label, c in record["cold_start"].items():
            print(f"cold start ({label}): first 1024^2 {c['first_1024_s']:.3f} s, warm "
                  f"{c['warm_1024_s']:.3f} s ({c['cold_ratio_1024']:.2f}x); first 2048^2 "
                  f"{c['first_2048_s']:.3f} s, warm {c['warm_2048_s']:.3f} s "
                  f"({c['new_resolution_ratio']:.2f}x)")
        print(f"figures written to {record['out']}")
    return 0
