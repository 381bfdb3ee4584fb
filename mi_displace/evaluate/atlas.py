"""The trade-off atlas: what to pick for each showcase scene and time budget.

:func:`atlas` runs :func:`mi_displace.evaluate.tradeoff.tradeoff` on every scene marked
``<!-- showcase -->`` that declares knobs (``<!-- tradeoff: NAME=V1,V2 -->``), each into
``DIR/<scene>/``, and writes ``DIR/index.html`` and ``DIR/atlas.json``.  The page is a
folder that works where it is copied: images are the sweep's own ``<scene>/point_<i>.png``
and ``<scene>/tradeoff.png``, linked relatively, each thumbnail opening its image at full
size.

Options, by name
----------------
Every measured point is an *option* named after what it renders (:func:`technique_name`):
the innermost technique plugin of the scene's approximation side under the point's values
(one of mi_displace's shape, BSDF or volume plugins, or Mitsuba's :data:`MITSUBA_TECHNIQUES`),
its enumerated variant as built (``ddm maps``, ``slicing best``: string parameters with
choices, read from the shape's ``build_stats``), the values of the other knobs
(``map_resolution=64``) and the integrator when it is not ``raster``; ``mode=reference``
points are "true geometry: ...".  Beside them, every point of the path tracer's own curve
is an option (``path 16 spp``), and of the denoised curve (``path 16 spp + OIDN high``).

Budgets
-------
For each scene and time budget per frame (:data:`BUDGETS_S`), :func:`budget_table` gives the
most accurate approximation within it, the most accurate raw and denoised path points within
it, the pick (the most accurate of all) and a verdict sentence.  Each budget is also given
in units measured in the same run (:func:`units`): × the render time of one path sample per
pixel (the raw curve's 1-spp point, build excluded) and × bump mapping's frame time (the
scene's fastest ``bumpmap`` option; ``None`` on scenes without one).
"""
from __future__ import annotations

import html
import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from mi_displace.evaluate import compare as cmp
from mi_displace.evaluate import tradeoff as tr

#: Time budgets per frame (seconds) of the "what to pick" tables.
BUDGETS_S = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0)
#: Mitsuba's own plugins that stand in for relief (by shading alone), named like ours.
MITSUBA_TECHNIQUES = ("bumpmap", "normalmap")
#: Plugin kinds that are a technique (textures feed them; integrators draw them).
TECHNIQUE_KINDS = ("shape", "bsdf", "volume")
#: Thumbnail width on the page (pixels); a click opens the image at full size.
THUMB_PX = 128
#: What an option is: an approximation setting, a raw or a denoised path-curve point.
KINDS = ("approximation", "path", "denoised path")
#: Film side (pixels) of the pass that measures a scene's view (:func:`scene_facts`).
FACTS_RES = 48
#: A pixel is seen at a grazing angle beyond this angle between its view ray and the
#: surface's geometric normal (degrees).
GRAZING_DEG = 70.0
#: A covered pixel is on an outline when a 4-neighbour is uncovered or the second
#: difference of inverse depth across it exceeds this fraction of its inverse depth.
DEPTH_JUMP = 0.1
#: The kinds of problem a scene poses (:func:`scene_facts`), in the order of the guide.
BASE_KINDS = ("height field on a parametric base", "height field on a mesh",
              "tiles of arbitrary geometry", "volume")


def atlas_scenes(scenes_dir) -> list[Path]:
    """Showcase scenes under ``scenes_dir`` that declare at least one trade-off knob."""
    from mi_displace.core.cli_args import showcase_scenes

    return [p for p in showcase_scenes(Path(scenes_dir)) if tr.declared_knobs(p)]


def path_flip_at(curve: list[dict], seconds: float) -> float | None:
    """FLIP of the path tracer's curve at ``seconds`` (the best point no slower; ``None`` if
    even its first point is slower)."""
    reachable = [p["flip"] for p in curve if p["time_s"] <= seconds]
    return min(reachable) if reachable else None


def technique_plugins() -> dict:
    """Plugin name -> its :class:`~mi_displace.core.properties.PluginSpec` (``None`` for
    :data:`MITSUBA_TECHNIQUES`) of every plugin that is a technique."""
    from mi_displace.core.reference import declared_specs

    found = {s.plugin: s for s in declared_specs() if s.kind in TECHNIQUE_KINDS}
    return {**found, **{name: None for name in MITSUBA_TECHNIQUES}}


