"""Figures and trade-off sweeps of the VDM docs (``docs/figures/vdm_*``).

``mi-displace figures vdm [--out docs/figures] [--quick] [--res N] [--only PART]`` writes:

* ``vdm_methods_{torus,spot}.png/.json/.md``: reference | bump | horizon | relief | VDM
  (raster), FLIP per method inside the masks (:func:`mi_displace.vdm.methods.methods_table`,
  the paper's Table 1 with its shadow / occlusion / silhouette masks);
* ``vdm_sweep_terms.json``: FLIP against the reference, reconstruction RMSE, compressed
  size and silhouette mismatch for ``svd_terms`` (``mvm_terms`` = min(svd_terms, 4)) and
  for ``mvm_terms`` at ``svd_terms`` 8;
* ``vdm_sweep_sizes.json``: the same against table sizes (res, phi, theta, curvatures
  varied one at a time around the paper's 128, 32, 8, 16), with the cold build time;
* ``vdm_sweep_tradeoff.json`` and ``vdm_sweep.png``: both sweeps are one
  :func:`mi_displace.evaluate.tradeoff.tradeoff` over explicit points (the table's own
  errors per point from :func:`table_errors`, its ``inspect``); the plot is tradeoff's
  error-vs-time panel beside the errors against terms and table size;
* ``vdm_unseen.json/.md``: the unseen-style scenes (issue 12): every method on
  ``vdm_bricks_grazing`` at 45, 70, 82 and 85 degrees and on ``vdm_corner_normals``.

The reference of every number is true displacement under the same raster integrator (256²,
4 × 4 samples per pixel); nothing is drawn by hand.  The cold build time of a table size is
a build from scratch only when the VDM table cache (``$MI_DISPLACE_CACHE/vdm``) is empty.
``--quick``: 32² images, 16³-texel tables (``vdm_res`` 16), one timed render per method, the
reduced sweeps of :func:`sweep_points`.
"""
from __future__ import annotations

import gc
import json
from pathlib import Path

from mi_displace.core.resources import scene_path

SCENES = {"torus": scene_path("vdm_torus.xml"), "spot": scene_path("vdm_spot.xml")}


def _save_json(path: Path, data) -> None:
    from mi_displace.evaluate.compare import _finite_or_none

    path.write_text(json.dumps(_finite_or_none(data), indent=2))


#: the scene parameters of ``--quick`` (besides the image size): small VDM tables
QUICK_PARAMS = {"vdm_res": "16"}


def methods_figure(name: str, out: Path, res: int, quick: bool = False) -> dict:
    """Panel of every method on one scene plus the measured table."""
    from matplotlib.figure import Figure

    from mi_displace.core.io import to_srgb
    from mi_displace.vdm import methods

    params = dict(QUICK_PARAMS if quick else {}, res=str(res))
    result = methods.methods_table(SCENES[name], params, repeats=1 if quick else 3)
    rows = {r["method"]: r for r in result["rows"]}
    order = ["reference", "bump", "horizon", "relief", "approximation"]
    fig = Figure(figsize=(3 * len(order), 3.4))
    for i, mode in enumerate(order):
        ax = fig.add_subplot(1, len(order), i + 1)
        ax.imshow(to_srgb(result["images"][mode]))
        r = rows[mode]
        ax.set_title(f"{methods.LABELS[mode]}\nFLIP {r['flip']:.3f}, sil. "
                     f"{(r['flip_silhouette'] or 0):.3f}", fontsize=8)
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(out / f"vdm_methods_{name}.png", dpi=110)
    _save_json(out / f"vdm_methods_{name}.json", {"rows": result["rows"],
                                                  "mask_pixels": result["mask_pixels"]})
    (out / f"vdm_methods_{name}.md").write_text(methods.markdown(result["rows"]) + "\n")
    return result


UNSEEN = {"grazing": scene_path("vdm_bricks_grazing.xml"),
          "corners": scene_path("vdm_corner_normals.xml")}
GRAZING_ANGLES = (45, 70, 82, 85)


