"""The measured figures of docs/slicing.md (``mi-displace figures slicing [--quick] [--only PART]``).

Every measurement is :func:`mi_displace.evaluate.tradeoff.tradeoff` on a comparison scene
(the approximation under the scene's ``raster`` at every point, warm time the median of 3
load + render rounds, FLIP against the scene's path-traced reference with its two-seed
noise floor):

* ``slicing_fig10``: the paper's Fig. 10 made numeric — direction (a, b, c, best, screen) ×
  slice count on the brick plane (scenes/slicing_plane_grazing.xml), one sweep per view angle
  (30, 60, 85 degrees from the normal, the scene's ``elevation``);
* ``slicing_tradeoff``: the bricked donut (scenes/slicing_donut.xml): one sweep over explicit
  points — each direction over slice counts (and ``auto``), relief mapping (``relief_steps``),
  VDM, true displacement (``mode=reference``) at several ``resolution`` under raster — with
  the path tracer's own error vs spp;
* ``slicing_depth``: the cup as depth object vs visual hull, one sweep over slices per object
  and view azimuth, with :func:`geometric_error` (where the first surface lies) per point.

Outputs: ``<out>/slicing_*.json`` (rows and the whole tradeoff results) and ``.png``.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.resources import scenes_dir
from mi_displace.evaluate import tradeoff as tr

SCENES = scenes_dir()
DIRECTIONS = ("a", "b", "c", "best", "screen")


def _sweep(name: str, params: dict, reference_spp: int, cache_dir, knobs=None, points=None,
           path_spps=()) -> dict:
    """:func:`tradeoff` on ``scenes/<name>`` with a reference of at most ``reference_spp``."""
    return tr.tradeoff(SCENES / name, knobs, points=points, cache_dir=cache_dir,
                       params={k: str(v) for k, v in params.items()}, max_spp=reference_spp,
                       path_spps=list(path_spps))


def _shape_stat(row: dict, key: str):
    """``build_stats[key]`` of the first shape of a point that reports it (else ``None``)."""
    return next((st[key] for st in row.get("build_stats") or [] if st and key in st), None)


def fig10(quick: bool, cache_dir=None) -> dict:
    res = 64 if quick else 128
    counts = (4, 16, 64) if quick else (4, 8, 16, 32, 64, 128)
    knobs = [tr.parse_knob(f"direction={','.join(DIRECTIONS)}"),
             tr.parse_knob(f"slices={','.join(map(str, counts))}")]
    sweeps = {}
    for theta in (30, 60, 85):
        elevation = f"{6 / math.tan(math.radians(theta)):.4f}"
        sweeps[theta] = _sweep("slicing_plane_grazing.xml", {"res": res, "elevation": elevation},
                               128 if quick else 512, cache_dir, knobs=knobs)
    return {"resolution": res, "rows": fig10_rows(sweeps), "tradeoff": sweeps}


def fig10_rows(sweeps: dict) -> list[dict]:
    """The Fig. 10 table from its sweeps (``{view angle: tradeoff result}``)."""
    return [{"theta_deg": int(theta), "direction": r["direction"], "slices": int(r["slices"]),
             "flip": r["flip"], "noise_floor": result["noise_floor_flip"],
             "render_s": r["render_warm_s"], "time_warm_s": r["time_warm_s"],
             "build_s": r["build_s"], "slice_triangles": _shape_stat(r, "slice_triangles")}
            for theta, result in sweeps.items() for r in tr.table_rows(result)]


def donut_methods(quick: bool) -> list[tuple[str, dict]]:
    """``(method, point)`` of the donut sweep: slicing per direction and count, ``auto``,
    relief steps, VDM, true displacement under raster at several tessellations."""
    counts = (4, 16) if quick else (4, 12, 25, 48)
    methods = [("slicing " + d, {"direction": d, "slices": n}) for d in DIRECTIONS for n in counts]
    methods.append(("slicing best auto", {"direction": "best", "slices": "auto"}))
    methods += [("relief", {"mode": "relief", "relief_steps": n})
                for n in ((8, 32) if quick else (8, 16, 32, 64))]
    methods.append(("vdm", {"mode": "vdm"}))
    methods += [("displaced (raster)", {"mode": "reference", "resolution": n})
                for n in ((128, 512) if quick else (128, 256, 512, 1024))]
    return methods


def tradeoff(quick: bool, cache_dir=None) -> dict:
    res = 64 if quick else 128
    methods = donut_methods(quick)
    result = _sweep("slicing_donut.xml", {"res": res}, 256 if quick else 1024, cache_dir,
                    points=[p for _, p in methods],
                    path_spps=(1, 8, 32) if quick else (1, 4, 16, 64, 256))
    return {"resolution": res, "reference_spp": result["reference_spp"],
            "noise_floor": result["noise_floor_flip"], "reference_s": result["reference_time_s"],
            "rows": donut_rows(result, methods), "tradeoff": result}


def donut_rows(result: dict, methods: list[tuple[str, dict]]) -> list[dict]:
    """The donut table from its sweep: one row per ``(method, point)`` that rendered, then
    the path curve."""
    by_label = {r["label"]: r for r in tr.table_rows(result)}
    rows = []
    for method, point in methods:
        r = by_label.get(tr.point_label(point))
        if r is None:  # recorded as failed in result["points"]
            continue
        knob = (_shape_stat(r, "slices") if point.get("slices") == "auto"
                else next(iter(v for k, v in point.items() if k != "mode" and k != "direction"),
                          "default table"))
        rows.append({"method": method, "knob": knob, "flip": r["flip"], "build_s": r["build_s"],
                     "render_s": r["render_warm_s"], "time_warm_s": r["time_warm_s"],
                     "bytes": _shape_stat(r, "bytes")})
    rows += [{"method": "path", "knob": c["spp"], "flip": c["flip"], "build_s": 0.0,
              "render_s": c["render_s"], "time_warm_s": c["time_s"], "bytes": None}
             for c in result["path_curve"]]
    return rows


def depth(quick: bool, cache_dir=None) -> dict:
    res = 96 if quick else 160
    counts = (50, 150) if quick else (25, 75, 150, 300)
    rows, sweeps = [], {}
    radius, height = 3.8, 2.3
    for azimuth in ((0, 45) if quick else (0, 22.5, 45)):
        a = math.radians(azimuth)
        cam = f"{radius * math.sin(a):.4f}, {-radius * math.cos(a):.4f}, {height}"
        for scene_name in ("slicing_cup_depth.xml", "slicing_cup_hull.xml"):
            obj = "hull" if "hull" in scene_name else "depth"
            result = _sweep(scene_name, {"res": res, "cam": cam}, 128 if quick else 512,
                            cache_dir, knobs=[tr.parse_knob(f"slices={','.join(map(str, counts))}")])
            sweeps[f"{obj} {azimuth}"] = result
            for r in tr.table_rows(result):
                n = int(r["slices"])
                rows.append({"object": obj, "azimuth_deg": azimuth, "slices": n,
                             "flip": r["flip"], "noise_floor": result["noise_floor_flip"],
                             "render_s": r["render_warm_s"], "time_warm_s": r["time_warm_s"],
                             **geometric_error(scene_name, cam, res, n)})
    return {"resolution": res, "rows": rows, "tradeoff": sweeps}


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


def _line(ax, pts: list[tuple[float, float]], fmt: str, label: str) -> None:
    """``pts`` joined on ``ax``; nothing (not a stray format string) when it is empty."""
    if pts:
        ax.plot(*zip(*pts), fmt, label=label)


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
                _line(ax, pts, "o-", direction)
            floor = next(r["noise_floor"] for r in rows if r["theta_deg"] == theta)
            ax.axhline(floor, color="gray", ls=":", label="ref. noise")
            ax.set_xscale("log", base=2)
            ax.set_title(f"{theta}° from the normal")
            ax.set_xlabel("slices N")
            ax.set_ylabel("FLIP")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "slicing_fig10.png", dpi=110)
    if "tradeoff" in results:  # the generic error-vs-time plot with its Pareto front
        tr.plot(results["tradeoff"]["tradeoff"], out / "slicing_tradeoff.png")
    if "depth" in results:
        rows = results["depth"]["rows"]
        fig = Figure(figsize=(10, 3.6))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(1, 2, 1)
        for obj in ("depth", "hull"):
            for az in sorted({r["azimuth_deg"] for r in rows}):
                pts = [(r["slices"], r["flip"]) for r in rows if r["object"] == obj and r["azimuth_deg"] == az]
                _line(ax, pts, "o-" if obj == "depth" else "s--", f"{obj} az {az}°")
        ax.set_xlabel("slices N")
        ax.set_ylabel("FLIP")
        ax.legend(fontsize=7)
        ax = fig.add_subplot(1, 2, 2)
        n = max(r["slices"] for r in rows)
        for obj in ("depth", "hull"):
            pts = [(r["azimuth_deg"], r["flip"]) for r in rows if r["object"] == obj and r["slices"] == n]
            _line(ax, pts, "o-", f"{obj}, N={n}")
        ax.set_xlabel("view azimuth from a cube face (°)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "slicing_depth.png", dpi=110)


PARTS = ("fig10", "tradeoff", "depth")


def write_figures(out, quick: bool = False, which=PARTS, cache_dir=None) -> dict:
    """The parts ``which`` of :data:`PARTS`: ``<out>/slicing_<part>.json`` and the plots."""
    from mi_displace.evaluate.compare import _finite_or_none

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for key, fn in (("fig10", fig10), ("tradeoff", tradeoff), ("depth", depth)):
        if key in which:
            results[key] = fn(quick, cache_dir)
            (out / f"slicing_{key}.json").write_text(json.dumps(_finite_or_none(
                {"command": f"mi-displace figures slicing{' --quick' if quick else ''}",
                 "variant": mi.variant(), **results[key]}), indent=1))
    plot(out, results)
    return results


def add_options(parser) -> None:
    parser.add_argument("--only", choices=PARTS, action="append", default=None,
                        help="only this part (repeatable; default: all)")


def run(args) -> int:
    """``mi-displace figures slicing``: the files of the module docstring under ``args.out``."""
    results = write_figures(args.out, quick=args.quick, which=tuple(args.only or PARTS))
    print(f"wrote {', '.join(f'slicing_{k}.json/.png' for k in results)} under {args.out}")
    return 0