def _substitute(text: str, values: dict[str, str]) -> str:
    return re.sub(r"\$(\w+)", lambda m: values.get(m.group(1), m.group(0)), text)


def scene_elements(scene_path, values: dict[str, str]) -> list[tuple[str, str, dict]]:
    """Every typed element of a scene file, ``$name`` replaced by ``values`` and includes
    followed (relative to the including file), depth first in document order.

    Returns:
        ``[(tag, type, {child name: value of its string/integer/float/boolean children})]``.
    """
    found = []

    def walk(element, folder: Path):
        for child in element:
            if child.tag == "include":
                path = folder / _substitute(child.get("filename", ""), values)
                walk(ET.parse(path).getroot(), path.parent)
            elif child.get("type") is not None:
                props = {c.get("name"): _substitute(c.get("value", ""), values) for c in child
                         if c.tag in ("string", "integer", "float", "boolean")}
                found.append((child.tag, _substitute(child.get("type"), values), props))
                walk(child, folder)
            else:
                walk(child, folder)

    scene_path = Path(scene_path)
    walk(ET.parse(scene_path).getroot(), scene_path.parent)
    return found


def technique_name(scene_path, knobs: list[dict], row: dict, plugins: dict | None = None) -> str:
    """The name of one measured point (module docstring, "Options, by name").

    Args:
        scene_path: the scene file.
        knobs: the sweep's knobs (``result["knobs"]``: ``name``, ``values``, ``kind``).
        row: the point (``point``: its knob values; ``build_stats``: its shapes' stats).
        plugins: :func:`technique_plugins` (computed when ``None``).
    """
    plugins = technique_plugins() if plugins is None else plugins
    settings = cmp.protocol_settings(scene_path)
    kinds = {k["name"]: k["kind"] for k in knobs}
    point = row["point"]
    mode = point.get("mode", "approximation")
    integrator = point.get("approximation_integrator", settings["approximation_integrator"])
    values = {**cmp.scene_defaults(scene_path),
              **{k: str(v) for k, v in point.items() if kinds.get(k) == "define"},
              "mode": mode, "integrator": integrator}
    techniques = [(t, props) for _, t, props in scene_elements(scene_path, values) if t in plugins]
    if not techniques:
        core = "no technique plugin"
    else:
        plugin, _ = techniques[-1]
        spec = plugins[plugin]
        variants = [] if spec is None else [
            stats[p.name] for p in spec.all_params() if p.type == "string" and p.choices
            for stats in (row.get("build_stats") or []) if isinstance(stats.get(p.name), str)]
        core = " ".join([plugin, *dict.fromkeys(variants)])
    others = [f"{k}={v}" for k, v in point.items()
              if k not in ("mode", "approximation_integrator")]
    name = ", ".join([core, *others])
    if mode == "reference":
        name = f"true geometry: {name}"
    return name if integrator == "raster" else f"{name} ({integrator})"


def _base_facts(scene_path, plugins: dict) -> dict:
    """``base_kind`` (:data:`BASE_KINDS`), ``base`` and ``closed`` / ``open_edges`` of a
    scene, from the technique elements of its approximation side, then its reference side,
    at the scene's defaults."""
    from mi_displace.core.mesh_io import load_uv_mesh
    from mi_displace.core.surfaces import BASES
    from mi_displace.vdm.mesh_curvature import open_edge_count

    scene_path = Path(scene_path)
    defaults = cmp.scene_defaults(scene_path)
    elements = [e for mode in ("approximation", "reference")
                for e in scene_elements(scene_path, {**defaults, "mode": mode}) if e[1] in plugins]
    types = {t for _, t, _ in elements}
    if any(tag == "volume" for tag, _, _ in elements):
        return {"base_kind": BASE_KINDS[3], "base": "volume", "closed": None, "open_edges": None}
    def base_of(plugin, props):  # a shape plugin without a `base` parameter takes meshes only
        spec = plugins[plugin]
        meshes_only = spec is not None and spec.kind == "shape" and not any(
            p.name == "base" for p in spec.all_params())
        return props.get("base") or ("mesh" if props.get("filename") or meshes_only else None)

    based = [(base_of(t, props), props) for _, t, props in elements if base_of(t, props)]
    base, props = based[0] if based else (None, {})
    filename = props.get("filename")
    if base == "mesh" and filename:
        positions, _, _, faces = load_uv_mesh(str(scene_path.parent / filename))
        open_edges = open_edge_count(positions, faces)
        closed = open_edges == 0
    else:
        cls = BASES.get(base)
        closed = None if cls is None else cls.periodic_u and (cls.periodic_v or cls.poles)
        open_edges = None
    kind = BASE_KINDS[2] if "ddm" in types else BASE_KINDS[1] if base == "mesh" else BASE_KINDS[0]
    return {"base_kind": kind, "base": base, "closed": closed, "open_edges": open_edges}


