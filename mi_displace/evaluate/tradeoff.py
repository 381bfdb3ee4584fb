"""Trade-off sweeps: error against time over a scene's quality knobs, and the cheapest setting.

:func:`tradeoff` sweeps named knobs of any scene that follows the comparison convention
(:mod:`mi_displace.evaluate.compare`) and measures, for every combination ("point"):

* the approximation's warm time (median of ``warm_repeats`` load + render rounds, build
  included, as :func:`compare.measure_approximation`) and its cold time;
* its error against one converged reference (FLIP, relMSE, PSNR), the reference being
  converged by :func:`compare.converge_reference` until its two-seed noise floor is at most
  ``target_ratio`` times the *smallest* error of the sweep, or at most the absolute target
  ``noise_floor`` when one is given (whichever comes first), or ``max_spp``;
* the reference integrator's own curve: the same integrator at 1, 2, 4, ... spp up to a
  quarter of the reference's (seeds that the reference did not use), its FLIP against the
  reference and its warm time;
* optionally ``inspect(scene) -> dict``: measurements of the loaded approximation scene
  itself (a table's reconstruction error, a normal's angle error, ...), per point;
* with ``denoise``: the same curve again, each image denoised by Open Image Denoise
  (:mod:`mi_displace.render.denoise`, the denoiser's time counted in the point's time) and
  measured against the same reference like any approximation;
* the crossover: how long the path tracer needs to reach each point's error (log-log
  interpolation along its curve; ``None`` when it does not get there within the curve),
  against the raw curve and against the denoised one, with a verdict sentence for each.

Knobs
-----
``NAME=V1,V2,...`` where ``NAME`` is

* a top-level ``<default>`` of the scene (``-D`` parameter), including ``mode`` — any part
  of the scene other than the reference may be the approximation (``mode=approximation,bump``)
  and ``mode=reference`` is the true geometry under the approximation's integrator — and
  the protocol parameters ``approximation_integrator`` / ``approximation_spp``;
* ``ID.PARAM`` with a dot: a ``mi.traverse`` parameter of the loaded approximation scene, set
  after each load (:func:`mi_displace.render.scene.apply_edits`).

The swept points are the product of the knobs' values, or an explicit list of points
(``points=[{NAME: VALUE, ...}, ...]``, each naming any subset of the knobs — a figure that
varies one parameter at a time, or pairs values).  Unknown knobs are refused before anything
renders.  A point whose value the plugin refuses
(``ValueError``) is skipped and recorded with the reason; the sweep goes on.  Scenes may
declare their own knobs for ``atlas``/``tune`` with comments ``<!-- tradeoff: NAME=V1,V2 -->``.

Cache and resumption
--------------------
Every finished point is written at once to ``cache_dir`` (default ``$MI_DISPLACE_CACHE`` or
``~/.cache/mi_displace``, sub-folder ``tradeoff``) under a key of the scene's text (and every
file it includes), the point's parameters, the integrator, ``warm_repeats``, the variant and
:func:`mi_displace.core.version.code_version`; an interrupted sweep resumes from there and a
cache written by other code is never read.  Cached points keep the time measured when they
ran (with the host that ran them).

Jobs run locally or on a Dask cluster (:mod:`mi_displace.evaluate.jobs`); the reference and
the path curve are rendered in the calling process.
"""
from __future__ import annotations

import csv
import datetime
import hashlib
import itertools
import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mi_displace.core.progress import log
from mi_displace.evaluate import compare as cmp
from mi_displace.evaluate import jobs as jobs_mod
from mi_displace.evaluate import metrics
from mi_displace.render import denoise as dn
from mi_displace.render import scene as scenes

#: Scene comment declaring a knob for ``atlas`` and ``tune``: ``<!-- tradeoff: NAME=V1,V2 -->``.
DECLARED_KNOB = re.compile(r"<!--\s*tradeoff:\s*([^>]*?)\s*-->")
#: CSV columns (and the per-point keys of ``tradeoff.json``).
CSV_COLUMNS = ("label", "ok", "flip", "relmse", "psnr", "time_warm_s", "time_cold_s",
               "build_s", "build_cold_s", "render_warm_s", "pareto", "path_crossover_s", "path_crossover_spp",
               "denoised_crossover_s", "denoised_crossover_spp", "host", "cached", "error")


@dataclass(frozen=True)
class Knob:
    """One swept parameter: ``kind`` is ``"define"`` (XML ``-D``) or ``"edit"`` (traverse)."""
    name: str
    values: tuple[str, ...]
    kind: str


