"""The figures and tables of docs/ddm.md (``mi-displace figures ddm [--quick] [--charts]``).

* ``ddm_accuracy.png``, ``ddm_figures.json`` / ``.md``: HDDM ``maps`` at 32 ... 1024 against
  ``exact`` on the thorns sphere (:func:`mi_displace.ddm.accuracy.geometric_accuracy`), the
  normal methods and the tangent points' epsilon against ``jacobian``;
* ``ddm_sweep.png``: the image trade-off over ``map_resolution`` of
  ``scenes/ddm_thorns_sphere.xml`` (:func:`mi_displace.evaluate.tradeoff.tradeoff`: FLIP and
  warm time per resolution against the path tracer's own curve);
* ``ddm_maps.png``: the paper's Fig. 3 and Fig. 5 (P and N of the teapot body and Spot);
* ``--charts``: only ``ddm_charts.json`` / ``.md``, ``maps`` against ``exact`` on the mesh
  bases of :data:`CHART_BASES`.

``--quick``: three map resolutions, the sweep at 32² and 16 spp, 64² maps.
"""
from __future__ import annotations

import json
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.resources import data_path, scene_path
from mi_displace.ddm import base_maps
from mi_displace.ddm.accuracy import (RESOLUTIONS, THORNS_SPHERE, epsilon_sweep,
                                      geometric_accuracy, normal_methods, to_numpy3)
from mi_displace.ddm.model import DDMConfig, DDMModel
from mi_displace.evaluate import tradeoff


#: the mesh bases of the UV-chart table: Spot (13 charts) and the xatlas genus-1 mesh
CHART_BASES = {
    "spot": dict(base="mesh", filename=str(data_path("spot", "spot_triangulated.obj")),
                 tile="chain", tiles_u=32, tiles_v=32, height=0.03),
    "genus1": dict(base="mesh", filename=str(scene_path("parts", "ddm_genus1", "genus1.obj")),
                   tile="chain", tiles_u=32, tiles_v=32, height=0.05),
}


def chart_accuracy(out_dir, resolutions=RESOLUTIONS) -> dict:
    """``maps`` against ``exact`` on the mesh bases of :data:`CHART_BASES` (chains, 32 x 32
    cells): RMS, max, the largest error of vertices on their own chart, the 99th percentile
    of clamped ones, tile stretch; writes ``ddm_charts.json`` / ``ddm_charts.md``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    record, md = {"variant": mi.variant()}, ""
    for name, kw in CHART_BASES.items():
        model = DDMModel(DDMConfig(mode="exact", **kw))
        rows = geometric_accuracy(DDMConfig(**kw), resolutions)
        record[name] = {"build_stats": model.stats(), "rows": rows}
        st = model.stats()
        md += (f"## {name}: {st['charts']} charts, {st['tiles_placed']} tiles "
               f"({st['tiles_pruned']} pruned, {st['tiles_straddling']} straddling)\n\n")
        md += tradeoff.markdown(rows, [
            ("map_resolution", "resolution", "d"), ("RMS / diag", "rms_error_rel", ".2e"),
            ("max / diag", "max_error_rel", ".2e"), ("unclamped max", "unclamped_max_rel", ".2e"),
            ("clamped p99", "clamped_p99_rel", ".2e"),
            ("tile extent max / median", "tile_extent_max_over_median", ".1f"),
            ("maps bytes", "maps_bytes", ",")]) + "\n"
    (out / "ddm_charts.json").write_text(json.dumps(record, indent=2))
    (out / "ddm_charts.md").write_text(md)
    return record


def _plot_accuracy(rows: list[dict], path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 3.2))
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    r = [x["resolution"] for x in rows]
    ax1.loglog(r, [x["rms_error_rel"] for x in rows], "o-", label="RMS")
    ax1.loglog(r, [x["max_error_rel"] for x in rows], "s-", label="max")
    ax1.set_xlabel("map_resolution")
    ax1.set_ylabel("vertex distance / bbox diagonal")
    ax1.legend()
    ax2.loglog(r, [x["normal_mean_deg"] for x in rows], "o-", label="mean")
    ax2.loglog(r, [x["normal_max_deg"] for x in rows], "s-", label="max")
    ax2.set_xlabel("map_resolution")
    ax2.set_ylabel("normal angle error (deg)")
    ax2.legend()
    fig.suptitle("HDDM maps vs exact DDM (thorns on a sphere)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def plot_geometry_images(path: Path, resolution: int = 256) -> dict:
    """The paper's Fig. 3 and Fig. 5: P (bounding box -> RGB) and N (n / 2 + 1/2) of the
    teapot body and of Spot (invalid texels darkened before, shown filled after §4.1)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from mi_displace.ddm.model import make_base

    spot = str(data_path("spot", "spot_triangulated.obj"))
    fig = Figure(figsize=(9, 4.8))
    FigureCanvasAgg(fig)
    info = {}
    for row, (name, base) in enumerate((("teapot body", make_base("teapot")),
                                        ("Spot", make_base("mesh", spot)))):
        maps = base_maps.build_maps(base, resolution)
        shape = (maps.rv, maps.ru, 3)
        p = to_numpy3(maps.position).reshape(shape)
        n = to_numpy3(maps.normal).reshape(shape)
        p = (p - p.min((0, 1))) / np.maximum(np.ptp(p, (0, 1)), 1e-12)
        shown = [p * np.where(maps.valid, 1.0, 0.25)[..., None], p,
                 (n * 0.5 + 0.5) * np.where(maps.valid, 1.0, 0.25)[..., None], n * 0.5 + 0.5]
        titles = ["P (invalid dark)", "P filled (§4.1)", "N (invalid dark)", "N filled"]
        for col, (img, title) in enumerate(zip(shown, titles)):
            ax = fig.add_subplot(2, 4, row * 4 + col + 1)
            ax.imshow(np.clip(img, 0, 1), origin="lower", interpolation="nearest")
            ax.set_title(f"{name}: {title}", fontsize=7)
            ax.set_axis_off()
        info[name] = maps.stats
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return info