def _view_facts(scene_path, result: dict) -> dict:
    """How the scene is seen: its fastest measured point loaded and drawn by Mitsuba's
    ``aov`` integrator (depth, geometric normal, position; one ray per pixel at
    :data:`FACTS_RES`² when the scene has a ``res`` parameter)."""
    import mitsuba as mi
    import numpy as np

    from mi_displace.render import scene as scenes

    ok = [r for r in result["points"] if r["ok"]]
    fastest = min(ok, key=lambda r: r["time_warm_s"])
    knobs = [tr.Knob(k["name"], tuple(k["values"]), k["kind"]) for k in result["knobs"]]
    job = tr._point_job(scene_path, cmp.protocol_settings(scene_path), fastest["point"], knobs, 3)
    res = {"res": str(FACTS_RES)} if "res" in cmp.scene_defaults(scene_path) else {}
    scene, _ = scenes.load(scene_path, **{**job["xml_params"], **res}, mode=job["mode"],
                           integrator=job["integrator"])
    scenes.apply_edits(scene, job["edits"])
    aovs = mi.load_dict({"type": "aov", "aovs": "dd:depth,nn:geo_normal,pp:position"})
    image = np.asarray(mi.render(scene, integrator=aovs, spp=1))
    camera = np.asarray(scene.sensors()[0].world_transform().translation()).ravel()
    depth, normal, position = image[..., 0], image[..., 1:4], image[..., 4:7]
    covered = depth > 0
    to_camera = camera - position
    to_camera /= np.maximum(np.linalg.norm(to_camera, axis=-1, keepdims=True), 1e-12)
    cosine = np.abs(np.sum(normal * to_camera, axis=-1)) / np.maximum(
        np.linalg.norm(normal, axis=-1), 1e-12)
    angle = np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0)))[covered]
    # inverse depth is linear in screen space across a plane: its second difference
    # stays near 0 on smooth surfaces and jumps where one surface occludes another
    inverse = np.pad(np.where(covered, 1.0 / np.maximum(depth, 1e-12), 0.0), 1)
    centre = inverse[1:-1, 1:-1]
    outline = np.zeros_like(covered)
    for before, after in ((inverse[:-2, 1:-1], inverse[2:, 1:-1]),
                          (inverse[1:-1, :-2], inverse[1:-1, 2:])):
        outline |= (before <= 0) | (after <= 0)
        outline |= np.abs(before + after - 2 * centre) > DEPTH_JUMP * centre
    outline &= covered
    count = max(int(covered.sum()), 1)
    return {"coverage": float(covered.mean()),
            "view_angle_deg": float(np.median(angle)) if angle.size else None,
            "grazing_share": float(np.mean(angle > GRAZING_DEG)) if angle.size else None,
            "outline_share": float(outline.sum() / count), "facts_from": fastest["label"]}


def scene_facts(scene_path, result: dict) -> dict:
    """What kind of problem a scene poses, measured (for the guide, :func:`choosing_markdown`).

    Returns:
        ``base_kind`` (:data:`BASE_KINDS`: a ``ddm`` plugin makes tiles, a volume plugin a
        volume, a ``mesh`` base or ``filename`` a height field on a mesh, else on a
        parametric base), ``base``, ``closed`` (a mesh: no edge used by one face once
        vertices are welded, ``open_edges`` counts them; a parametric base: periodic in u
        and in v or closed by poles; ``None`` for a volume), and for surfaces how it is
        seen at :data:`FACTS_RES`² from its fastest measured point: ``coverage`` (share of
        pixels on the geometry), ``view_angle_deg`` (median angle between view ray and
        geometric normal over them), ``grazing_share`` (share beyond :data:`GRAZING_DEG`),
        ``outline_share`` (share of them on an outline, the object's own or where it hides
        itself: :data:`DEPTH_JUMP`) and
        ``facts_from`` (that point's label).
    """
    facts = _base_facts(scene_path, technique_plugins())
    if facts["base_kind"] != BASE_KINDS[3]:
        facts.update(_view_facts(scene_path, result))
    return facts


