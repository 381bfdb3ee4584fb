"""``mi-displace bench denoise [--json] [--quick] [--out DIR]``: each showcase approximation
against path tracing, raw and denoised, in the same run.

For every scene marked ``<!-- showcase -->`` (:func:`mi_displace.core.cli_args.showcase_scenes`
over the packaged scenes) this runs the comparison protocol with the denoiser
(:func:`mi_displace.evaluate.compare.compare` with ``denoise``): the approximation's FLIP and
warm time, a converged reference, and the reference integrator's own curve at 1, 2, 4, ...
spp, raw and denoised by Open Image Denoise (build, render, AOV render and denoiser all
counted in a curve point's time).  Per scene (``rows``):

* ``approx_flip``, ``approx_time_s``: the approximation's mean FLIP and warm time per frame
  (build + render, seconds); ``approx_render_s``: its warm render alone;
* ``raw`` and ``denoised``, one dict per curve:

  - ``crossover_spp`` / ``crossover_s``: the spp and seconds at which that curve reaches the
    approximation's FLIP (log-log interpolation, :func:`mi_displace.evaluate.tradeoff.crossover`;
    ``null``: not within the curve), and ``time_ratio`` = ``crossover_s / approx_time_s``
    (how many times the approximation's time the path tracer needs for the same error);
  - ``flip_at_equal_time``: the lowest FLIP of the curve's points no slower than the
    approximation (:func:`mi_displace.evaluate.atlas.path_flip_at`; ``null``: even its
    1-spp point, whose time includes the true geometry's build, is slower);
    ``flip_at_equal_render_time``: the same with both builds left out (the curve point's
    render, AOV render and denoiser against the approximation's warm render: a scene built
    once and drawn many times);
    ``first_point``: that 1-spp point (``spp``, ``time_s``, ``flip``);
  - ``verdict``: :func:`mi_displace.evaluate.tradeoff.crossover_verdict`'s sentence;

* ``reference_spp``, ``noise_floor_flip``, ``width``, ``height``.

``--quick`` runs :data:`QUICK` (two scenes at 32² pixels, references capped at 16 spp, the
denoiser's ``fast`` quality): the same code paths in seconds, numbers not comparable.
``--out DIR`` also writes ``denoise_bench.json`` and each scene's ``compare`` outputs
(``DIR/<scene>/panel.png``, ``metrics.json``) there.
"""
from __future__ import annotations

import json as _json
from pathlib import Path
from typing import NamedTuple

from mi_displace.bench._timing import output_dir


class Sizes(NamedTuple):
    """A run: ``scenes`` (showcase scene names, ``None``: all of them), ``res`` (film side
    in pixels passed as ``-D res=``; ``None``: each scene's own), ``max_spp`` (reference cap)
    and ``quality`` (OIDN quality)."""
    scenes: tuple[str, ...] | None
    res: int | None
    max_spp: int
    quality: str


FULL = Sizes(None, None, 1024, "high")
QUICK = Sizes(("ddm_genus1", "volume_nucleon_pull"), 32, 16, "fast")


def _curve_summary(info: dict, name: str) -> dict:
    """The ``raw`` / ``denoised`` entry of a row from ``compare``'s metrics (``name`` is
    ``path`` or ``denoised``)."""
    from mi_displace.evaluate.atlas import path_flip_at

    curve = info["path_curve" if name == "path" else "denoised_curve"]
    seconds = info[f"{name}_crossover_s"]
    first = curve[0]
    renders = [{"time_s": p["render_s"] + p.get("denoise_s", 0.0), "flip": p["flip"]}
               for p in curve]
    return {"crossover_spp": info[f"{name}_crossover_spp"], "crossover_s": seconds,
            "time_ratio": None if seconds is None else seconds / info["approx_time_warm_s"],
            "flip_at_equal_time": path_flip_at(curve, info["approx_time_warm_s"]),
            "flip_at_equal_render_time": path_flip_at(renders, info["approx_render_warm_s"]),
            "first_point": {k: first[k] for k in ("spp", "time_s", "flip")},
            "verdict": info[f"{name}_verdict"]}


def scene_row(scene, out_dir: Path, sizes: Sizes) -> dict:
    """One showcase scene through :func:`compare` with the denoiser: its row (module
    docstring)."""
    from mi_displace.evaluate.compare import compare

    params = {"res": str(sizes.res)} if sizes.res is not None else None
    info = compare(scene, out_dir, params=params, max_spp=sizes.max_spp,
                   denoise=sizes.quality)
    return row(Path(scene).stem, info)


def row(name: str, info: dict) -> dict:
    """A scene's row from its comparison's metrics (``compare``'s result or the
    ``metrics.json`` it wrote)."""
    return {"scene": name, "approx_flip": info["flip_mean"],
            "approx_time_s": info["approx_time_warm_s"],
            "approx_render_s": info["approx_render_warm_s"],
            "raw": _curve_summary(info, "path"), "denoised": _curve_summary(info, "denoised"),
            "reference_spp": info["reference_spp"], "noise_floor_flip": info["noise_floor_flip"],
            "width": info["width"], "height": info["height"]}


def run(sizes: Sizes = FULL, out=None) -> dict:
    """Every scene of ``sizes`` (module docstring); ``out``: folder for the compare outputs
    (default: :func:`mi_displace.bench._timing.output_dir`)."""
    import mitsuba as mi

    from mi_displace.core.cli_args import showcase_scenes
    from mi_displace.core.resources import scenes_dir

    folder = output_dir("denoise", out)
    scenes = showcase_scenes(scenes_dir())
    if sizes.scenes is not None:
        scenes = [p for p in scenes if p.stem in sizes.scenes]
    rows = [scene_row(p, folder / p.stem, sizes) for p in scenes]
    return {"variant": mi.variant(), "quality": sizes.quality, "max_spp": sizes.max_spp,
            "res": sizes.res, "rows": rows}


def markdown(record: dict) -> str:
    """The record as a Markdown table (one row per scene)."""
    def num(value, spec=".3g"):
        return "–" if value is None else format(value, spec)

    lines = ["| scene | approx. FLIP | approx. time, render (s) | path: spp, s to match | "
             "denoised: spp, s to match | denoised path at equal time: FLIP | "
             "at equal render time: path, denoised FLIP |", "|" + "---|" * 7]
    for r in record["rows"]:
        raw, den = r["raw"], r["denoised"]
        lines.append(
            f"| {r['scene']} | {num(r['approx_flip'], '.4f')} | {num(r['approx_time_s'])}, "
            f"{num(r['approx_render_s'])} | {num(raw['crossover_spp'])}, "
            f"{num(raw['crossover_s'])} | {num(den['crossover_spp'])}, "
            f"{num(den['crossover_s'])} | {num(den['flip_at_equal_time'], '.4f')} | "
            f"{num(raw['flip_at_equal_render_time'], '.4f')}, "
            f"{num(den['flip_at_equal_render_time'], '.4f')} |")
    return "\n".join(lines) + "\n"


def main(json: bool = False, quick: bool = False, out=None) -> dict:
    """Run every scene (:data:`QUICK` with ``quick``); print JSON (``json``) or the Markdown
    table; with ``out`` also write ``denoise_bench.json`` there."""
    from mi_displace.evaluate.compare import _finite_or_none

    record = _finite_or_none(run(QUICK if quick else FULL, out))
    if out is not None:
        (output_dir("denoise", out) / "denoise_bench.json").write_text(
            _json.dumps(record, indent=2) + "\n")
    print(_json.dumps(record, indent=2) if json else markdown(record))
    return record
