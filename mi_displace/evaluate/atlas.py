"""The trade-off atlas: every showcase scene's sweep on one self-contained HTML page.

:func:`atlas` runs :func:`mi_displace.evaluate.tradeoff.tradeoff` on every scene marked
``<!-- showcase -->`` that declares knobs (``<!-- tradeoff: NAME=V1,V2 -->``), each into
``DIR/<scene>/``, and writes ``DIR/index.html`` (plots and point images inlined as base64
PNG, no external file needed) and ``DIR/atlas.json``:

* a table per scene: every setting's FLIP, relMSE, warm time, whether it is on the Pareto
  front, and how long the path tracer needs to reach the same error;
* "which setting for which budget": for each time budget (a geometric ladder over the
  measured times), the most accurate setting of each scene that fits it, next to what the
  path tracer reaches in the same time.  On scenes whose knob is ``mode`` (bump, relief,
  VDM, ... on one geometry) that row is the choice between techniques.
"""
from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path

from mi_displace.evaluate import compare as cmp
from mi_displace.evaluate import tradeoff as tr

#: Time budgets per frame (seconds) of the "which setting for which budget" table.
BUDGETS_S = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0)


def atlas_scenes(scenes_dir) -> list[Path]:
    """Showcase scenes under ``scenes_dir`` that declare at least one trade-off knob."""
    from mi_displace.core.cli_args import showcase_scenes

    return [p for p in showcase_scenes(Path(scenes_dir)) if tr.declared_knobs(p)]


def path_flip_at(curve: list[dict], seconds: float) -> float | None:
    """FLIP of the path tracer's curve at ``seconds`` (the best point no slower; ``None`` if
    even its first point is slower)."""
    reachable = [p["flip"] for p in curve if p["time_s"] <= seconds]
    return min(reachable) if reachable else None


def budget_table(results: dict[str, dict], budgets=BUDGETS_S) -> list[dict]:
    """For each scene and budget: the most accurate setting within it, and the path tracer's.

    Returns:
        ``[{"scene", "budget_s", "setting" (label or None), "flip", "time_s", "path_flip"}]``.
    """
    rows = []
    for name, result in results.items():
        ok = [r for r in result["points"] if r["ok"]]
        for budget in budgets:
            fits = [r for r in ok if r["time_warm_s"] <= budget]
            best = min(fits, key=lambda r: r["flip"]) if fits else None
            rows.append({"scene": name, "budget_s": budget,
                         "setting": best["label"] if best else None,
                         "flip": best["flip"] if best else None,
                         "time_s": best["time_warm_s"] if best else None,
                         "path_flip": path_flip_at(result["path_curve"], budget)})
    return rows


def _img(path: Path, width: int | None = None) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    size = f' width="{width}"' if width else ""
    return f'<img src="data:image/png;base64,{data}"{size} alt="{html.escape(path.name)}">'