def write_figures(out_dir, quick: bool = False) -> dict:
    """Accuracy table + plot, normal-method table and the map_resolution sweep (module
    docstring)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    res = RESOLUTIONS[:3] if quick else RESOLUTIONS
    acc = geometric_accuracy(DDMConfig(**THORNS_SPHERE), res)
    methods = normal_methods(DDMConfig(**THORNS_SPHERE))
    eps = epsilon_sweep(DDMConfig(**THORNS_SPHERE))
    knob = tradeoff.parse_knob("map_resolution=" + ("16,32,64" if quick else "16,32,64,128,256,512"))
    sweep = tradeoff.tradeoff(scene_path("ddm_thorns_sphere.xml"), [knob],
                              params={"res": "32"} if quick else None,
                              max_spp=16 if quick else 1024)
    _plot_accuracy(acc, out / "ddm_accuracy.png")
    tradeoff.plot(sweep, out / "ddm_sweep.png")
    plot_geometry_images(out / "ddm_maps.png", 64 if quick else 256)
    record = {"accuracy": acc, "normal_methods": methods, "epsilon": eps, "sweep": sweep,
              "variant": mi.variant()}
    (out / "ddm_figures.json").write_text(json.dumps(record, indent=2))
    md = ("## maps vs exact\n\n" + tradeoff.markdown(acc, [
        ("map_resolution", "resolution", "d"), ("RMS / diag", "rms_error_rel", ".3g"),
        ("max / diag", "max_error_rel", ".3g"), ("normal mean (deg)", "normal_mean_deg", ".3g"),
        ("normal max (deg)", "normal_max_deg", ".3g"), ("maps bytes", "maps_bytes", ",")])
        + "\n## normal methods vs jacobian (exact)\n\n" + tradeoff.markdown(methods, [
            ("method", "method", "s"), ("mean (deg)", "mean_deg", ".3g"),
            ("p99 (deg)", "p99_deg", ".3g"), ("max (deg)", "max_deg", ".3g")])
        + "\n## tangent normals against jacobian per epsilon (tile units; maps at 256)\n\n"
        + tradeoff.markdown(eps, [("epsilon", "epsilon", "g"), ("exact mean (deg)", "exact_mean_deg", ".3g"),
                          ("exact max (deg)", "exact_max_deg", ".3g"),
                          ("maps mean (deg)", "maps_mean_deg", ".3g"),
                          ("maps max (deg)", "maps_max_deg", ".3g")])
        + "\n## image sweep (mi-displace tradeoff)\n\n" + tradeoff.markdown(
            [{**r["point"], **r} for r in sweep["points"] if r["ok"]], [
                ("map_resolution", "map_resolution", "s"), ("FLIP", "flip", ".4f"),
                ("warm time (s)", "time_warm_s", ".3f"),
                ("path needs (s)", "path_crossover_s", ".3g")])
        + "\npath reference by spp:\n\n" + tradeoff.markdown(sweep["path_curve"], [
            ("spp", "spp", "d"), ("FLIP", "flip", ".4f"), ("time (s)", "time_s", ".3f")]))
    (out / "ddm_figures.md").write_text(md)
    dr.sync_thread()
    return record


def add_options(parser) -> None:
    parser.add_argument("--charts", action="store_true",
                        help="only the UV-chart table (maps vs exact on Spot and the genus-1 mesh)")


def run(args) -> int:
    """``mi-displace figures ddm``: the files of the module docstring under ``args.out``."""
    if args.charts:
        chart_accuracy(args.out, RESOLUTIONS[:2] if args.quick else RESOLUTIONS)
        print((args.out / "ddm_charts.md").read_text())
        return 0
    record = write_figures(args.out, quick=args.quick)
    for row in record["accuracy"]:
        print(f"R={row['resolution']:5d}  rms/diag {row['rms_error_rel']:.3g}  "
              f"max/diag {row['max_error_rel']:.3g}  normal mean {row['normal_mean_deg']:.3g} deg")
    print(f"wrote {args.out}/ddm_accuracy.png, ddm_sweep.png, ddm_maps.png, ddm_figures.json, "
          "ddm_figures.md")
    return 0
