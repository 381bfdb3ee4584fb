"""The measured figures of docs/slicing.md (``mi-displace slicing-figures [--quick]``).

* ``slicing_fig10``: the paper's Fig. 10 made numeric — FLIP against the path-traced
  reference vs slice count for each direction (a, b, c, best, screen) at three view angles
  (30, 60, 85 degrees from the normal) on the brick plane (scenes/slicing_plane_grazing.xml).
* ``slicing_tradeoff``: the bricked donut (scenes/slicing_donut.xml): error vs render time
  for each direction over slice counts (and ``auto``), the path tracer's own error vs spp,
  relief mapping (steps), VDM, and true displacement (``displaced`` resolution) under raster.
* ``slicing_depth``: the cup as depth object vs visual hull, and the depth object's error vs
  slices and vs the view's azimuth relative to the cube faces.

Approximations render with ``raster`` at one sample per pixel (as a GPU draws them); the
references with the scenes' ``path`` (direct light) at ``REF_SPP`` samples.  Times are warm
medians in this process.  Outputs: ``<out>/slicing_*.json`` and ``.png``.
"""
from __future__ import annotations

import json
import math
import statistics
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.evaluate.metrics import flip

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _load(name, **params):
    dr.sync_thread()
    start = time.perf_counter()
    scene = mi.load_file(str(SCENES / name), **{k: str(v) for k, v in params.items()})
    dr.sync_thread()
    return scene, time.perf_counter() - start


def _render(scene, integrator=None, spp=None, seed=0, repeats=2):
    """(image, warm render seconds): one cold render, then the median of ``repeats``."""
    kw = {} if integrator is None else {"integrator": integrator}
    if spp is not None:
        kw["spp"] = spp
    times, img = [], None
    for i in range(repeats + 1):
        dr.sync_thread()
        start = time.perf_counter()
        img = np.asarray(mi.render(scene, seed=seed, **kw), np.float32)[..., :3]
        times.append(time.perf_counter() - start)
    assert np.all(np.isfinite(img)), "non-finite pixels"
    return img, statistics.median(times[1:]) if repeats else times[0]


def reference(name, spp, **params):
    scene, _ = _load(name, mode="reference", integrator="path", **params)
    img, seconds = _render(scene, spp=spp, repeats=0)
    other, _ = _render(scene, spp=spp, seed=1, repeats=0)
    return 0.5 * (img + other), flip(img, other)[0], seconds


def approximation(name, raster, mode="approximation", **params):
    scene, build = _load(name, mode=mode, integrator="raster", **params)
    img, seconds = _render(scene, raster)
    stats = [getattr(s, "build_stats", {}) for s in scene.shapes()]
    return img, build, seconds, stats[0] if stats else {}


def fig10(out: Path, quick: bool, raster) -> dict:
    res = 64 if quick else 128
    counts = (4, 16, 64) if quick else (4, 8, 16, 32, 64, 128)
    rows = []
    for theta in (30, 60, 85):
        elevation = 6 / math.tan(math.radians(theta))
        ref, floor, _ = reference("slicing_plane_grazing.xml", 64 if quick else 256, res=res,
                                  elevation=f"{elevation:.4f}")
        for direction in ("a", "b", "c", "best", "screen"):
            for n in counts:
                img, build, seconds, stats = approximation(
                    "slicing_plane_grazing.xml", raster, res=res, elevation=f"{elevation:.4f}",
                    slices=n, direction=direction)
                rows.append({"theta_deg": theta, "direction": direction, "slices": n,
                             "flip": flip(ref, img)[0], "noise_floor": floor, "render_s": seconds,
                             "build_s": build, "slice_triangles": stats.get("slice_triangles")})
                print(f"fig10 theta={theta} {direction} N={n}: FLIP {rows[-1]['flip']:.4f}", flush=True)
    return {"resolution": res, "rows": rows}


