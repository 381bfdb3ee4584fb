"""The comparison protocol: one scene, rendered as reference and as approximation.

Scene convention
----------------
Every comparison scene is one XML file that renders both ways.  At its top level it declares::

    <default name="mode" value="reference"/>        <!-- or "approximation" -->
    <default name="integrator" value="path"/>
    <default name="spp" value="64"/>                 <!-- reference samples per pixel -->

and uses ``$mode`` to switch the geometry (``<include filename="parts/ball_$mode.xml"/>``
or a technique plugin's ``<string name="mode" value="$mode"/>``), ``$integrator`` in
``<integrator type="$integrator">`` and ``$spp`` in the sampler's ``sample_count``.  Camera,
lights and materials are shared.  Mitsuba refuses a ``$name`` parameter that the scene does
not use, so ``mode`` and ``integrator`` must both be used.

Optional top-level defaults that only :func:`compare` reads (they are not passed to Mitsuba,
so the scene need not use them; ``params`` may override them too):

* ``reference_integrator`` (default ``path``) and ``approximation_integrator`` (default
  ``raster``): the integrator plugin type of each side;
* ``approximation_spp``: spp of the approximation render (default: the scene's sampler count;
  the raster integrator takes one sample at each pixel centre anyway).

A scene is part of the showcase (``mi-displace showcase``) when it contains the comment
``<!-- showcase -->``.

Procedure
---------
1. **Approximation**, ``mode=approximation``: load + render once *cold* (first call in this
   process: tracing and JIT compilation included, though Dr.Jit's on-disk kernel cache may
   shorten it), then ``warm_repeats`` (>= 3) more load + render rounds; warm times are medians.
2. **Reference**, ``mode=reference``: loaded once cold (discarded) and once warm; one 1-spp
   warm-up render compiles its kernels.  Two independent images (seed streams 0 and 1) are
   rendered with ``spp`` each.  The *noise floor* is FLIP(image 0, image 1); the reference is
   their average (``2 * spp`` samples), and the error is FLIP(reference, approximation).
   While ``noise_floor > target_ratio * flip_mean`` both images get as many new samples
   again (fresh seeds, so spp doubles each round) until that holds or the reference would
   exceed ``max_spp`` samples in total, which sets ``spp_capped``.  The noise floor is thus
   measured between two half-budget images: it overestimates the final reference's noise.
3. Metrics against the averaged reference: FLIP (LDR sRGB), relMSE (HDR), PSNR, SSIM.
   ``converged`` says the noise-floor ratio was met; ``within_noise_floor`` says the error is
   no larger than the noise floor, which is what a consistency scene (DESIGN protocol item 4:
   raster on the reference geometry) must show — such a scene never "converges" and runs to
   ``max_spp``.
4. Optionally (``denoise``): the reference integrator's own curve at 1, 2, 4, ... spp, raw
   and denoised by Open Image Denoise (:mod:`mi_displace.render.denoise`), and the time at
   which each reaches the approximation's FLIP.

Times are wall seconds in this process.  ``reference_time_s`` = warm build + every render
that went into the final reference image; ``approx_time_warm_s`` = median over the warm rounds
of (build + render); ``speedup = reference_time_s / approx_time_warm_s``, both end to end.

Outputs in ``out_dir``: ``reference.exr``, ``approximation.exr`` (linear float32),
``panel.png`` (reference | approximation | FLIP heat map) and ``metrics.json``
(:data:`METRIC_KEYS` and more; a non-finite float such as the PSNR of identical images is
written as ``null``).  ``warnings`` lists every ``build_stats["warnings"]`` entry of either
side's shapes (for instance a displacement deeper than a thin shell's wall).
"""
from __future__ import annotations

import json
import math
import statistics
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.io import to_srgb, write_exr
from mi_displace.core.progress import stage
from mi_displace.evaluate import metrics
from mi_displace.render import denoise as dn
from mi_displace.render import scene as scenes

#: XML parameters set by the protocol itself; ``params`` may not set them.
RESERVED_PARAMS = ("mode", "integrator")
#: Top-level defaults (or params) read by :func:`compare` and not passed to Mitsuba.
PROTOCOL_PARAMS = ("reference_integrator", "approximation_integrator", "approximation_spp")
DEFAULT_INTEGRATORS = {"reference": "path", "approximation": "raster"}