def scene_file(name: str, result: dict, scenes_dir=None) -> Path:
    """The scene file of an atlas entry: the one its result names, else the scene of that
    name under ``scenes_dir`` (default: the packaged scenes) — for an ``atlas.json`` made on
    another machine."""
    path = Path(result["scene"])
    if path.is_file():
        return path
    from mi_displace.core.resources import scenes_dir as packaged

    return Path(scenes_dir or packaged()) / f"{name}.xml"


def options(name: str, result: dict, scenes_dir=None) -> list[dict]:
    """Every option of a scene's sweep (module docstring).

    Returns:
        ``[{"name", "kind" (:data:`KINDS`), "flip", "time_s", "index" (the point's index,
        ``None`` for a path point), "spp" (path points)}]``: the rendered points in sweep
        order, then the raw and the denoised curve in increasing spp.
    """
    plugins = technique_plugins()
    path = scene_file(name, result, scenes_dir)
    found = [{"name": technique_name(path, result["knobs"], r, plugins), "kind": KINDS[0],
              "flip": r["flip"], "time_s": r["time_warm_s"], "index": i, "spp": None}
             for i, r in enumerate(result["points"]) if r["ok"]]
    integrator = result["reference_integrator"]
    for kind, key, suffix in ((KINDS[1], "path_curve", ""),
                              (KINDS[2], "denoised_curve", f" + OIDN {result.get('denoise')}")):
        found += [{"name": f"{integrator} {p['spp']} spp{suffix}", "kind": kind,
                   "flip": p["flip"], "time_s": p["time_s"], "index": None, "spp": p["spp"]}
                  for p in result.get(key) or []]
    return found


def units(result: dict, found: list[dict]) -> dict:
    """The portable time units of a scene, measured in its sweep (seconds; ``None`` when
    not measured): ``path_spp_s``, the raw curve's 1-spp render (build excluded), and
    ``bump_s``, the fastest ``bumpmap`` option's frame."""
    one = [p["render_s"] for p in result["path_curve"] if p["spp"] == 1]
    bump = [o["time_s"] for o in found
            if o["kind"] == KINDS[0] and o["name"].split(",")[0].split(" ")[0] == "bumpmap"]
    return {"path_spp_s": one[0] if one else None, "bump_s": min(bump) if bump else None}


def _best(found: list[dict], kind: str, budget: float) -> dict | None:
    fits = [o for o in found if o["kind"] == kind and o["time_s"] <= budget]
    return min(fits, key=lambda o: (o["flip"], o["time_s"])) if fits else None


def verdict(budget: float, picks: dict, noise_floor: float = 0.0) -> str:
    """One plain sentence for a budget: what to pick and what it beats.

    Args:
        budget: seconds per frame.
        picks: kind (:data:`KINDS`) -> the most accurate option of that kind within the
            budget, or ``None``.
        noise_floor: the reference's two-seed noise floor (FLIP): a runner-up closer to
            the pick than that is called a tie.
    """
    fits = sorted((o for o in picks.values() if o is not None),
                  key=lambda o: (o["flip"], o["time_s"]))
    if not fits:
        return f"Nothing measured renders a frame within {budget:.3g} s."
    best, others = fits[0], fits[1:]
    missing = [k for k, o in picks.items() if o is None]
    text = f"Pick {best['name']} (FLIP {best['flip']:.3g}, {best['time_s']:.3g} s)"
    if others:
        text += "; it beats " + " and ".join(f"{o['name']} ({o['flip']:.3g})" for o in others)
        if others[0]["flip"] - best["flip"] < noise_floor:
            text += (f"; {others[0]['name']} is within the reference's noise floor "
                     f"({noise_floor:.2g}) of it: a tie")
    if missing:
        text += "; no " + " or ".join(missing) + " frame fits"
    return text + "."