def unseen(out: Path, res: int, quick: bool = False) -> list[dict]:
    """Every method on the unseen-style scenes; one Markdown table per scene/angle."""
    from mi_displace.vdm import methods

    cases = [(f"vdm_bricks_grazing, {a} deg", UNSEEN["grazing"], {"angle": str(a)})
             for a in GRAZING_ANGLES] + [("vdm_corner_normals", UNSEEN["corners"], {})]
    records, text = [], []
    for title, path, params in cases:
        result = methods.methods_table(path, dict(params, **(QUICK_PARAMS if quick else {}),
                                                  res=str(res)), repeats=1 if quick else 3)
        records.append({"case": title, "rows": result["rows"],
                        "mask_pixels": result["mask_pixels"]})
        text += [f"### {title}", "", methods.markdown(result["rows"]), "",
                 f"Mask pixels: {result['mask_pixels']}", ""]
        gc.collect()
    _save_json(out / "vdm_unseen.json", records)
    (out / "vdm_unseen.md").write_text("\n".join(text))
    return records


#: ``svd_terms`` (with ``mvm_terms`` = min(k, 4)) and ``mvm_terms`` (with ``svd_terms`` 8)
SVD_TERMS, MVM_TERMS = (1, 2, 4, 8, 12, 16), (1, 2, 4, 8, 16)
#: the paper's table sizes (the scene's defaults) and the values varied one at a time
TABLE_BASE = {"vdm_res": 128, "vdm_phi": 32, "vdm_theta": 8, "vdm_curvatures": 16}
TABLE_GRID = {"vdm_res": (32, 64, 128), "vdm_phi": (8, 16, 32), "vdm_theta": (4, 8, 16),
              "vdm_curvatures": (4, 8, 16)}


def table_errors(scene) -> dict:
    """The VDM table of the scene's first shape at its term counts (a :func:`tradeoff`
    ``inspect``): reconstruction RMSE of the VDM [tile units] and MVM [rad], compressed and
    full table size [MB], fraction of silhouette decisions the compression flips."""
    bsdf = scene.shapes()[0].bsdf()
    data, svd, mvm = bsdf.data, bsdf.svd_terms, bsdf.mvm_terms
    rmse_vdm, rmse_mvm = data.reconstruction_rmse(svd, mvm)
    return {"rmse_vdm": rmse_vdm, "rmse_mvm": rmse_mvm,
            "compressed_mb": data.compressed.nbytes(svd, mvm) / 1e6,
            "table_mb": data.table_bytes() / 1e6,
            "silhouette_mismatch": data.silhouette_mismatch(mvm)}


def sweep_points(quick: bool) -> tuple[list[dict], list[tuple[str, int, dict]]]:
    """The term points, and ``(size, value, point)`` for every table size varied one at a
    time (the paper's sizes at 8 + 4 terms being the shared point
    ``{"svd_terms": 8, "mvm_terms": 4}``)."""
    svd, mvm = ((1, 4, 8), (1, 4, 8)) if quick else (SVD_TERMS, MVM_TERMS)
    terms = [{"svd_terms": k, "mvm_terms": min(k, 4)} for k in svd]
    terms += [p for p in ({"svd_terms": 8, "mvm_terms": k} for k in mvm) if p not in terms]
    grid = {"vdm_res": (32, 128), "vdm_theta": (4, 8)} if quick else TABLE_GRID
    base = {"svd_terms": 8, "mvm_terms": 4}
    sizes = [(key, v, base if v == TABLE_BASE[key] else {key: v})
             for key, values in grid.items() for v in values]
    return terms, sizes