#: Keys always present in ``metrics.json`` and in the dict :func:`compare` returns.
METRIC_KEYS = (
    "scene", "params", "variant", "width", "height",
    "flip_mean", "relmse", "psnr", "ssim", "noise_floor_flip", "target_ratio", "converged",
    "within_noise_floor",
    "reference_spp", "max_spp", "spp_capped", "reference_rounds",
    "reference_integrator", "approximation_integrator", "approximation_spp",
    "reference_time_s", "reference_build_s", "reference_render_s",
    "reference_build_cold_s", "reference_render_cold_s",
    "approx_time_cold_s", "approx_build_cold_s", "approx_render_cold_s",
    "approx_time_warm_s", "approx_build_s", "approx_render_warm_s", "warm_repeats",
    "speedup", "build_stats", "warnings", "mitsuba_version", "drjit_version",
)


def scene_defaults(path: str | Path) -> dict[str, str]:
    """The ``<default name=... value=...>`` declarations at the top level of a scene file.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: the file is not well-formed XML.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        raise ValueError(f"scene file {str(path)!r} is not valid XML: {e}") from None
    return {
        d.get("name"): d.get("value", "") for d in root.findall("default") if d.get("name")
    }


def protocol_settings(scene_path: str | Path, params: dict | None = None) -> dict:
    """Check a scene against the convention and split ``params`` for the two sides.

    Returns:
        dict with ``xml_params`` (passed to Mitsuba on both sides), ``reference_integrator``,
        ``approximation_integrator`` and ``approximation_spp`` (int or ``None``).

    Raises:
        FileNotFoundError, ValueError: missing file, convention not followed, bad params.
    """
    defaults = scene_defaults(scene_path)
    missing = [name for name in RESERVED_PARAMS if name not in defaults]
    if missing:
        raise ValueError(
            f"scene {str(scene_path)!r} does not follow the comparison convention: it must "
            f"declare <default name=...> for {', '.join(missing)} (see mi_displace.evaluate.compare)"
        )
    params = scenes.check_params(params)
    reserved = [name for name in RESERVED_PARAMS if name in params]
    if reserved:
        raise ValueError(f"params: {', '.join(reserved)} is set by the comparison protocol itself")
    settings = {**{k: v for k, v in defaults.items() if k in PROTOCOL_PARAMS},
                **{k: v for k, v in params.items() if k in PROTOCOL_PARAMS}}
    approximation_spp = settings.get("approximation_spp")
    if approximation_spp is not None:
        if not approximation_spp.isdigit() or int(approximation_spp) < 1:
            raise ValueError(f"approximation_spp: expected a positive integer, got {approximation_spp!r}")
        approximation_spp = int(approximation_spp)
    return {
        "xml_params": {k: v for k, v in params.items() if k not in PROTOCOL_PARAMS},
        "reference_integrator": settings.get("reference_integrator", DEFAULT_INTEGRATORS["reference"]),
        "approximation_integrator": settings.get(
            "approximation_integrator", DEFAULT_INTEGRATORS["approximation"]),
        "approximation_spp": approximation_spp,
    }


def _finite_or_none(value):
    """JSON-friendly value: NumPy scalars to Python, non-finite floats to ``None``."""
    if isinstance(value, dict):
        return {str(k): _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_panel(path: str | Path, reference, approximation, error_map, info: dict) -> Path:
    """Save the PNG panel: reference | approximation | FLIP heat map (magma, 0..1).

    Args:
        path: output PNG.
        reference, approximation: linear RGB ``(H, W, 3)`` (shown sRGB-encoded, clipped).
        error_map: FLIP error ``(H, W)`` in ``[0, 1]``.
        info: the metrics dict (titles use its numbers).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    height, width = error_map.shape
    panel_w = min(4.0, 5.0 * width / height)  # inches; tall images get narrower panels
    panel_h = panel_w * height / width
    gap, left, top, bottom, bar_w, bar_labels = 0.1, 0.1, 0.85, 0.1, 0.15, 0.5
    fig_w = left + 3 * panel_w + 3 * gap + bar_w + bar_labels
    fig_h = bottom + panel_h + top
    fig = Figure(figsize=(fig_w, fig_h))
    FigureCanvasAgg(fig)
    axes = [
        fig.add_axes([(left + i * (panel_w + gap)) / fig_w, bottom / fig_h,
                      panel_w / fig_w, panel_h / fig_h])
        for i in range(3)
    ]
    bar_ax = fig.add_axes([(left + 3 * panel_w + 3 * gap) / fig_w, bottom / fig_h,
                           bar_w / fig_w, panel_h / fig_h])
    capped = " (capped)" if info["spp_capped"] else ""
    titles = [
        f"reference: {info['reference_integrator']}, {info['reference_spp']} spp{capped}\n"
        f"{info['reference_time_s']:.3g} s",
        f"approximation: {info['approximation_integrator']}\n"
        f"{info['approx_time_warm_s']:.3g} s warm, {info['approx_time_cold_s']:.3g} s cold",
        f"FLIP {info['flip_mean']:.4f}\nnoise floor {info['noise_floor_flip']:.4f}",
    ]
    for ax, image, title in zip(axes[:2], (reference, approximation), titles):
        ax.imshow(to_srgb(image), interpolation="nearest")
        ax.set_title(title, fontsize=9)
    heat = axes[2].imshow(error_map, cmap="magma", vmin=0.0, vmax=1.0, interpolation="nearest")
    axes[2].set_title(titles[2], fontsize=9)
    for ax in axes:
        ax.set_axis_off()
    fig.colorbar(heat, cax=bar_ax)
    psnr = "inf" if info["psnr"] is None or not math.isfinite(info["psnr"]) else f"{info['psnr']:.2f}"
    fig.suptitle(
        f"{Path(info['scene']).name}: relMSE {info['relmse']:.4g} · PSNR {psnr} dB · "
        f"SSIM {info['ssim']:.4f} · speed-up {info['speedup']:.3g}×",
        fontsize=10, y=1 - 0.08 / fig_h, va="top",
    )
    path = Path(path)
    fig.savefig(path, dpi=max(100, min(300, width / panel_w)))
    return path