def tradeoff(out: Path, quick: bool, raster) -> dict:
    res = 64 if quick else 128
    name = "slicing_donut.xml"
    ref, floor, ref_s = reference(name, 128 if quick else 512, res=res, resolution=1536)
    rows = []

    def add(method, knob, img, build, seconds, **extra):
        rows.append({"method": method, "knob": knob, "flip": flip(ref, img)[0],
                     "build_s": build, "render_s": seconds, **extra})
        print(f"tradeoff {method} {knob}: FLIP {rows[-1]['flip']:.4f}, {seconds:.3f} s", flush=True)

    for direction in ("a", "b", "c", "best", "screen"):
        for n in ((4, 16) if quick else (4, 12, 25, 48)):
            img, build, seconds, stats = approximation(name, raster, res=res, slices=n, direction=direction)
            add(f"slicing {direction}", n, img, build, seconds, bytes=stats.get("bytes"))
    img, build, seconds, stats = approximation(name, raster, res=res, slices="auto", direction="best")
    add("slicing best auto", stats.get("slices"), img, build, seconds, bytes=stats.get("bytes"))
    for steps in ((8, 32) if quick else (8, 16, 32, 64)):
        scene, build = _load(name, mode="relief", integrator="raster", res=res)
        for shape in scene.shapes():
            bsdf = shape.bsdf()
            if hasattr(bsdf, "steps"):
                bsdf.steps = steps
        img, seconds = _render(scene, raster)
        add("relief", steps, img, build, seconds)
    img, build, seconds, stats = approximation(name, raster, mode="vdm", res=res)
    add("vdm", "default table", img, build, seconds)
    for resolution in ((128, 512) if quick else (128, 256, 512, 1024)):
        img, build, seconds, stats = approximation(name, raster, mode="reference", res=res,
                                                   resolution=resolution)
        add("displaced (raster)", resolution, img, build, seconds, bytes=stats.get("bytes"))
    scene, _ = _load(name, mode="reference", integrator="path", res=res, resolution=1536)
    for spp in ((1, 8, 32) if quick else (1, 4, 16, 64, 256)):
        img, seconds = _render(scene, spp=spp, seed=7, repeats=1)
        add("path", spp, img, 0.0, seconds)
    return {"resolution": res, "reference_spp": 128 if quick else 512, "noise_floor": floor,
            "reference_s": ref_s, "rows": rows}


def depth(out: Path, quick: bool, raster) -> dict:
    res = 96 if quick else 160
    rows = []
    radius, height = 3.8, 2.3
    for azimuth in ((0, 45) if quick else (0, 22.5, 45)):
        a = math.radians(azimuth)
        cam = f"{radius * math.sin(a):.4f}, {-radius * math.cos(a):.4f}, {height}"
        for scene_name in ("slicing_cup_depth.xml", "slicing_cup_hull.xml"):
            ref, floor, _ = reference(scene_name, 64 if quick else 256, res=res, cam=cam)
            for n in ((50, 150) if quick else (25, 75, 150, 300)):
                img, build, seconds, _ = approximation(scene_name, raster, res=res, cam=cam, slices=n)
                rows.append({"object": "hull" if "hull" in scene_name else "depth", "azimuth_deg": azimuth,
                             "slices": n, "flip": flip(ref, img)[0], "noise_floor": floor,
                             "render_s": seconds, **geometric_error(scene_name, cam, res, n)})
                print(f"depth {rows[-1]['object']} az={azimuth} N={n}: FLIP {rows[-1]['flip']:.4f}", flush=True)
    return {"resolution": res, "rows": rows}