def budget_table(results: dict[str, dict], budgets=BUDGETS_S, scenes_dir=None) -> list[dict]:
    """For each scene and budget: the best option of each kind within it, and the pick.

    Returns:
        ``[{"scene", "budget_s", "budget_path_spp" (budget / path_spp_s), "budget_bump"
        (budget / bump_s), "setting" (the best approximation's point label), "technique" (its
        name), "flip", "time_s", "path" / "denoised_path" (the best raw / denoised curve
        point's name), "path_flip", "denoised_path_flip", "pick", "pick_kind", "pick_flip",
        "verdict"}]``; ``None`` where nothing fits or nothing was measured.
    """
    rows = []
    for name, result in results.items():
        found = options(name, result, scenes_dir)
        unit = units(result, found)
        for budget in budgets:
            picks = {kind: _best(found, kind, budget) for kind in KINDS
                     if kind != KINDS[2] or result.get("denoised_curve")}
            approx, path, den = (picks.get(k) for k in KINDS)
            fits = [o for o in picks.values() if o is not None]
            pick = min(fits, key=lambda o: (o["flip"], o["time_s"])) if fits else None

            def get(option, key):
                return None if option is None else option[key]

            rows.append({
                "scene": name, "budget_s": budget,
                "budget_path_spp": budget / unit["path_spp_s"] if unit["path_spp_s"] else None,
                "budget_bump": budget / unit["bump_s"] if unit["bump_s"] else None,
                "setting": (None if approx is None
                            else result["points"][approx["index"]]["label"]),
                "technique": get(approx, "name"), "flip": get(approx, "flip"),
                "time_s": get(approx, "time_s"),
                "path": get(path, "name"), "path_flip": get(path, "flip"),
                "denoised_path": get(den, "name"), "denoised_path_flip": get(den, "flip"),
                "pick": get(pick, "name"), "pick_kind": get(pick, "kind"),
                "pick_flip": get(pick, "flip"),
                "verdict": verdict(budget, picks, result.get("noise_floor_flip") or 0.0)})
    return rows