def _render_side(path, xml_params, mode, integrator, spp, edits=None,
                 inspect=None) -> tuple[dict, np.ndarray, float]:
    """Load the scene for one side, apply ``edits`` and render it once (seed 0).

    Returns ``(timings, image, seconds)``; ``timings["build_s"]`` includes the edits'
    ``params.update()``, ``timings["inspected"]`` is ``inspect(scene)`` when ``inspect`` is
    given.  The scene is released before returning, so consecutive calls never hold two scenes.
    """
    scene, timings = scenes.load(path, **xml_params, mode=mode, integrator=integrator)
    if edits:
        start = time.perf_counter()
        scenes.apply_edits(scene, edits)
        timings["build_s"] += time.perf_counter() - start
    image, seconds = scenes.render(scene, spp=spp, seed=0)
    metrics.assert_finite(image, f"{mode} image of {path}")
    if inspect is not None:
        timings["inspected"] = inspect(scene)
    return timings, image, seconds


def measure_approximation(scene_path, xml_params: dict, integrator: str, spp: int | None,
                          warm_repeats: int = 3, mode: str = "approximation",
                          edits: dict | None = None, progress: bool | None = False,
                          inspect=None) -> dict:
    """Step 1 of the protocol: the approximation rendered cold, then ``warm_repeats`` times.

    Args:
        scene_path: scene XML following the convention.
        xml_params: XML parameters (not ``mode`` / ``integrator``).
        integrator: the approximation's integrator plugin type.
        spp: samples per pixel (``None``: the scene's).
        warm_repeats: warm load + render rounds (the warm times are their medians).
        mode: the ``$mode`` to render (``approximation``, or another part of the scene).
        edits: ``mi.traverse`` parameters set after each load (see ``scene.apply_edits``).
        progress: a line per stage (:mod:`mi_displace.core.progress`; ``None``: on a terminal).
        inspect: ``inspect(scene) -> dict`` called on the loaded scene of the last warm round
            (after its render): measurements of the scene itself (table errors, normals, ...).

    Returns:
        dict with ``image`` (linear float32 ``(H, W, 3)``, the last warm round),
        ``time_cold_s``, ``build_cold_s``, ``render_cold_s``, ``time_warm_s`` (median of
        build + render), ``build_s``, ``render_warm_s`` (medians), ``build_stats`` and
        ``inspected`` (``inspect``'s dict, or ``None``).
    """
    name = Path(scene_path).name
    with stage(f"{name}: {mode} ({integrator}), cold", progress) as s:
        cold, image, render_cold = _render_side(scene_path, xml_params, mode, integrator, spp,
                                                edits)
        s.note = f"build {cold['build_s']:.2f} s, render {render_cold:.2f} s"
    builds, renders = [], []
    with stage(f"{name}: {mode}, {warm_repeats} warm rounds", progress):
        for i in range(warm_repeats):
            warm, image, seconds = _render_side(scene_path, xml_params, mode, integrator, spp,
                                                edits, inspect if i == warm_repeats - 1 else None)
            builds.append(warm["build_s"])
            renders.append(seconds)
    return {
        "image": image,
        "time_cold_s": cold["build_s"] + render_cold,
        "build_cold_s": cold["build_s"],
        "render_cold_s": render_cold,
        "time_warm_s": statistics.median(b + r for b, r in zip(builds, renders)),
        "build_s": statistics.median(builds),
        "render_warm_s": statistics.median(renders),
        "build_stats": warm["shapes"],
        "inspected": warm.get("inspected"),
    }