def geometric_error(scene_name: str, cam: str, res: int, slices: int) -> dict:
    """Where the depth object / hull puts the first surface vs the true cup, per pixel
    centre: mean distance along the ray (pixels both hit) and the fraction of pixels whose
    first hit is more than 0.05 (the cup's wall: 0.06) from the truth or covers wrongly."""
    from mi_displace.slicing import depth_object as dobj

    images = dobj.read(SCENES / "parts" / "slicing_cup_depth" / "cube.json")
    obj = dobj.DepthObject(images, slices, hull="hull" in scene_name)
    truth = mi.load_dict({"type": "scene", "cup": {"type": "ply", "filename": str(SCENES / "parts" / "slicing_cup.ply")}})
    sensor = mi.load_dict({"type": "perspective", "fov": 30, "film": {"type": "hdrfilm", "width": res, "height": res},
                           "to_world": mi.ScalarTransform4f().look_at(
                               origin=[float(x) for x in cam.split(",")], target=[0, 0, 0.33], up=[0, 0, 1])})
    idx = dr.arange(mi.UInt32, res * res)
    uv = mi.Point2f((mi.Float(idx % res) + 0.5) / res, (mi.Float(idx // res) + 0.5) / res)
    ray, _ = sensor.sample_ray(0.0, 0.5, uv, mi.Point2f(0.5))
    si = truth.ray_intersect(ray)
    found, p = obj.find(ray.o, ray.d, mi.Bool(True))
    t_true = np.where(np.array(si.is_valid()), np.array(si.t), np.inf)
    t_obj = np.where(np.array(found), np.array(dr.norm(p - ray.o)), np.inf)
    both = np.isfinite(t_true) & np.isfinite(t_obj)
    err = np.abs(np.where(both, t_true, 0.0) - np.where(both, t_obj, 0.0))
    wrong = (np.isfinite(t_true) != np.isfinite(t_obj)) | (err > 0.05)
    covered = np.isfinite(t_true) | np.isfinite(t_obj)
    return {"depth_error_mean": float(np.mean(err[both])),
            "wrong_surface_fraction": float(wrong.sum() / max(covered.sum(), 1))}


def plot(out: Path, results: dict) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if "fig10" in results:
        rows = results["fig10"]["rows"]
        fig = Figure(figsize=(12, 3.6))
        FigureCanvasAgg(fig)
        for i, theta in enumerate((30, 60, 85)):
            ax = fig.add_subplot(1, 3, i + 1)
            for direction in ("a", "b", "c", "best", "screen"):
                pts = [(r["slices"], r["flip"]) for r in rows if r["theta_deg"] == theta and r["direction"] == direction]
                ax.plot(*zip(*pts), "o-", label=direction)
            floor = next(r["noise_floor"] for r in rows if r["theta_deg"] == theta)
            ax.axhline(floor, color="gray", ls=":", label="ref. noise")
            ax.set_xscale("log", base=2)
            ax.set_title(f"{theta}° from the normal")
            ax.set_xlabel("slices N")
            ax.set_ylabel("FLIP")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "slicing_fig10.png", dpi=110)
    if "tradeoff" in results:
        rows = results["tradeoff"]["rows"]
        fig = Figure(figsize=(7, 4.5))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(1, 1, 1)
        for method in dict.fromkeys(r["method"] for r in rows):
            pts = [(r["render_s"], r["flip"]) for r in rows if r["method"] == method]
            ax.plot(*zip(*pts), "*" if "auto" in method else "o-", ms=12 if "auto" in method else 5,
                    label=method)
        ax.set_xscale("log")
        ax.set_xlabel("render time, warm (s)")
        ax.set_ylabel("FLIP vs path reference")
        ax.set_title("bricked donut: error vs time")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "slicing_tradeoff.png", dpi=110)
    if "depth" in results:
        rows = results["depth"]["rows"]
        fig = Figure(figsize=(10, 3.6))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(1, 2, 1)
        for obj in ("depth", "hull"):
            for az in sorted({r["azimuth_deg"] for r in rows}):
                pts = [(r["slices"], r["flip"]) for r in rows if r["object"] == obj and r["azimuth_deg"] == az]
                ax.plot(*zip(*pts), "o-" if obj == "depth" else "s--", label=f"{obj} az {az}°")
        ax.set_xlabel("slices N")
        ax.set_ylabel("FLIP")
        ax.legend(fontsize=7)
        ax = fig.add_subplot(1, 2, 2)
        n = max(r["slices"] for r in rows)
        for obj in ("depth", "hull"):
            pts = [(r["azimuth_deg"], r["flip"]) for r in rows if r["object"] == obj and r["slices"] == n]
            ax.plot(*zip(*pts), "o-", label=f"{obj}, N={n}")
        ax.set_xlabel("view azimuth from a cube face (°)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "slicing_depth.png", dpi=110)


def main(out=Path("docs/figures"), quick: bool = False, which=("fig10", "tradeoff", "depth")) -> dict:
    import mi_displace

    mi_displace.init()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    raster = mi.load_dict({"type": "raster", "aa": 1})
    results = {}
    for key, fn in (("fig10", fig10), ("tradeoff", tradeoff), ("depth", depth)):
        if key in which:
            results[key] = fn(out, quick, raster)
            (out / f"slicing_{key}.json").write_text(json.dumps(
                {"command": f"mi-displace slicing-figures{' --quick' if quick else ''}",
                 "variant": mi.variant(), **results[key]}, indent=1))
    plot(out, results)
    return results


if __name__ == "__main__":
    import sys

    main(quick="--quick" in sys.argv,
         which=tuple(a for a in sys.argv[1:] if not a.startswith("--")) or ("fig10", "tradeoff", "depth"))