def parse_knob(text: str) -> Knob:
    """``NAME=V1,V2,...`` as a :class:`Knob` (module docstring).

    Raises:
        ValueError: no ``=``, an empty name or value, or a repeated value.
    """
    name, sep, values = text.partition("=")
    name = name.strip()
    items = tuple(v.strip() for v in values.split(","))
    if not sep or not name or not all(items):
        raise ValueError(f"--knob: expected NAME=V1,V2,..., got {text!r}")
    if len(set(items)) != len(items):
        raise ValueError(f"--knob {name}: a value is repeated in {values!r}")
    if "." in name:
        if not re.fullmatch(r"[\w\-]+(\.[\w\-]+)+", name):
            raise ValueError(f"--knob: {name!r} is not a traverse key (ID.PARAM)")
        return Knob(name, items, "edit")
    if not re.fullmatch(r"[A-Za-z_]\w*", name):
        raise ValueError(f"--knob: {name!r} is not a parameter name")
    return Knob(name, items, "define")


def declared_knobs(scene_path) -> list[Knob]:
    """The knobs a scene declares with ``<!-- tradeoff: NAME=V1,V2 -->`` comments."""
    text = Path(scene_path).read_text()
    return [parse_knob(m.group(1)) for m in DECLARED_KNOB.finditer(text)]


def check_knobs(scene_path, knobs: list[Knob], params: dict | None = None) -> None:
    """Refuse knobs the scene does not have, before anything renders.

    ``define`` knobs must be top-level defaults of the scene (or protocol parameters);
    ``mode=reference`` is allowed (the true geometry under the approximation's integrator).
    ``edit`` knobs are checked against ``mi.traverse`` of the approximation scene, loaded once.

    Raises:
        ValueError: naming the knob (and the scene's parameters).
    """
    if not knobs:
        raise ValueError("no knob to sweep: give --knob NAME=V1,V2,... or declare "
                         "<!-- tradeoff: NAME=V1,V2 --> in the scene")
    names = [k.name for k in knobs]
    if len(set(names)) != len(names):
        raise ValueError(f"--knob: a knob is given twice in {names}")
    defaults = cmp.scene_defaults(scene_path)
    settings = cmp.protocol_settings(scene_path, params)
    allowed = (set(defaults) - {"integrator"}) | set(cmp.PROTOCOL_PARAMS)
    for knob in knobs:
        if knob.kind == "define" and knob.name not in allowed:
            raise ValueError(
                f"--knob {knob.name}: scene {str(scene_path)!r} has no parameter {knob.name!r} "
                f"(its defaults: {', '.join(sorted(allowed))}; traverse keys are ID.PARAM)")
    edits = [k for k in knobs if k.kind == "edit"]
    if edits:
        import mitsuba as mi

        scene, _ = scenes.load(scene_path, **settings["xml_params"], mode="approximation",
                               integrator=settings["approximation_integrator"])
        keys = set(mi.traverse(scene).keys())
        del scene
        for knob in edits:
            if knob.name not in keys:
                import difflib

                close = difflib.get_close_matches(knob.name, sorted(keys), n=3)
                hint = f" (closest: {', '.join(close)})" if close else ""
                raise ValueError(f"--knob {knob.name}: the approximation scene has no traverse "
                                 f"parameter {knob.name!r}{hint}")


def sweep_points(knobs: list[Knob]) -> list[dict[str, str]]:
    """Every combination of the knobs' values, the first knob varying slowest."""
    return [dict(zip([k.name for k in knobs], combo))
            for combo in itertools.product(*[k.values for k in knobs])]


def knobs_of(points: list[dict]) -> list[Knob]:
    """The knobs an explicit list of points names (values as text, in order of appearance).

    Raises:
        ValueError: no point, or a point naming no knob.
    """
    if not points or not all(points):
        raise ValueError("points: give at least one point, each naming at least one knob")
    values: dict[str, list[str]] = {}
    for point in points:
        for name, value in point.items():
            seen = values.setdefault(name, [])
            if str(value) not in seen:
                seen.append(str(value))
    return [parse_knob(f"{name}={','.join(vals)}") for name, vals in values.items()]


def point_label(point: dict[str, str]) -> str:
    """``name=value`` pairs of a point, comma separated."""
    return ",".join(f"{k}={v}" for k, v in point.items())


def _included_files(path: Path, params: dict[str, str], seen: set) -> None:
    """Collect ``path`` and every file it names (``filename="..."``, ``$name`` substituted)."""
    if path in seen or not path.is_file():
        return
    seen.add(path)
    if path.suffix.lower() != ".xml":
        return
    for name in re.findall(r'filename\s*=\s*"([^"]+)"', path.read_text(errors="replace")):
        for key, value in params.items():
            name = name.replace(f"${key}", value)
        _included_files((path.parent / name).resolve(), params, seen)