def _num(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    if isinstance(value, bool):
        return "yes" if value else ""
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return html.escape(str(value))


def _scene_section(name: str, result: dict, folder: Path) -> str:
    rows = []
    for index, r in enumerate(result["points"]):
        image = folder / f"point_{index}.png"
        thumb = _img(image, 96) if r["ok"] and image.is_file() else ""
        if r["ok"]:
            cross = (f"{_num(r['path_crossover_s'])} s ({_num(r['path_crossover_spp'])} spp)"
                     if r["path_crossover_s"] is not None else "not reached")
            cells = [_num(r["flip"], 4), _num(r["relmse"]), _num(r["time_warm_s"]),
                     _num(r["pareto"]), cross, _num(r["host"])]
        else:
            cells = [f'failed: {_num(r["error"])}'] + [""] * 5
        rows.append(f"<tr><td>{html.escape(r['label'])}</td><td>{thumb}</td>"
                    + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    capped = " (capped)" if result["spp_capped"] else ""
    target = ("" if result.get("noise_floor_target") is None
              else f" (target {_num(result['noise_floor_target'], 4)})")
    return (
        f'<h2 id="{html.escape(name)}">{html.escape(name)}</h2>\n'
        f"<p>reference: {html.escape(result['reference_integrator'])}, "
        f"{result['reference_spp']} spp{capped}, noise floor FLIP "
        f"{_num(result['noise_floor_flip'], 4)}{target}, {result['width']}×{result['height']}; "
        f"knobs: {html.escape(', '.join(k['name'] for k in result['knobs']))}</p>\n"
        f"{_img(folder / 'tradeoff.png', 640)}\n"
        "<table><tr><th>setting</th><th>image</th><th>FLIP</th><th>relMSE</th>"
        "<th>warm time (s)</th><th>Pareto</th><th>path needs</th><th>host</th></tr>\n"
        + "\n".join(rows) + "\n</table>\n")


def write_html(path: Path, results: dict[str, dict], out_dir: Path, failures: dict) -> Path:
    """The self-contained atlas page (module docstring)."""
    budget = budget_table(results)
    budget_rows = "\n".join(
        f"<tr><td>{html.escape(r['scene'])}</td><td>{_num(r['budget_s'])}</td>"
        f"<td>{_num(r['setting'])}</td><td>{_num(r['flip'], 4)}</td><td>{_num(r['time_s'])}</td>"
        f"<td>{_num(r['path_flip'], 4)}</td></tr>" for r in budget)
    sections = "\n".join(_scene_section(name, result, out_dir / name)
                         for name, result in results.items())
    failed = "".join(f"<li>{html.escape(n)}: {html.escape(e)}</li>" for n, e in failures.items())
    toc = " · ".join(f'<a href="#{html.escape(n)}">{html.escape(n)}</a>' for n in results)
    page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>mi_displace trade-off atlas</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}
table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #ccc;padding:2px 6px;
font-size:13px;text-align:right}}td:first-child{{text-align:left}}</style></head><body>
<h1>mi_displace trade-off atlas</h1>
<p>Error (mean FLIP against a converged path-traced reference) against warm time per frame
(build included) for every quality setting of every showcase scene, with the path tracer's
own error-vs-spp curve.  Made by <code>mi-displace atlas</code>; each scene's CSV/JSON is in
its folder.  Timings are wall seconds on the machine that rendered each point.</p>
<p>{toc}</p>
<h2>Which setting for which budget</h2>
<p>The most accurate measured setting within each time budget per frame, and the FLIP the
path tracer reaches in the same time (– : nothing fits).</p>
<table><tr><th>scene</th><th>budget (s)</th><th>setting</th><th>FLIP</th><th>time (s)</th>
<th>path FLIP</th></tr>
{budget_rows}
</table>
{f"<h2>Failed scenes</h2><ul>{failed}</ul>" if failed else ""}
{sections}
</body></html>
"""
    path.write_text(page)
    return path


def atlas(out_dir, scenes_dir=None, max_spp: int = 1024, cluster: str | None = None,
          cache_dir=None, progress: bool | None = False, warm_repeats: int = 3,
          noise_floor: float | None = None) -> dict:
    """Sweep every atlas scene and write ``index.html`` and ``atlas.json`` (module docstring).

    Each scene's reference doubles its spp until its two-seed noise floor is at most
    ``noise_floor`` (or a fifth of the sweep's smallest error), capped at ``max_spp``: the
    reference spp is chosen per scene.

    Returns:
        ``{"scenes": {name: tradeoff result}, "failures": {name: message}, "budgets": rows}``.
    """
    from mi_displace.core.resources import scenes_dir as default_scenes_dir

    scenes_dir = Path(scenes_dir) if scenes_dir is not None else default_scenes_dir()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results, failures = {}, {}
    for path in atlas_scenes(scenes_dir):
        name = path.relative_to(scenes_dir).with_suffix("").as_posix()
        try:
            results[name] = tr.tradeoff(path, tr.declared_knobs(path), out_dir=out_dir / name,
                                        max_spp=max_spp, cluster=cluster, cache_dir=cache_dir,
                                        progress=progress, warm_repeats=warm_repeats,
                                        noise_floor=noise_floor)
        except (ValueError, FileNotFoundError) as e:  # one broken scene must not hide the rest
            failures[name] = " ".join(str(e).split())
    write_html(out_dir / "index.html", results, out_dir, failures)
    record = {"scenes": results, "failures": failures, "budgets": budget_table(results)}
    with open(out_dir / "atlas.json", "w") as f:
        json.dump(cmp._finite_or_none(record), f, indent=2, allow_nan=False)
    return record
