"""Figures and trade-off sweeps of the VDM docs (``docs/figures/vdm_*``).

``python -m mi_displace.vdm.figures [--out docs/figures] [--quick]`` writes:

* ``vdm_methods_{torus,spot}.png/.json/.md``: reference | bump | horizon | relief | VDM
  (raster), FLIP per method inside the masks (:mod:`mi_displace.vdm.methods`);
* ``vdm_sweep_terms.json``: FLIP against the reference, reconstruction RMSE, compressed
  size and silhouette mismatch for ``svd_terms`` 1...16 (``mvm_terms`` = min(svd_terms,
  4)) and for ``mvm_terms`` 1...16 at ``svd_terms`` 8;
* ``vdm_sweep_sizes.json``: the same against table sizes (res, phi, theta, curvatures
  varied one at a time around the paper's 128, 32, 8, 16), with the build time;
* ``vdm_sweep.png``: both sweeps plotted;
* ``vdm_unseen.json/.md``: the unseen-style scenes (issue 12): every method on
  ``vdm_bricks_grazing`` at 45, 70, 82 and 85 degrees and on ``vdm_corner_normals``.

Every number is measured in this run (raster integrator, torus scene, 256 x 256, 4 x 4
samples per pixel); nothing is drawn by hand.
"""
from __future__ import annotations

import argparse
import gc
import json
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parents[2]
SCENES = {"torus": ROOT / "scenes" / "vdm_torus.xml", "spot": ROOT / "scenes" / "vdm_spot.xml"}


def _save_json(path: Path, data) -> None:
    from mi_displace.evaluate.compare import _finite_or_none

    path.write_text(json.dumps(_finite_or_none(data), indent=2))


def methods_figure(name: str, out: Path, res: int) -> dict:
    """Panel of every method on one scene plus the measured table."""
    from matplotlib.figure import Figure

    from mi_displace.core.io import to_srgb
    from mi_displace.vdm import methods

    result = methods.methods_table(SCENES[name], {"res": str(res)}, repeats=3)
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


UNSEEN = {"grazing": ROOT / "scenes" / "vdm_bricks_grazing.xml",
          "corners": ROOT / "scenes" / "vdm_corner_normals.xml"}
GRAZING_ANGLES = (45, 70, 82, 85)


def unseen(out: Path, res: int) -> list[dict]:
    """Every method on the unseen-style scenes; one Markdown table per scene/angle."""
    from mi_displace.vdm import methods

    cases = [(f"vdm_bricks_grazing, {a} deg", UNSEEN["grazing"], {"angle": str(a)})
             for a in GRAZING_ANGLES] + [("vdm_corner_normals", UNSEEN["corners"], {})]
    records, text = [], []
    for title, path, params in cases:
        result = methods.methods_table(path, dict(params, res=str(res)), repeats=3)
        records.append({"case": title, "rows": result["rows"],
                        "mask_pixels": result["mask_pixels"]})
        text += [f"### {title}", "", methods.markdown(result["rows"]), "",
                 f"Mask pixels: {result['mask_pixels']}", ""]
        gc.collect()
    _save_json(out / "vdm_unseen.json", records)
    (out / "vdm_unseen.md").write_text("\n".join(text))
    return records


def _render_flip(scene, reference) -> tuple[float, float]:
    from mi_displace.evaluate import metrics
    from mi_displace.render import scene as scenes

    scenes.render(scene)  # compile
    image, seconds = scenes.render(scene)
    return metrics.flip(reference, image)[0], seconds