def sweeps(out: Path, res: int, quick: bool, cache_dir=None) -> dict:
    """svd_terms / mvm_terms and table-size sweeps on the torus: one :func:`tradeoff` over
    explicit points, the reference being true displacement under the same ``raster``
    (deterministic: no noise floor, no path curve); :func:`table_errors` per point."""
    from mi_displace.evaluate import tradeoff as tr

    terms, sizes = sweep_points(quick)
    points = terms + [p for _, _, p in sizes if p not in terms]
    result = tr.tradeoff(SCENES["torus"], None, points=points, cache_dir=cache_dir,
                         params={"res": str(res), "reference_integrator": "raster"},
                         max_spp=2, path_spps=[], inspect=table_errors)
    rows = {r["label"]: r for r in tr.table_rows(result)}

    def row(point, **extra):
        r = rows[tr.point_label(point)]
        return {**{k: r[k] for k in ("flip", "time_warm_s", "render_warm_s", "build_s",
                                     "build_cold_s", "rmse_vdm", "rmse_mvm", "compressed_mb",
                                     "table_mb", "silhouette_mismatch")}, **extra}

    term_rows = [row(p, svd_terms=p["svd_terms"], mvm_terms=p["mvm_terms"]) for p in terms]
    size_rows = [row(p, **{**TABLE_BASE, key: v}, varied=key) for key, v, p in sizes]
    _save_json(out / "vdm_sweep_terms.json", term_rows)
    _save_json(out / "vdm_sweep_sizes.json", size_rows)
    _save_json(out / "vdm_sweep_tradeoff.json", result)
    _plot_sweeps(out, result, term_rows, size_rows)
    return {"terms": term_rows, "sizes": size_rows, "tradeoff": result}


def _plot_sweeps(out: Path, result: dict, terms: list[dict], sizes: list[dict]) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from mi_displace.evaluate import tradeoff as tr

    fig = Figure(figsize=(15, 4.2))
    FigureCanvasAgg(fig)
    tr.plot(result, ax=fig.add_subplot(1, 3, 1), title="VDM on the torus: error vs time")
    ax = fig.add_subplot(1, 3, 2)
    a = [t for t in terms if t["mvm_terms"] == min(t["svd_terms"], 4)]
    b = sorted((t for t in terms if t["svd_terms"] == 8), key=lambda t: t["mvm_terms"])
    ax.plot([t["svd_terms"] for t in a], [t["flip"] for t in a], "o-", label="FLIP, svd_terms (mvm = min(k, 4))")
    ax.plot([t["mvm_terms"] for t in b], [t["flip"] for t in b], "s--", label="FLIP, mvm_terms (svd = 8)")
    ax.semilogy([t["svd_terms"] for t in a], [t["rmse_vdm"] for t in a], "o:", label="VDM RMSE [tile]")
    ax.semilogy([t["mvm_terms"] for t in b], [t["rmse_mvm"] for t in b], "s:", label="MVM RMSE [rad]")
    ax.semilogy([t["mvm_terms"] for t in b], [max(t["silhouette_mismatch"], 1e-6) for t in b], "^:",
                label="silhouette mismatch")
    ax.set_xlabel("terms")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 3, 3)
    for key in TABLE_GRID:
        rows = [s for s in sizes if s["varied"] == key]
        if rows:
            ax.plot([s["table_mb"] for s in rows], [s["flip"] for s in rows], "o-", label=key)
        for s in rows:
            ax.annotate(str(s[key]), (s["table_mb"], s["flip"]), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("full table size (MB, float32)")
    ax.set_ylabel("FLIP")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "vdm_sweep.png", dpi=110)


PARTS = ("methods", "unseen", "sweeps")


def add_options(parser) -> None:
    parser.add_argument("--res", type=int, default=None,
                        help="image size (default 256, 32 with --quick)")
    parser.add_argument("--only", choices=PARTS, action="append", default=None,
                        help="only this part (repeatable; default: all)")


def run(args) -> int:
    """``mi-displace figures vdm``: the files of the module docstring under ``args.out``."""
    res = args.res or (32 if args.quick else 256)
    if res < 8:
        raise ValueError(f"--res: must be at least 8, got {res}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    parts = args.only or PARTS
    if "methods" in parts:
        for name in SCENES:
            methods_figure(name, out, res, args.quick)
            gc.collect()
    if "unseen" in parts:
        unseen(out, res, args.quick)
    if "sweeps" in parts:
        sweeps(out, res, args.quick)
    print(f"wrote the VDM {', '.join(parts)} files under {out}")
    return 0