def _num(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    if isinstance(value, bool):
        return "yes" if value else ""
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return html.escape(str(value))


def _thumb(href: str, alt: str, width: int = THUMB_PX) -> str:
    """A thumbnail that opens the image at full size (``href``: relative to the page)."""
    href = html.escape(href)
    return f'<a href="{href}"><img src="{href}" width="{width}" alt="{html.escape(alt)}"></a>'


def _scene_section(name: str, result: dict, out_dir: Path, budgets: list[dict],
                   found: list[dict]) -> str:
    unit = units(result, found)
    rows = []
    names = {o["index"]: o["name"] for o in found if o["index"] is not None}
    for index, r in enumerate(result["points"]):
        label = html.escape(names.get(index, r["label"]))
        image = f"{name}/point_{index}.png"
        if not r["ok"]:
            rows.append(f"<tr><td>{label}</td><td colspan=\"7\">failed: {_num(r['error'])}</td></tr>")
            continue
        thumb = _thumb(image, names[index]) if (out_dir / image).is_file() else ""
        cross = [(f"{_num(r[f'{c}_crossover_s'])} s ({_num(r[f'{c}_crossover_spp'])} spp)"
                  if r.get(f"{c}_crossover_s") is not None else "not reached")
                 for c in ("path", "denoised")]
        if not result.get("denoised_curve"):
            cross[1] = "–"
        units_cell = (f"{_num(r['time_warm_s'] / unit['path_spp_s'])}"
                      if unit["path_spp_s"] else "–")
        cells = [thumb, _num(r["flip"], 4), _num(r["time_warm_s"]), units_cell,
                 _num(r["pareto"]), *cross]
        rows.append(f"<tr><td>{label}</td>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    budget_rows = "\n".join(
        f"<tr><td>{_num(b['budget_s'])}</td><td>{_num(b['budget_path_spp'])}</td>"
        f"<td>{_num(b['budget_bump'])}</td><td>{_num(b['pick'])}</td>"
        f"<td>{_num(b['pick_flip'], 4)}</td><td>{html.escape(b['verdict'])}</td></tr>"
        for b in budgets if b["scene"] == name)
    capped = " (capped)" if result["spp_capped"] else ""
    plot = (_thumb(f"{name}/tradeoff.png", f"{name}: error against time", 480)
            if (out_dir / name / "tradeoff.png").is_file() else "")
    return (
        f'<h2 id="{html.escape(name)}">{html.escape(name)}</h2>\n'
        f"<p>Reference: {html.escape(result['reference_integrator'])}, "
        f"{result['reference_spp']} spp{capped}, noise floor FLIP "
        f"{_num(result['noise_floor_flip'], 4)}, {result['width']}×{result['height']} pixels. "
        f"One path sample per pixel renders in {_num(unit['path_spp_s'])} s; "
        + (f"bump mapping's frame takes {_num(unit['bump_s'])} s." if unit["bump_s"]
           else "no bump mapping option was measured.") + "</p>\n"
        "<table><tr><th>budget (s)</th><th>× 1-spp path render</th><th>× bump frame</th>"
        "<th>pick</th><th>its FLIP</th><th>verdict</th></tr>\n"
        f"{budget_rows}\n</table>\n{plot}\n"
        "<table><tr><th>option</th><th>image</th><th>FLIP</th><th>time (s)</th>"
        "<th>× 1-spp path render</th><th>Pareto</th><th>path needs</th>"
        "<th>denoised path needs</th></tr>\n" + "\n".join(rows) + "\n</table>\n")


def write_html(path: Path, results: dict[str, dict], out_dir: Path, failures: dict,
               budgets: list[dict] | None = None, scenes_dir=None) -> Path:
    """The atlas page (module docstring): ``path`` in ``out_dir``, images linked from
    ``out_dir/<scene>/``."""
    out_dir = Path(out_dir)
    budgets = budget_table(results, scenes_dir=scenes_dir) if budgets is None else budgets
    sections = "\n".join(_scene_section(name, result, out_dir, budgets,
                                        options(name, result, scenes_dir))
                         for name, result in results.items())
    failed = "".join(f"<li>{html.escape(n)}: {html.escape(e)}</li>" for n, e in failures.items())
    toc = " · ".join(f'<a href="#{html.escape(n)}">{html.escape(n)}</a>' for n in results)
    summary_budgets = [b for b in BUDGETS_S if any(r["budget_s"] == b for r in budgets)]
    summary = "\n".join(
        f"<tr><td>{html.escape(n)}</td>" + "".join(
            f"<td>{_num(r['pick'])} ({_num(r['pick_flip'])})</td>" if r["pick"] else "<td>–</td>"
            for r in budgets if r["scene"] == n) + "</tr>" for n in results)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>mi_displace trade-off atlas</title>
<link rel="icon" href="data:,">
<style>body{{font-family:sans-serif;max-width:1200px;margin:auto}}
table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #ccc;padding:2px 6px;
font-size:13px;text-align:right}}td:first-child,td:last-child{{text-align:left}}
img{{vertical-align:middle}}</style></head><body>
<h1>mi_displace trade-off atlas</h1>
<p>What to pick for each showcase scene and time budget per frame. Every option is measured
against a converged path-traced reference (mean FLIP; lower is better) with its warm time
per frame (build included): the approximations by technique name, and path tracing itself,
raw (<i>path N spp</i>) and denoised (<i>path N spp + OIDN</i>). Budgets are in seconds and
in units a reader can carry to another machine, measured in the same run: × the render time
of one path sample per pixel and × bump mapping's frame time. Click a thumbnail for the
full image. Made by <code>mi-displace atlas</code>; each scene's CSV/JSON is in its
folder.</p>
<p>{toc}</p>
<h2>What to pick</h2>
<p>The most accurate option within each budget (its FLIP in brackets; – : nothing fits).</p>
<table><tr><th>scene</th>{"".join(f"<th>{_num(b)} s</th>" for b in summary_budgets)}</tr>
{summary}
</table>
{f"<h2>Failed scenes</h2><ul>{failed}</ul>" if failed else ""}
{sections}
</body></html>
"""
    path = Path(path)
    path.write_text(page)
    return path


def atlas(out_dir, scenes_dir=None, max_spp: int = 1024, cluster: str | None = None,
          cache_dir=None, progress: bool | None = False, warm_repeats: int = 3,
          noise_floor: float | None = None, denoise: str | None = None) -> dict:
    """Sweep every atlas scene and write ``index.html`` and ``atlas.json`` (module docstring).

    Each scene's reference doubles its spp until its two-seed noise floor is at most
    ``noise_floor`` (or a fifth of the sweep's smallest error), capped at ``max_spp``: the
    reference spp is chosen per scene.  ``denoise``: OIDN quality of the denoised path
    curve measured beside the raw one (:func:`tradeoff.tradeoff`).

    Returns:
        ``{"scenes": {name: tradeoff result, each point with its "technique" name},
        "units": {name: :func:`units`}, "facts": {name: :func:`scene_facts`},
        "failures": {name: message}, "budgets": rows}``.
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
                                        noise_floor=noise_floor, denoise=denoise)
        except (ValueError, FileNotFoundError) as e:  # one broken scene must not hide the rest
            failures[name] = " ".join(str(e).split())
    budgets = budget_table(results, scenes_dir=scenes_dir)
    write_html(out_dir / "index.html", results, out_dir, failures, budgets, scenes_dir)
    found = {name: options(name, result, scenes_dir) for name, result in results.items()}
    for name, result in results.items():
        for option in found[name]:
            if option["index"] is not None:
                result["points"][option["index"]]["technique"] = option["name"]
    record = {"scenes": results, "units": {n: units(r, found[n]) for n, r in results.items()},
              "facts": {n: scene_facts(scene_file(n, r, scenes_dir), r)
                        for n, r in results.items()},
              "failures": failures, "budgets": budgets}
    with open(out_dir / "atlas.json", "w") as f:
        json.dump(cmp._finite_or_none(record), f, indent=2, allow_nan=False)
    return record