def sweeps(out: Path, res: int, quick: bool) -> dict:
    """svd_terms / mvm_terms and table-size sweeps on the torus."""
    from mi_displace.render import scene as scenes

    path = SCENES["torus"]
    reference, _ = scenes.render(scenes.load(path, mode="reference", integrator="raster",
                                             res=res)[0])
    scene, _ = scenes.load(path, mode="approximation", integrator="raster", res=res)
    bsdf = scene.shapes()[0].bsdf()
    terms = []
    ks = [1, 2, 4, 8, 16] if quick else list(range(1, 17))
    for k in ks:
        for svd, mvm in ((k, min(k, 4)), (8, k)):
            bsdf.rebuild(svd_terms=svd, mvm_terms=mvm)
            flip, seconds = _render_flip(scene, reference)
            rv, rm = bsdf.data.reconstruction_rmse(svd, mvm)
            terms.append({"svd_terms": svd, "mvm_terms": mvm, "flip": flip, "render_s": seconds,
                          "rmse_vdm": rv, "rmse_mvm": rm,
                          "compressed_mb": bsdf.data.compressed.nbytes(svd, mvm) / 1e6,
                          "silhouette_mismatch": bsdf.data.silhouette_mismatch(mvm)})
            gc.collect()
    sizes = []
    base = {"res": 128, "phi": 32, "theta": 8, "curvatures": 16}
    grid = {"res": [32, 64, 128], "phi": [8, 16, 32], "theta": [4, 8, 16],
            "curvatures": [4, 8, 16]}
    if quick:
        grid = {"res": [32, 128], "phi": [8], "theta": [4], "curvatures": [4]}
    for key, values in grid.items():
        for v in values:
            cfg = dict(base, **{key: v})
            start = time.perf_counter()
            bsdf.rebuild(svd_terms=8, mvm_terms=4, use_cache=False, **cfg)
            build_s = time.perf_counter() - start
            flip, seconds = _render_flip(scene, reference)
            sizes.append(dict(cfg, varied=key, flip=flip, render_s=seconds, build_s=build_s,
                              table_mb=bsdf.data.table_bytes() / 1e6,
                              compressed_mb=bsdf.data.compressed.nbytes(8, 4) / 1e6,
                              rmse_vdm=bsdf.data.reconstruction_rmse(8, 4)[0],
                              silhouette_mismatch=bsdf.data.silhouette_mismatch(4)))
            gc.collect()
    _save_json(out / "vdm_sweep_terms.json", terms)
    _save_json(out / "vdm_sweep_sizes.json", sizes)
    _plot_sweeps(out, terms, sizes)
    return {"terms": terms, "sizes": sizes}


def _plot_sweeps(out: Path, terms: list[dict], sizes: list[dict]) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 3.6))
    ax = fig.add_subplot(1, 3, 1)
    a = [t for t in terms if t["mvm_terms"] == min(t["svd_terms"], 4)]
    b = [t for t in terms if t["svd_terms"] == 8]
    ax.plot([t["svd_terms"] for t in a], [t["flip"] for t in a], "o-", label="svd_terms (mvm = min(k, 4))")
    ax.plot([t["mvm_terms"] for t in b], [t["flip"] for t in b], "s--", label="mvm_terms (svd = 8)")
    ax.set_xlabel("terms")
    ax.set_ylabel("FLIP vs true displacement")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 3, 2)
    ax.semilogy([t["svd_terms"] for t in a], [t["rmse_vdm"] for t in a], "o-", label="VDM RMSE [tile]")
    ax.semilogy([t["mvm_terms"] for t in b], [t["rmse_mvm"] for t in b], "s--", label="MVM RMSE [rad]")
    ax.semilogy([t["mvm_terms"] for t in b], [max(t["silhouette_mismatch"], 1e-6) for t in b], "^:",
                label="silhouette mismatch")
    ax.set_xlabel("terms")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 3, 3)
    for key in ("res", "phi", "theta", "curvatures"):
        rows = [s for s in sizes if s["varied"] == key]
        ax.plot([s["table_mb"] for s in rows], [s["flip"] for s in rows], "o-", label=key)
        for s in rows:
            ax.annotate(str(s[key]), (s["table_mb"], s["flip"]), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("full table size (MB, float32)")
    ax.set_ylabel("FLIP")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "vdm_sweep.png", dpi=110)


def main(argv=None) -> int:
    import mi_displace

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "figures"))
    parser.add_argument("--res", type=int, default=256)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--only", choices=("methods", "sweeps", "unseen"), default=None)
    args = parser.parse_args(argv)
    mi_displace.init()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.only in (None, "methods"):
        for name in SCENES:
            methods_figure(name, out, args.res)
            gc.collect()
    if args.only in (None, "unseen"):
        unseen(out, args.res)
    if args.only in (None, "sweeps"):
        sweeps(out, args.res, args.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