def converge_reference(scene_path, xml_params: dict, integrator: str, approximations: list,
                       target_ratio: float = 0.2, max_spp: int = 1024,
                       progress: bool | None = False, noise_floor: float | None = None) -> dict:
    """Step 2 of the protocol: a reference converged against the given approximations.

    Two independent images (seed streams 0 and 1) get as many new samples again each round
    until ``noise_floor <= target_ratio * min_i FLIP(reference, approximations[i])`` — or,
    when the ``noise_floor`` target is given, until the floor is at most that target, if
    that comes first — or the next round would pass ``max_spp`` samples in total
    (``spp_capped``).

    Args:
        scene_path, xml_params: as for :func:`measure_approximation`.
        integrator: the reference's integrator plugin type.
        approximations: linear ``(H, W, 3)`` images the reference must resolve (>= 1).
        target_ratio, max_spp: see :func:`compare`.
        noise_floor: an absolute target of the two-seed noise floor (FLIP, in (0, 1); ``None``:
            only the ratio rule).
        progress: a line per stage (build, each round with its noise floor and FLIP) and bars
            over long multi-pass renders (:mod:`mi_displace.core.progress`).

    Returns:
        dict with ``reference`` (the average of the two images), ``images`` (the two),
        ``noise_floor_flip``, ``flips`` (FLIP of each approximation), ``error_maps``,
        ``rounds``, ``spp`` (total samples per pixel), ``spp_capped``, ``build_s``,
        ``build_cold_s``, ``render_s`` (every render of the final reference),
        ``render_cold_s`` (a 1-spp warm-up), ``build_stats`` and ``scene`` (the loaded
        reference scene, for further renders).
    """
    if noise_floor is not None and not (isinstance(noise_floor, (int, float))
                                        and 0 < noise_floor < 1):
        raise ValueError(f"noise_floor: the target must lie in (0, 1), got {noise_floor!r}")
    name = Path(scene_path).name
    ref_params = dict(xml_params, mode="reference", integrator=integrator)
    with stage(f"{name}: reference ({integrator}), cold and warm build", progress):
        ref_scene, ref_cold = scenes.load(scene_path, **ref_params)
        del ref_scene
        ref_scene, ref_warm = scenes.load(scene_path, **ref_params)
        _, render_cold = scenes.render(ref_scene, spp=1, seed=2**31)
    per_seed = max(1, min(ref_warm["spp"], max_spp // 2))
    images, count, rounds, render_s, spp_capped = [None, None], 0, [], 0.0, False
    while True:
        new = per_seed if count == 0 else count
        with stage(f"{name}: reference round {len(rounds) + 1}, {2 * (count + new)} spp",
                   progress) as s:
            for side in (0, 1):
                image, seconds = scenes.render(
                    ref_scene, spp=new, seed=2 * len(rounds) + side, progress=progress)
                metrics.assert_finite(image, f"reference image of {scene_path}")
                render_s += seconds
                images[side] = image if count == 0 else (images[side] * count + image * new) / (count + new)
            count += new
            reference = 0.5 * (images[0] + images[1])
            floor, _ = metrics.flip(images[0], images[1])
            results = [metrics.flip(reference, a) for a in approximations]
            flips = [f for f, _ in results]
            s.note = f"noise floor {floor:.4f}, FLIP {min(flips):.4f}"
        rounds.append({"spp": 2 * count, "noise_floor_flip": floor, "flip_mean": min(flips)})
        if floor <= max(target_ratio * min(flips), noise_floor or 0.0):
            break
        if 4 * count > max_spp:
            spp_capped = True
            break
    return {
        "reference": reference, "images": images, "noise_floor_flip": floor,
        "flips": flips, "error_maps": [m for _, m in results], "rounds": rounds,
        "spp": 2 * count, "spp_capped": spp_capped, "build_s": ref_warm["build_s"],
        "build_cold_s": ref_cold["build_s"], "render_s": render_s,
        "render_cold_s": render_cold, "build_stats": ref_warm["shapes"], "scene": ref_scene,
    }


def compare(scene_path, out_dir, params: dict | None = None, max_spp: int = 1024,
            target_ratio: float = 0.2, warm_repeats: int = 3,
            progress: bool | None = False, denoise: str | None = None) -> dict:
    """Run the comparison protocol (module docstring) on one scene and write its outputs.

    Args:
        scene_path: scene XML following the convention.
        out_dir: output folder (created).
        params: extra XML parameters for both sides (not ``mode`` / ``integrator``).
        max_spp: most samples per pixel of the averaged reference image (>= 2).
        target_ratio: required ``noise_floor_flip / flip_mean`` (0 < ratio <= 1).
        warm_repeats: warm load + render rounds of the approximation (>= 3).
        progress: a line per stage with its time (approximation rounds, reference build,
            each reference round with its noise floor and FLIP) and bars over long
            multi-pass renders; ``None``: only on a terminal (:mod:`mi_displace.core.progress`).
        denoise: OIDN quality (``"fast"``, ``"balanced"``, ``"high"``; the ``denoise`` extra):
            also measure the reference integrator's own curve at 1, 2, 4, ... spp (up to a
            quarter of the reference's), raw and denoised
            (:func:`mi_displace.evaluate.tradeoff.path_curve`), and where each reaches the
            approximation's FLIP; ``None``: neither curve.

    Returns:
        The metrics dict also written to ``out_dir/metrics.json`` (keys: :data:`METRIC_KEYS`;
        with ``denoise`` also ``path_curve``, ``denoised_curve``, ``path_crossover_s``,
        ``denoised_crossover_s`` and the verdicts ``path_verdict``, ``denoised_verdict``).
    """
    scene_path = Path(scene_path)
    settings = protocol_settings(scene_path, params)
    if not isinstance(max_spp, (int, np.integer)) or max_spp < 2:
        raise ValueError(f"max_spp: must be an integer >= 2 (two reference seeds), got {max_spp!r}")
    if not isinstance(target_ratio, (int, float)) or not 0 < target_ratio <= 1:
        raise ValueError(f"target_ratio: must lie in (0, 1], got {target_ratio!r}")
    if not isinstance(warm_repeats, (int, np.integer)) or warm_repeats < 3:
        raise ValueError(f"warm_repeats: must be an integer >= 3, got {warm_repeats!r}")
    if denoise is not None:
        dn.check_quality(denoise)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"out_dir {str(out_dir)!r} exists and is not a folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    xml_params = settings["xml_params"]

    # 1. approximation: cold, then warm rounds
    approx_int, approx_spp = settings["approximation_integrator"], settings["approximation_spp"]
    measured = measure_approximation(scene_path, xml_params, approx_int, approx_spp, warm_repeats,
                                     progress=progress)
    approx = measured["image"]

    # 2. reference: cold build (discarded), warm build, warm-up render, converging renders
    ref_int = settings["reference_integrator"]
    ref = converge_reference(scene_path, xml_params, ref_int, [approx], target_ratio, max_spp,
                             progress)
    curves = _path_curves(ref, denoise, measured["time_warm_s"]) if denoise is not None else {}
    del ref["scene"]
    reference, noise_floor, flip_mean = ref["reference"], ref["noise_floor_flip"], ref["flips"][0]
    error_map = ref["error_maps"][0]
    width, height = reference.shape[1], reference.shape[0]

    # 3. metrics and outputs
    reference_time = ref["build_s"] + ref["render_s"]
    info = {
        "scene": str(scene_path.resolve()),
        "params": scenes.check_params(params),
        "variant": mi.variant(),
        "width": width,
        "height": height,
        "flip_mean": flip_mean,
        "relmse": metrics.relmse(reference, approx),
        "psnr": metrics.psnr(reference, approx),
        "ssim": metrics.ssim(reference, approx),
        "noise_floor_flip": noise_floor,
        "target_ratio": float(target_ratio),
        "converged": noise_floor <= target_ratio * flip_mean,
        "within_noise_floor": flip_mean <= noise_floor,
        "reference_spp": ref["spp"],
        "max_spp": int(max_spp),
        "spp_capped": ref["spp_capped"],
        "reference_rounds": ref["rounds"],
        "reference_integrator": ref_int,
        "approximation_integrator": approx_int,
        "approximation_spp": approx_spp,
        "reference_time_s": reference_time,
        "reference_build_s": ref["build_s"],
        "reference_render_s": ref["render_s"],
        "reference_build_cold_s": ref["build_cold_s"],
        "reference_render_cold_s": ref["render_cold_s"],
        "approx_time_cold_s": measured["time_cold_s"],
        "approx_build_cold_s": measured["build_cold_s"],
        "approx_render_cold_s": measured["render_cold_s"],
        "approx_time_warm_s": measured["time_warm_s"],
        "approx_build_s": measured["build_s"],
        "approx_render_warm_s": measured["render_warm_s"],
        "warm_repeats": int(warm_repeats),
        "speedup": reference_time / measured["time_warm_s"],
        "build_stats": {"reference": ref["build_stats"], "approximation": measured["build_stats"]},
        # what the plugins warned about while building (e.g. displacement through a thin shell)
        "warnings": [f"{side}: {w}" for side, shapes in
                     (("reference", ref["build_stats"]), ("approximation", measured["build_stats"]))
                     for shape in shapes for w in shape.get("warnings", [])],
        "mitsuba_version": mi.__version__,
        "drjit_version": dr.__version__,
        **curves,
    }
    write_exr(out_dir / "reference.exr", reference)
    write_exr(out_dir / "approximation.exr", approx)
    write_panel(out_dir / "panel.png", reference, approx, error_map, info)
    with open(out_dir / "metrics.json", "w") as f:
        json.dump(_finite_or_none(info), f, indent=2, allow_nan=False)
    return info


def _path_curves(ref: dict, denoise: str, approx_time_s: float) -> dict:
    """The reference integrator's raw and denoised curves against ``ref`` and where each
    reaches the approximation's FLIP (``ref["flips"][0]``), for :func:`compare`."""
    from mi_displace.evaluate import tradeoff as tr  # tradeoff builds on this module

    raw, denoised = tr.path_curve(ref, tr.default_path_spps(ref["spp"]), denoise=denoise)
    info = {"path_curve": raw, "denoised_curve": denoised, "denoise": denoise}
    for name, curve, competitor in (("path", raw, "path tracing"),
                                    ("denoised", denoised, "denoised path tracing")):
        seconds, spp = tr.crossover(curve, ref["flips"][0])
        info.update({f"{name}_crossover_s": seconds, f"{name}_crossover_spp": spp,
                     f"{name}_verdict": tr.crossover_verdict(approx_time_s, seconds, competitor)})
    return info


def compare_job(scene_path: str, params: dict | None = None, **options) -> dict:
    """:func:`compare` as an independent job (:func:`mi_displace.evaluate.jobs.run_jobs`).

    The worker writes into a temporary folder of its own and returns the files' bytes, so a
    worker on another machine needs no shared file system; :func:`write_job_files` writes
    them on the caller's side.

    Returns:
        ``{"info": metrics dict, "files": {name: bytes}}``.
    """
    import tempfile

    with tempfile.TemporaryDirectory(prefix="mi_displace_compare_") as tmp:
        info = compare(scene_path, tmp, params=params, **options)
        files = {p.name: p.read_bytes() for p in Path(tmp).iterdir() if p.is_file()}
    return {"info": _finite_or_none(info), "files": files}


def write_job_files(out_dir, files: dict) -> None:
    """Write the ``{name: bytes}`` returned by :func:`compare_job` into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (out_dir / Path(name).name).write_bytes(data)