#: Where ``python -m mi_displace.evaluate.atlas`` reads the atlas and writes the guide.
DOCS = Path(__file__).resolve().parents[2] / "docs"


def _md(value, digits: int = 3) -> str:
    return "–" if value is None else f"{value:.{digits}g}" if isinstance(value, float) else str(value)


def _remake_command(record: dict) -> str:
    """The ``mi-displace atlas`` command line that re-makes ``record`` (its settings)."""
    first = next(iter(record["scenes"].values()))
    parts = ["mi-displace atlas --out docs/atlas"]
    if first.get("noise_floor_target") is not None:
        parts.append(f"--noise-floor {first['noise_floor_target']:g}")
    parts.append(f"--max-spp {first['max_spp']}")
    if first.get("denoise"):
        parts.append(f"--denoise {first['denoise']}")
    return " ".join(parts)


def _scene_lines(name: str, result: dict, facts: dict, budgets: list[dict]) -> list[str]:
    """A scene's paragraph of the guide: what it is, then its budget rows where something fits."""
    base = facts["base"] or "unknown base"
    closed = ("" if facts["base_kind"] == BASE_KINDS[3] else
              {True: ", closed", False: ", open", None: ", closedness not measured"}[facts["closed"]])
    seen = ("" if facts.get("view_angle_deg") is None else
            f"; seen at a median {facts['view_angle_deg']:.0f}° from the normal, "
            f"{100 * facts['grazing_share']:.0f} % of its pixels beyond {GRAZING_DEG:.0f}°, "
            f"{100 * facts['outline_share']:.0f} % on an outline")
    knobs = " ".join(f"--knob {k['name']}={','.join(k['values'])}" for k in result["knobs"])
    denoise = f" --denoise {result['denoise']}" if result.get("denoise") else ""
    lines = [f"### `{name}`", "",
             f"{base}{closed}{seen}. Reference: {result['reference_integrator']}, "
             f"{result['reference_spp']} spp, noise floor FLIP {result['noise_floor_flip']:.3g}, "
             f"{result['width']}×{result['height']}. Re-made alone by:", "", "```console",
             f"mi-displace tradeoff scenes/{name}.xml {knobs}{denoise} --max-spp "
             f"{result['max_spp']} --out DIR", "```", "",
             "| budget (s) | × 1-spp path | pick | FLIP | best approximation (FLIP) | "
             "path (FLIP) | denoised path (FLIP) |", "|---|---|---|---|---|---|---|"]
    for b in budgets:
        if b["scene"] != name or b["pick"] is None:
            continue
        lines.append(
            f"| {_md(b['budget_s'])} | {_md(b['budget_path_spp'])} | {b['pick']} | "
            f"{_md(b['pick_flip'])} | {b['technique'] or '–'} ({_md(b['flip'])}) | "
            f"{b['path'] or '–'} ({_md(b['path_flip'])}) | "
            f"{b['denoised_path'] or '–'} ({_md(b['denoised_path_flip'])}) |")
    return lines + [""]