def scene_digest(scene_path, params: dict[str, str]) -> str:
    """SHA-256 of the scene file and of every file it includes under ``params``.

    ``params`` must hold every ``$name`` that file names depend on (``mode`` included).
    """
    defaults = cmp.scene_defaults(scene_path)
    files: set = set()
    for mode in ("reference", params.get("mode", "approximation")):
        _included_files(Path(scene_path).resolve(), {**defaults, **params, "mode": mode}, files)
    h = hashlib.sha256()
    for path in sorted(files):
        h.update(str(path.name).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """``$MI_DISPLACE_CACHE/tradeoff``, else ``~/.cache/mi_displace/tradeoff``."""
    root = os.environ.get("MI_DISPLACE_CACHE") or Path.home() / ".cache" / "mi_displace"
    return Path(root) / "tradeoff"


def _cache_key(**parts) -> str:
    from mi_displace.core.version import code_version

    text = json.dumps({**parts, "code_version": code_version()}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _cache_read(cache_dir: Path, key: str) -> dict | None:
    meta, image = cache_dir / f"{key}.json", cache_dir / f"{key}.npy"
    if not (meta.is_file() and image.is_file()):
        return None
    try:
        record = json.loads(meta.read_text())
        record["image"] = np.load(image)
    except (OSError, ValueError):
        return None  # a torn or foreign entry is measured again
    return record


def _cache_write(cache_dir: Path, key: str, record: dict) -> None:
    """Atomically write one finished point (image as ``.npy`` beside its JSON)."""
    cache_dir.mkdir(parents=True, exist_ok=True)
    record = dict(record)
    image = record.pop("image")
    for suffix, write in ((".npy", lambda f: np.save(f, image)),
                          (".json", lambda f: f.write(json.dumps(cmp._finite_or_none(record)).encode()))):
        tmp = cache_dir / f"{key}{suffix}.tmp{os.getpid()}"
        with open(tmp, "wb") as f:
            write(f)
        os.replace(tmp, cache_dir / f"{key}{suffix}")


def measure_point(scene_path: str, xml_params: dict, integrator: str, spp: int | None,
                  warm_repeats: int, mode: str, edits: dict, inspect=None) -> dict:
    """One sweep point: :func:`compare.measure_approximation` (a job of :func:`jobs.run_jobs`)."""
    return cmp.measure_approximation(scene_path, xml_params, integrator, spp, warm_repeats,
                                     mode=mode, edits=edits, inspect=inspect)


def _point_job(scene_path, settings, point: dict[str, str], knobs: list[Knob],
               warm_repeats: int, inspect=None) -> dict:
    """Keyword arguments of :func:`measure_point` for one point."""
    kinds = {k.name: k.kind for k in knobs}
    point = {name: str(value) for name, value in point.items()}
    xml_params = dict(settings["xml_params"])
    integrator, spp, mode, edits = (settings["approximation_integrator"],
                                    settings["approximation_spp"], "approximation", {})
    for name, value in point.items():
        if kinds[name] == "edit":
            edits[name] = value
        elif name == "mode":
            mode = value
        elif name == "approximation_integrator":
            integrator = value
        elif name == "approximation_spp":
            if not value.isdigit() or int(value) < 1:
                raise ValueError(f"approximation_spp: expected a positive integer, got {value!r}")
            spp = int(value)
        else:
            xml_params[name] = value
    return {"scene_path": str(scene_path), "xml_params": xml_params, "integrator": integrator,
            "spp": spp, "warm_repeats": warm_repeats, "mode": mode, "edits": edits,
            "inspect": inspect}


def _callable_name(fn) -> str | None:
    """``module.qualname`` of a function (cache keys name it; its source is in code_version)."""
    return None if fn is None else f"{fn.__module__}.{fn.__qualname__}"


def pareto_front(times: list[float], errors: list[float]) -> list[bool]:
    """Whether each (time, error) point is on the Pareto front (no other point is at least as
    fast *and* at least as accurate, and strictly better in one)."""
    flags = []
    for i, (t, e) in enumerate(zip(times, errors)):
        dominated = any((t2 <= t and e2 <= e) and (t2 < t or e2 < e)
                        for j, (t2, e2) in enumerate(zip(times, errors)) if j != i)
        flags.append(not dominated)
    return flags


def crossover(curve: list[dict], error: float) -> tuple[float | None, float | None]:
    """The time (and spp) at which the path curve first reaches ``error``.

    Args:
        curve: ``[{"spp", "time_s", "flip"}]`` in increasing spp.
        error: the FLIP to reach.

    Returns:
        ``(seconds, spp)`` interpolated linearly in log time / log spp against log FLIP
        between the two curve points around ``error``; the first point if it already
        reaches it; ``(None, None)`` if no point of the curve does.
    """
    for i, p in enumerate(curve):
        if p["flip"] <= error:
            if i == 0:
                return p["time_s"], float(p["spp"])
            q = curve[i - 1]
            lo, hi = math.log(max(q["flip"], 1e-12)), math.log(max(p["flip"], 1e-12))
            w = 0.0 if hi == lo else (math.log(max(error, 1e-12)) - lo) / (hi - lo)
            w = min(max(w, 0.0), 1.0)

            def lerp(a, b):
                return math.exp(math.log(a) + w * (math.log(b) - math.log(a)))
            return lerp(q["time_s"], p["time_s"]), lerp(q["spp"], p["spp"])
    return None, None


def default_path_spps(reference_spp: int) -> list[int]:
    """1, 2, 4, ... samples per pixel up to a quarter of the reference's: the path curve."""
    return [2 ** k for k in range(int(math.log2(max(1, reference_spp // 4))) + 1)]


def path_curve(ref: dict, spps: list[int], seed_base: int = 1 << 20,
               denoise: str | None = None) -> tuple[list[dict], list[dict]]:
    """The reference integrator's own error against the converged reference, per spp: raw,
    and (``denoise``) denoised.

    Args:
        ref: :func:`compare.converge_reference`'s result (its loaded ``scene`` is rendered).
        spps: samples per pixel to render (each an independent image, fresh seeds).
        seed_base: first seed (far from the reference's own seeds 0, 1, 2, ...).
        denoise: OIDN quality (:data:`mi_displace.render.denoise.QUALITIES`): each spp is
            rendered again with albedo and normal AOVs (same seed, so the same noisy colour;
            after one untimed 1-spp warm-up, as the reference's) and denoised
            (:func:`mi_displace.render.denoise.render_denoised`); ``None``: no denoised curve.

    Returns:
        ``(raw, denoised)``: ``[{"spp", "time_s" (warm build + render), "render_s", "flip",
        "relmse"}]``; the denoised points' ``time_s`` also counts the AOV render and the
        denoiser (``denoise_s``); ``denoised`` is ``[]`` without ``denoise``.
    """
    def point(spp, image, render_s, what, **extra):
        metrics.assert_finite(image, f"{what} image at {spp} spp")
        flip, _ = metrics.flip(ref["reference"], image)
        return {"spp": spp, "time_s": ref["build_s"] + render_s + extra.get("denoise_s", 0.0),
                "render_s": render_s, "flip": flip,
                "relmse": metrics.relmse(ref["reference"], image), **extra}

    raw, denoised = [], []
    if denoise is not None:  # warm-up: the AOV integrator's kernels and OIDN's filter
        dn.render_denoised(ref["scene"], 1, seed_base - 1, denoise)
    for i, spp in enumerate(spps):
        image, seconds = scenes.render(ref["scene"], spp=spp, seed=seed_base + i)
        raw.append(point(spp, image, seconds, "path-curve"))
        if denoise is not None:
            image, _, times = dn.render_denoised(ref["scene"], spp, seed_base + i, denoise)
            denoised.append(point(spp, image, times["render_s"], "denoised path-curve",
                                  denoise_s=times["denoise_s"], quality=denoise))
    return raw, denoised


def crossover_verdict(time_s: float, crossover_s: float | None, competitor: str) -> str:
    """One sentence: below which time a point beats ``competitor`` (a path curve).

    Args:
        time_s: the point's warm time (s).
        crossover_s: when the competitor reaches the point's FLIP (:func:`crossover`), or
            ``None`` if its curve never does.
        competitor: its name, e.g. ``"denoised path tracing"``.
    """
    if crossover_s is None:
        return f"{competitor} does not reach this error within its curve: this technique wins"
    if crossover_s <= time_s:
        return f"{competitor} reaches this error sooner ({crossover_s:.3g} s): path trace"
    return (f"below {crossover_s:.3g} s this technique beats {competitor}; above, path trace")


def _log_point(points: list[dict], index: int, result: str, progress: bool | None) -> None:
    """The progress line of one sweep point: ``point 2/4: map_resolution=32: 0.41 s``."""
    setting = ", ".join(f"{name}={value}" for name, value in points[index].items())
    log(f"point {index + 1}/{len(points)}: {setting}: {result}", enabled=progress)


def tradeoff(scene_path, knobs: list[Knob] | None, out_dir=None, params: dict | None = None,
             max_spp: int = 1024, target_ratio: float = 0.2, warm_repeats: int = 3,
             cluster: str | None = None, cache_dir=None, progress: bool | None = False,
             path_spps: list[int] | None = None, noise_floor: float | None = None,
             points: list[dict] | None = None, inspect=None,
             denoise: str | None = None) -> dict:
    """Sweep ``knobs`` on a comparison scene (module docstring); write CSV, JSON and a plot.

    Args:
        scene_path: scene XML following the comparison convention.
        knobs: the knobs (:func:`parse_knob`); their product is swept unless ``points`` is
            given (``None`` with ``points``: :func:`knobs_of` them).
        out_dir: output folder for ``tradeoff.csv``, ``tradeoff.json``, ``tradeoff.png``
            (``None``: nothing written).
        params: fixed XML parameters for both sides.
        max_spp, target_ratio: reference convergence (see :func:`compare.compare`).
        warm_repeats: warm rounds per point (>= 3).
        cluster: ``None``, ``"local:N"`` or a Dask scheduler address.
        cache_dir: point cache (``None``: :func:`default_cache_dir`).
        progress: progress bars.
        path_spps: spp of the path curve (default 1, 2, 4, ... up to a quarter of the
            reference's spp; ``[]``: none, e.g. when the reference integrator is ``raster``).
        noise_floor: absolute target of the reference's noise floor (FLIP): the reference
            stops doubling once its floor is below it even if the ratio rule is not met.
        points: explicit points instead of the product (module docstring).
        inspect: a module-level ``inspect(scene) -> dict`` run on each point's loaded
            approximation scene (on the worker; its name is part of the cache key).
        denoise: OIDN quality of a second, denoised path curve (``"fast"``, ``"balanced"``,
            ``"high"``; ``None``: the raw curve only); needs the ``denoise`` extra.

    Returns:
        The dict written to ``tradeoff.json``: ``points`` (one dict per point: ``point``,
        ``label``, :data:`CSV_COLUMNS`, ``build_stats``, ``inspected``, ``path_verdict``,
        ``denoised_verdict``), ``path_curve``, ``denoised_curve``, ``denoise``,
        ``noise_floor_flip``, ``reference_spp``, ``spp_capped`` and the settings.
    """
    import mitsuba as mi

    scene_path = Path(scene_path)
    settings = cmp.protocol_settings(scene_path, params)
    if points is not None:
        knobs = knobs or knobs_of(points)
        unknown = sorted({n for p in points for n in p} - {k.name for k in knobs})
        if unknown:
            raise ValueError(f"points: {', '.join(unknown)} is not among the knobs")
    check_knobs(scene_path, knobs, params)
    jobs_mod.check_cluster(cluster)
    if not isinstance(warm_repeats, int) or warm_repeats < 3:
        raise ValueError(f"warm_repeats: must be an integer >= 3, got {warm_repeats!r}")
    if not isinstance(max_spp, int) or max_spp < 2:
        raise ValueError(f"max_spp: must be an integer >= 2, got {max_spp!r}")
    if noise_floor is not None and not (isinstance(noise_floor, (int, float))
                                        and 0 < noise_floor < 1):
        raise ValueError(f"--noise-floor: the target must lie in (0, 1), got {noise_floor!r}")
    if denoise is not None:
        dn.check_quality(denoise)
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    points = (sweep_points(knobs) if points is None
              else [{name: str(value) for name, value in p.items()} for p in points])

    # 1. the approximation at every point: cached, or run as jobs (locally / on the cluster)
    records: list[dict | None] = [None] * len(points)
    pending, keys = [], []
    for index, point in enumerate(points):
        try:
            job = _point_job(scene_path, settings, point, knobs, warm_repeats, inspect)
        except ValueError as e:
            records[index] = {"ok": False, "error": f"ValueError: {e}", "cached": False}
            keys.append(None)
            continue
        key = _cache_key(scene=scene_digest(scene_path, {**job["xml_params"], "mode": job["mode"]}),
                         job={**{k: v for k, v in job.items() if k != "scene_path"},
                              "inspect": _callable_name(inspect)},
                         variant=mi.variant())
        keys.append(key)
        cached = _cache_read(cache_dir, key)
        if cached is not None:
            records[index] = {**cached, "ok": True, "cached": True}
            _log_point(points, index, "cached", progress)
        else:
            pending.append((index, job))

    def store(position, outcome):
        index = pending[position][0]
        _log_point(points, index, f"{outcome['job_s']:.2f} s" if outcome["ok"]
                   else f"failed ({outcome['error']})", progress)
        if outcome["ok"]:
            record = {**outcome["value"], "host": outcome["host"], "job_s": outcome["job_s"],
                      "measured_at": datetime.datetime.now().isoformat(timespec="seconds")}
            _cache_write(cache_dir, keys[index], record)
            records[index] = {**record, "ok": True, "cached": False}
        else:
            records[index] = {"ok": False, "error": outcome["error"], "host": outcome["host"],
                              "cached": False}

    jobs_mod.run_jobs(measure_point, [job for _, job in pending], cluster=cluster,
                      on_result=store, progress=progress, desc=f"sweep {scene_path.stem}")
    good = [i for i, r in enumerate(records) if r["ok"]]
    if not good:
        reasons = "; ".join(sorted({r["error"] for r in records}))
        raise ValueError(f"scene {str(scene_path)!r}: no point of the sweep rendered ({reasons})")

    # 2. one reference, converged against the most accurate point; 3. the path curve
    ref = cmp.converge_reference(scene_path, settings["xml_params"],
                                 settings["reference_integrator"],
                                 [records[i]["image"] for i in good], target_ratio, max_spp,
                                 progress, noise_floor)
    if path_spps is None:
        path_spps = default_path_spps(ref["spp"])
    curve, denoised = path_curve(ref, path_spps, denoise=denoise)
    del ref["scene"]

    # 4. metrics per point, front, crossover
    for i, flip in zip(good, ref["flips"]):
        image = records[i]["image"]
        records[i].update(flip=flip, relmse=metrics.relmse(ref["reference"], image),
                          psnr=metrics.psnr(ref["reference"], image))
    front = pareto_front([records[i]["time_warm_s"] for i in good],
                         [records[i]["flip"] for i in good])
    rows = []
    for index, (point, record) in enumerate(zip(points, records)):
        row = {"point": point, "label": point_label(point), "ok": record["ok"],
               "cached": record.get("cached", False), "host": record.get("host"),
               "error": record.get("error")}
        if record["ok"]:
            t, s = crossover(curve, record["flip"])
            td, sd = crossover(denoised, record["flip"])
            row.update({k: record.get(k) for k in ("flip", "relmse", "psnr", "time_warm_s",
                                                   "time_cold_s", "build_s", "build_cold_s",
                                                   "render_warm_s")},
                       pareto=front[good.index(index)], path_crossover_s=t,
                       path_crossover_spp=s, denoised_crossover_s=td, denoised_crossover_spp=sd,
                       path_verdict=(crossover_verdict(record["time_warm_s"], t, "path tracing")
                                     if curve else None),
                       denoised_verdict=(crossover_verdict(record["time_warm_s"], td,
                                                           "denoised path tracing")
                                         if denoised else None),
                       build_stats=record.get("build_stats"),
                       inspected=record.get("inspected"), measured_at=record.get("measured_at"))
        rows.append(row)
    result = {
        "scene": str(scene_path.resolve()), "params": scenes.check_params(params),
        "knobs": [{"name": k.name, "values": list(k.values), "kind": k.kind} for k in knobs],
        "variant": mi.variant(), "cluster": cluster, "warm_repeats": warm_repeats,
        "width": int(ref["reference"].shape[1]), "height": int(ref["reference"].shape[0]),
        "reference_integrator": settings["reference_integrator"],
        "reference_spp": ref["spp"], "spp_capped": ref["spp_capped"], "max_spp": max_spp,
        "reference_rounds": ref["rounds"],
        "target_ratio": target_ratio, "noise_floor_target": noise_floor,
        "noise_floor_flip": ref["noise_floor_flip"], "inspect": _callable_name(inspect),
        "reference_time_s": ref["build_s"] + ref["render_s"],
        "points": rows, "path_curve": curve, "denoised_curve": denoised, "denoise": denoise,
    }
    if out_dir is not None:
        write_outputs(out_dir, result, ref["reference"], {i: records[i]["image"] for i in good})
    return result


def write_outputs(out_dir, result: dict, reference: np.ndarray, images: dict) -> None:
    """``tradeoff.json``, ``tradeoff.csv``, ``tradeoff.png``, ``reference.exr`` and one
    ``point_<i>.png`` (sRGB) per rendered point in ``out_dir``."""
    from mi_displace.core.io import write_exr, write_image

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "tradeoff.json", "w") as f:
        json.dump(cmp._finite_or_none(result), f, indent=2, allow_nan=False)
    inspected = list(dict.fromkeys(k for row in result["points"]
                                   for k in (row.get("inspected") or {})))
    with open(out_dir / "tradeoff.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=[*CSV_COLUMNS, *inspected], extrasaction="ignore")
        writer.writeheader()
        for row in result["points"]:
            writer.writerow({**{k: row.get(k) for k in CSV_COLUMNS}, **(row.get("inspected") or {})})
    write_exr(out_dir / "reference.exr", reference)
    for index, image in images.items():
        write_image(out_dir / f"point_{index}.png", image)
    plot(result, out_dir / "tradeoff.png")


#: Points of a trade-off plot beyond which only the Pareto front is labelled.
MAX_PLOT_LABELS = 40
#: Colours of the groups of points (Matplotlib's cycle without C7, the grey of path's curve).
PLOT_COLOURS = [f"C{i}" for i in range(10) if i != 7]


def plot(result: dict, path=None, ax=None, title: str | None = None) -> Path | None:
    """Error against warm time, log-log: every point labelled, the Pareto front joined, the
    reference's noise floor as a dashed line and the path tracer's own curve.

    Args:
        result: :func:`tradeoff`'s result.
        path: PNG to write (a figure of its own), or ``None`` with ``ax``.
        ax: a Matplotlib axes to draw into instead (a panel of a larger figure).
        title: the axes' title (default: the scene's file name).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = None
    if ax is None:
        fig = Figure(figsize=(7.5, 5.0))
        FigureCanvasAgg(fig)
        ax = fig.add_subplot(1, 1, 1)
    curve = result["path_curve"]
    if curve:
        ax.plot([p["time_s"] for p in curve], [p["flip"] for p in curve], "o-", color="0.55",
                label=f"{result['reference_integrator']} (error vs spp)")
    denoised = result.get("denoised_curve") or []
    if denoised:
        ax.plot([p["time_s"] for p in denoised], [p["flip"] for p in denoised], "s--",
                color="0.3", label=f"{result['reference_integrator']} + OIDN "
                                   f"{result['denoise']} (error vs spp)")
    for p in (*curve, *denoised):
        ax.annotate(f"{p['spp']}", (p["time_s"], p["flip"]), fontsize=6, color="0.4",
                    xytext=(3, 3), textcoords="offset points")
    ok = [r for r in result["points"] if r["ok"]]
    groups = _plot_groups(ok)
    for i, (name, members) in enumerate(groups.items()):
        ax.scatter([r["time_warm_s"] for r, _ in members], [r["flip"] for r, _ in members],
                   color=PLOT_COLOURS[i % len(PLOT_COLOURS)],
                   marker="osD^v<>"[i // len(PLOT_COLOURS) % 7], zorder=3,
                   label=name or "approximation settings")
    front = sorted((r for r in ok if r["pareto"]), key=lambda r: r["time_warm_s"])
    ax.plot([r["time_warm_s"] for r in front], [r["flip"] for r in front], "-", color="0.2",
            lw=0.8, zorder=2, label="Pareto front")
    # every point is labelled while that stays legible, else only the Pareto front
    legible = len(ok) <= MAX_PLOT_LABELS
    for members in groups.values():
        for r, text in members:
            if text and (legible or r["pareto"]):
                ax.annotate(text, (r["time_warm_s"], r["flip"]), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
    if result["noise_floor_flip"] > 0:  # a deterministic reference (raster) has none
        ax.axhline(result["noise_floor_flip"], ls="--", color="C2",
                   label=f"reference noise floor ({result['reference_spp']} spp)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("warm time per frame (s, build included)")
    ax.set_ylabel("mean FLIP against the reference")
    ax.set_title(title or Path(result["scene"]).name, fontsize=10)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, loc="best")
    if fig is None:
        return None
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return Path(path)


def _plot_groups(points: list[dict]) -> dict[str, list[tuple[dict, str]]]:
    """Points grouped for a legend by their first knob's setting, each with the values of
    the rest as its label: ``{"direction=b: slices": [(point, "12"), ...]}``; one unnamed
    group, labelled in full, when they all share the first setting or none does."""
    def split(r):
        items = list(r["point"].items())
        first = f"{items[0][0]}={items[0][1]}" if items else ""
        return first, [k for k, _ in items[1:]], ",".join(str(v) for _, v in items[1:])

    if not 1 < len({split(r)[0] for r in points}) < len(points):  # nothing to group
        return {"": [(r, r["label"]) for r in points]}
    groups: dict[str, list[tuple[dict, str]]] = {}
    for r in points:
        first, keys, values = split(r)
        groups.setdefault(first + (": " + ",".join(keys) if keys else ""), []).append((r, values))
    return groups


def table_rows(result: dict) -> list[dict]:
    """One flat dict per rendered point of a sweep: its knob values, the
    :data:`CSV_COLUMNS`, ``build_stats`` and its ``inspected`` measurements (for tables of
    figures)."""
    return [{**r["point"], **{k: r.get(k) for k in (*CSV_COLUMNS, "build_stats")},
             **(r.get("inspected") or {})} for r in result["points"] if r["ok"]]


def markdown(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """A Markdown table: ``columns`` are ``(header, key, format spec)``; missing values '–'."""
    def cell(row, key, spec):
        value = row.get(key)
        if value is None:
            return "–"
        return format(value, spec) if spec else str(value)

    head = "| " + " | ".join(c[0] for c in columns) + " |\n|" + "---|" * len(columns) + "\n"
    return head + "".join("| " + " | ".join(cell(r, key, spec) for _, key, spec in columns)
                          + " |\n" for r in rows)


def tune(scene_path, flip_budget: float, knobs: list[Knob] | None = None, out_dir=None,
         params: dict | None = None, verify: bool = True, **sweep) -> dict:
    """The cheapest measured setting whose FLIP meets ``flip_budget``.

    Sweeps ``knobs`` (default: the scene's declared knobs) with :func:`tradeoff`, picks the
    point of least warm time with ``flip <= flip_budget``, then (``verify``) renders it again
    from scratch — no cache — against the same reference, and measures the scene's default
    setting the same way for the time ratio.

    Returns:
        dict with ``budget``, ``chosen`` (the point, ``None`` if none meets the budget),
        ``defines`` (``-D name=value`` strings), ``sweep_flip`` / ``sweep_time_s`` of the
        chosen point, ``verified_flip`` / ``verified_time_s``, ``meets_budget``,
        ``default_time_s`` / ``default_flip`` and ``speedup_vs_default``; ``path`` and
        ``denoised_path``: the fastest measured point of the raw / denoised path curve
        within the budget (``None``: none, or no such curve); ``answer``: one sentence
        naming the fastest of the three (the approximation's sweep time against the path
        points' times, all measured in this run). Also written to ``out_dir/tune.json`` with
        the sweep's outputs.
    """
    if not isinstance(flip_budget, (int, float)) or not 0 < flip_budget < 1:
        raise ValueError(f"--flip: the budget must lie in (0, 1), got {flip_budget!r}")
    knobs = knobs or declared_knobs(scene_path)
    result = tradeoff(scene_path, knobs, out_dir=out_dir, params=params, **sweep)
    candidates = [r for r in result["points"] if r["ok"] and r["flip"] <= flip_budget]
    answer = {"scene": result["scene"], "budget": float(flip_budget), "chosen": None,
              "defines": [], "noise_floor_flip": result["noise_floor_flip"]}
    if candidates:
        best = min(candidates, key=lambda r: r["time_warm_s"])
        answer.update(chosen=best["point"], sweep_flip=best["flip"],
                      sweep_time_s=best["time_warm_s"],
                      defines=[f"-D {k}={v}" for k, v in best["point"].items()])
        if verify:
            answer.update(_verify(scene_path, best["point"], knobs, params, sweep))
            answer["meets_budget"] = answer["verified_flip"] <= flip_budget
    options = [(answer.get("sweep_time_s"), "approximation:" + " ".join(answer["defines"]))]
    for name, key in (("path", "path_curve"), ("denoised_path", "denoised_curve")):
        reach = [p for p in result[key] if p["flip"] <= flip_budget]
        answer[name] = min(reach, key=lambda p: p["time_s"]) if reach else None
        if reach:
            with_denoiser = (f" with the denoiser (OIDN {result['denoise']})"
                             if name == "denoised_path" else "")
            options.append((answer[name]["time_s"],
                            f"path trace at {answer[name]['spp']} spp{with_denoiser}"))
    options = [(t, text) for t, text in options if t is not None]
    answer["answer"] = (min(options)[1] + f" ({min(options)[0]:.3g} s)" if options
                        else "nothing measured meets the budget")
    if out_dir is not None:
        with open(Path(out_dir) / "tune.json", "w") as f:
            json.dump(cmp._finite_or_none(answer), f, indent=2, allow_nan=False)
    return answer


def _verify(scene_path, point, knobs, params, sweep) -> dict:
    """Render the chosen point and the scene's defaults again from scratch (no cache) and
    measure both against a reference converged the same way (same seeds) as the sweep's."""
    settings = cmp.protocol_settings(scene_path, params)
    warm = sweep.get("warm_repeats", 3)
    chosen = measure_point(**_point_job(scene_path, settings, point, knobs, warm))
    default = measure_point(**_point_job(scene_path, settings, {}, knobs, warm))
    ref = cmp.converge_reference(scene_path, settings["xml_params"],
                                 settings["reference_integrator"],
                                 [chosen["image"], default["image"]],
                                 sweep.get("target_ratio", 0.2), sweep.get("max_spp", 1024),
                                 noise_floor=sweep.get("noise_floor"))
    del ref["scene"]
    flip_chosen, flip_default = ref["flips"]
    return {"verified_flip": flip_chosen, "verified_time_s": chosen["time_warm_s"],
            "default_flip": flip_default, "default_time_s": default["time_warm_s"],
            "speedup_vs_default": default["time_warm_s"] / chosen["time_warm_s"]}
