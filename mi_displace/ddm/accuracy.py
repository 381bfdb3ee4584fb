"""Measured accuracy of HDDM: geometry (``maps`` at R against ``exact``), the three normal
methods, and the image trade-off over ``map_resolution`` against the path tracer's own curve.

* :func:`geometric_accuracy` — the same tiles mapped by DDM (exact S, n; ``jacobian``
  normals as the truth) and by HDDM at each map resolution: RMS and max vertex distance
  relative to the bounding-box diagonal, mean / max normal angle error [degrees].
* :func:`normal_methods` — ``tangent`` / ``naive`` against ``jacobian`` on ``exact``;
  :func:`epsilon_sweep` — the tangent points' ε against the same truth.
* the image sweep over ``map_resolution`` is :func:`mi_displace.evaluate.tradeoff.tradeoff`
  on the comparison scene (FLIP and warm time per resolution, the path tracer's own curve).
* :func:`write_figures` writes the tables (JSON, Markdown) and plots under
  ``docs/figures/ddm_*``; ``mi-displace ddm-figures`` runs it.
"""
from __future__ import annotations

import json
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.resources import data_path, scene_path
from mi_displace.ddm import base_maps, mapping
from mi_displace.ddm import normals as nrm
from mi_displace.ddm.model import DDMConfig, DDMModel
from mi_displace.evaluate import tradeoff

RESOLUTIONS = (32, 64, 128, 256, 512, 1024)
#: the thorns-on-sphere set-up of scenes/ddm_thorns_sphere.xml
THORNS_SPHERE = dict(base="sphere", base_params={"radius": 1.0}, tile="thorn", tiles_u=32,
                     tiles_v=16, height=0.3)


def _np3(v) -> np.ndarray:
    return np.stack([np.asarray(c) for c in v], 1)


def geometric_accuracy(cfg: DDMConfig, resolutions=RESOLUTIONS, method: str | None = None) -> list[dict]:
    """``maps`` at each resolution against ``exact`` on the same placed tiles.

    Returns:
        One dict per resolution: ``resolution``, ``rms_error_rel``, ``max_error_rel``
        (vertex distance / bbox diagonal), ``normal_mean_deg``, ``normal_max_deg``
        (against exact ``jacobian`` normals), ``maps_bytes``.
    """
    cfg.mode = "exact"
    model = DDMModel(cfg)
    p_ref, n_ref, uv = model.map(method="jacobian")
    ref = _np3(p_ref)
    diag = float(np.linalg.norm(ref.max(0) - ref.min(0)))
    clamped = model.clamped_mask(uv)
    rows = []
    for r in resolutions:
        maps = model.maps_at(r)
        p, n, _ = model.map(method=method, evaluator=mapping.MapsEvaluator(maps))
        p = _np3(p)
        d = np.linalg.norm(p - ref, axis=1)
        ang = np.asarray(nrm.angle_error_deg(n, n_ref))
        row = {"resolution": r, "rms_error_rel": float(np.sqrt(np.mean(d * d)) / diag),
               "max_error_rel": float(d.max() / diag), "normal_mean_deg": float(ang.mean()),
               "normal_max_deg": float(ang.max()), "maps_bytes": maps.nbytes, "vertices": len(d)}
        if clamped.any():   # mesh bases: vertices on their chart vs clamped ones
            row.update(unclamped_max_rel=float(d[~clamped].max() / diag),
                       clamped_p99_rel=float(np.percentile(d[clamped], 99) / diag),
                       clamped_fraction=float(clamped.mean()),
                       **_stretch(p, model.buffers.vertex_count))
        rows.append(row)
    return rows


def _stretch(p: np.ndarray, vertex_count: list) -> dict:
    """Largest mapped tile extent (bbox diagonal) over the median, and how many tiles are
    more than 3x the median (one tile kind)."""
    if len(vertex_count) != 1:
        return {}
    extent = np.linalg.norm(np.ptp(p.reshape(-1, vertex_count[0], 3), 1), axis=1)
    med = np.median(extent)
    return {"tile_extent_max_over_median": float(extent.max() / med),
            "tiles_over_3x_median": int((extent > 3 * med).sum())}


#: the mesh bases of the UV-chart table: Spot (13 charts) and the xatlas genus-1 mesh
CHART_BASES = {
    "spot": dict(base="mesh", filename=str(data_path("spot", "spot_triangulated.obj")),
                 tile="chain", tiles_u=32, tiles_v=32, height=0.03),
    "genus1": dict(base="mesh", filename=str(scene_path("parts", "ddm_genus1", "genus1.obj")),
                   tile="chain", tiles_u=32, tiles_v=32, height=0.05),
}


def chart_accuracy(out_dir, resolutions=(32, 64, 128, 256, 512, 1024)) -> dict:
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


def normal_methods(cfg: DDMConfig) -> list[dict]:
    """Angle error [degrees] of each normal method against ``jacobian``, all on ``exact``."""
    cfg.mode = "exact"
    model = DDMModel(cfg)
    _, truth, _ = model.map(method="jacobian")
    rows = []
    for method in nrm.METHODS:
        _, n, _ = model.map(method=method)
        ang = np.asarray(nrm.angle_error_deg(n, truth))
        rows.append({"method": method, "mean_deg": float(ang.mean()),
                     "p99_deg": float(np.percentile(ang, 99)), "max_deg": float(ang.max())})
    return rows


def epsilon_sweep(cfg: DDMConfig, epsilons=(1e-5, 1e-4, 1e-3, 1e-2, 1e-1)) -> list[dict]:
    """Angle error [degrees] of ``tangent`` normals against ``jacobian`` per ε (tile units),
    on ``exact`` and on ``maps`` (at ``cfg.map_resolution``): too small an ε loses float32
    precision after the mapping, too large an ε bends across the tile / map texels."""
    cfg.mode = "exact"
    model = DDMModel(cfg)
    _, truth, _ = model.map(method="jacobian")
    maps = mapping.MapsEvaluator(base_maps.build_maps(model.base, cfg.map_resolution))
    _, truth_maps, _ = model.map(method="jacobian", evaluator=maps)
    rows = []
    for eps in epsilons:
        model.cfg.epsilon = eps
        row = {"epsilon": eps}
        for name, ev, ref in (("exact", None, truth), ("maps", maps, truth_maps)):
            _, n, _ = model.map(method="tangent", evaluator=ev)
            ang = np.asarray(nrm.angle_error_deg(n, ref))
            row[f"{name}_mean_deg"], row[f"{name}_max_deg"] = float(ang.mean()), float(ang.max())
        rows.append(row)
    return rows


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
        p = _np3(maps.position).reshape(shape)
        n = _np3(maps.normal).reshape(shape)
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


def write_figures(out_dir, scene_path, quick: bool = False) -> dict:
    """Accuracy table + plot, normal-method table and the map_resolution sweep."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    res = RESOLUTIONS[:3] if quick else RESOLUTIONS
    acc = geometric_accuracy(DDMConfig(**THORNS_SPHERE), res)
    methods = normal_methods(DDMConfig(**THORNS_SPHERE))
    eps = epsilon_sweep(DDMConfig(**THORNS_SPHERE))
    knob = tradeoff.parse_knob("map_resolution=" + ("16,32,64" if quick else "16,32,64,128,256,512"))
    sweep = tradeoff.tradeoff(scene_path, [knob], max_spp=64 if quick else 1024)
    _plot_accuracy(acc, out / "ddm_accuracy.png")
    tradeoff.plot(sweep, out / "ddm_sweep.png")
    plot_geometry_images(out / "ddm_maps.png")
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