def choosing_markdown(record: dict, scenes_dir=None) -> str:
    """The "Choosing a technique" guide (``docs/choosing.md``) from an atlas record
    (``atlas.json``): scenes grouped by base kind, then open or closed base; each with its
    measured view, its budget rows (:func:`budget_table`) and the commands that re-make
    them; then the picks by view angle and by budget."""
    results, facts = record["scenes"], record["facts"]
    budgets = budget_table(results, scenes_dir=scenes_dir)
    lines = [
        "# Choosing a technique", "",
        "Generated from the trade-off atlas (<a href=\"atlas/index.html\">the atlas page</a>, "
        "`docs/atlas/atlas.json`) by `python -m mi_displace.evaluate.atlas`; do not edit by "
        "hand.  Every number is measured; the atlas is re-made (minutes to an hour) by:", "",
        "```console", _remake_command(record), "```", "",
        "Each option is measured against a converged path-traced reference: mean FLIP (lower "
        "is better) and warm time per frame, build included, on the machine that made the "
        "atlas.  Budgets are seconds per frame and, to carry them to another machine, × the "
        "render time of one path sample per pixel measured in the same run.  *pick* is the "
        "most accurate option within the budget: an approximation by its technique name, "
        "path tracing raw (`path N spp`) or denoised (`path N spp + OIDN`). Only budgets "
        "within which something renders are listed; "
        "<a href=\"atlas/index.html\">the atlas page</a> has "
        "every option with its image and the verdict sentences.", ""]
    for kind in BASE_KINDS:
        names = [n for n in results if facts[n]["base_kind"] == kind]
        if not names:
            continue
        lines += [f"## {kind[0].upper()}{kind[1:]}", ""]
        for closed, title in ((True, "Closed base"), (False, "Open base"),
                              (None, "Closedness not measured" if kind != BASE_KINDS[3] else "")):
            group = [n for n in names if facts[n]["closed"] is closed]
            if not group:
                continue
            if title:
                lines += [f"**{title}**: " + ", ".join(f"`{n}`" for n in group) + ".", ""]
            for name in group:
                lines += _scene_lines(name, results[name], facts[name], budgets)
    seen = sorted((n for n in results if facts[n].get("view_angle_deg") is not None),
                  key=lambda n: facts[n]["view_angle_deg"])
    middle = sorted({b["budget_s"] for b in budgets})
    one = min(middle, key=lambda b: abs(math.log(b)))  # the budget nearest 1 s
    lines += ["## By view angle and silhouettes", "",
              f"Scenes from the most frontal to the most grazing view, with their pick at "
              f"{_md(one)} s per frame; *outline* is the share of the object's pixels on an "
              f"outline (its silhouette or where it hides itself), where a technique that "
              f"only shades the base (bump, relief, horizon) cannot be right.", "",
              "| scene | median view angle | beyond 70° | outline | pick at "
              f"{_md(one)} s (FLIP) | best approximation (FLIP) |", "|---|---|---|---|---|---|"]
    for n in seen:
        b = next(r for r in budgets if r["scene"] == n and r["budget_s"] == one)
        f = facts[n]
        lines.append(f"| `{n}` | {f['view_angle_deg']:.0f}° | {100 * f['grazing_share']:.0f} % | "
                     f"{100 * f['outline_share']:.0f} % | {b['pick'] or '–'} "
                     f"({_md(b['pick_flip'])}) | {b['technique'] or '–'} ({_md(b['flip'])}) |")
    lines += ["", "## By budget", "",
              "How often each kind of option is the pick, over the scenes of the atlas:", "",
              "| budget (s) | " + " | ".join(KINDS) + " | nothing fits |",
              "|---|" + "---|" * (len(KINDS) + 1)]
    for budget in middle:
        rows = [r for r in budgets if r["budget_s"] == budget]
        counts = [sum(r["pick_kind"] == k for r in rows) for k in KINDS]
        lines.append(f"| {_md(budget)} | " + " | ".join(map(str, counts))
                     + f" | {sum(r['pick'] is None for r in rows)} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m mi_displace.evaluate.atlas [ATLAS_JSON [OUT_MD]]``: write the guide
    (default: ``docs/atlas/atlas.json`` to ``docs/choosing.md`` of the checkout)."""
    import sys

    import mi_displace

    argv = sys.argv[1:] if argv is None else argv
    source = Path(argv[0]) if argv else DOCS / "atlas" / "atlas.json"
    target = Path(argv[1]) if len(argv) > 1 else DOCS / "choosing.md"
    mi_displace.init()
    target.write_text(choosing_markdown(json.loads(source.read_text())))
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
