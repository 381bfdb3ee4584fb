"""The atlas's options by name, its budget table, and its page in a real browser.

Names come from the scene files (the technique plugin each point renders) and the points'
build statistics; the pick within a budget is checked by brute force over every option of a
synthetic sweep (approximation points, raw and denoised path points with random errors and
times), and the portable units against the curve's own 1-spp render time.  The page, with
the sweep's images and plot written beside it, is loaded in headless Chromium: it loads,
every image resolves (``naturalWidth > 0``) and nothing is written to the console; a copy
with a missing image and a console error shows the check sees both.
"""
import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

import mi_displace
from mi_displace.core.resources import scene_path
from mi_displace.evaluate import atlas

MODE = [{"name": "mode", "values": ["approximation", "bump", "relief", "reference"],
         "kind": "define"}]


@pytest.fixture(scope="module", autouse=True)
def _variant():
    mi_displace.init("llvm_ad_rgb")


@pytest.mark.parametrize("scene, knobs, point, stats, expected", [
    # the BSDF inside vdm_mesh is the technique; the comparison's mode picks the part file
    ("vdm_torus.xml", MODE, {"mode": "approximation"}, [], "vdm"),
    ("vdm_torus.xml", MODE, {"mode": "bump"}, [], "bumpmap"),
    ("vdm_torus.xml", MODE, {"mode": "relief"}, [], "relief"),
    ("vdm_torus.xml", MODE, {"mode": "reference"}, [], "true geometry: displaced"),
    # the variant as built (build_stats) and the other knobs' values
    ("ddm_thorns_sphere.xml", [{"name": "map_resolution", "values": ["64"], "kind": "define"}],
     {"map_resolution": "64"}, [{"type": "DDM", "mode": "maps"}], "ddm maps, map_resolution=64"),
    ("slicing_donut.xml", MODE, {"mode": "approximation"},
     [{"type": "Slicing", "direction": "best"}], "slicing best"),
    # an integrator other than raster is named
    ("volume_nucleon_pull.xml", [{"name": "spacing", "values": ["2"], "kind": "define"}],
     {"spacing": "2"}, [], "displaced_volume, spacing=2 (volume_slicer)"),
])
def test_technique_names(scene, knobs, point, stats, expected):
    row = {"point": point, "build_stats": stats}
    assert atlas.technique_name(scene_path(scene), knobs, row) == expected


def _synthetic(seed: int) -> dict:
    """A sweep of the test scene with random errors and times, raw and denoised curves."""
    rng = np.random.default_rng(seed)
    values = ["8", "16", "48"]
    points = [{"point": {"resolution": v}, "label": f"resolution={v}", "ok": True,
               "flip": float(rng.uniform(0.01, 0.2)), "time_warm_s": float(rng.uniform(0.005, 5)),
               "build_stats": [], "pareto": True, "path_crossover_s": None,
               "path_crossover_spp": None, "denoised_crossover_s": 1.0,
               "denoised_crossover_spp": 3.0} for v in values]
    points.append({"point": {"resolution": "0"}, "label": "resolution=0", "ok": False,
                   "error": "ValueError: resolution"})

    def curve(extra):
        spps = [1, 2, 4, 8, 16]
        times = np.sort(rng.uniform(0.02, 8, len(spps)))
        flips = np.sort(rng.uniform(0.005, 0.3, len(spps)))[::-1]
        return [{"spp": s, "time_s": float(t), "render_s": float(t) / 2, "flip": float(f), **extra}
                for s, t, f in zip(spps, times, flips)]

    return {"scene": str(scene_path("tradeoff/bumpy_sphere.xml")),
            "knobs": [{"name": "resolution", "values": values + ["0"], "kind": "define"}],
            "points": points, "reference_integrator": "path", "path_curve": curve({}),
            "denoised_curve": curve({"denoise_s": 0.01}), "denoise": "fast",
            "reference_spp": 64, "spp_capped": False, "noise_floor_flip": 0.02,
            "width": 24, "height": 16}


def kind_of(option) -> str:
    """The kind of a brute-force option ``(name, flip, time)`` from its name."""
    name = option[0]
    return "denoised" if name.endswith("OIDN fast") else "path" if name.startswith("path") else "approx"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_budget_pick_by_brute_force(seed):
    result = _synthetic(seed)
    budgets = (0.01, 0.1, 0.5, 1.0, 3.0, 10.0)
    rows = atlas.budget_table({"s": result}, budgets)
    one_spp = result["path_curve"][0]["render_s"]
    everything = ([(f"displaced, {p['label']}", p["flip"], p["time_warm_s"])
                   for p in result["points"] if p["ok"]]
                  + [(f"path {c['spp']} spp", c["flip"], c["time_s"]) for c in result["path_curve"]]
                  + [(f"path {c['spp']} spp + OIDN fast", c["flip"], c["time_s"])
                     for c in result["denoised_curve"]])
    assert [r["budget_s"] for r in rows] == list(budgets)
    for row in rows:
        assert row["budget_path_spp"] == pytest.approx(row["budget_s"] / one_spp)
        assert row["budget_bump"] is None  # no bump mapping in this sweep
        fits = [o for o in everything if o[2] <= row["budget_s"]]
        if not fits:
            assert row["pick"] is None and row["verdict"].startswith("Nothing measured")
            continue
        name, flip, _ = min(fits, key=lambda o: (o[1], o[2]))
        assert (row["pick"], row["pick_flip"]) == (name, flip)
        assert row["verdict"].startswith(f"Pick {name} (FLIP {flip:.3g}")
        runner_up = sorted({min((o for o in fits if kind_of(o) == k), key=lambda o: o[1])[1]
                            for k in {kind_of(o) for o in fits}})[1:2]
        tie = bool(runner_up) and runner_up[0] - flip < result["noise_floor_flip"]
        assert ("a tie" in row["verdict"]) == tie
        approx = [o for o in fits if o[0].startswith("displaced")]
        assert row["technique"] == (min(approx, key=lambda o: (o[1], o[2]))[0] if approx else None)
        for kind in ("path", "denoised_path"):
            other = [o for o in fits if o[0].startswith("path")
                     and o[0].endswith("OIDN fast") == (kind == "denoised_path")]
            assert row[f"{kind}_flip"] == (min(o[1] for o in other) if other else None)


#: The page under test in an iframe: the harness writes what the page's document holds.
HARNESS = """<!DOCTYPE html><html><head><meta charset="utf-8"><link rel="icon" href="data:,">
</head><body><iframe id="page" src="PAGE" width="1200" height="900"></iframe><pre id="out"></pre>
<script>
document.getElementById("page").addEventListener("load", () => {
  const doc = document.getElementById("page").contentDocument;
  document.getElementById("out").textContent = JSON.stringify({
    title: doc.title, headings: Array.from(doc.querySelectorAll("h2"), h => h.textContent),
    images: Array.from(doc.images, i => [i.getAttribute("src"), i.complete, i.naturalWidth])});
});
</script></body></html>"""
INSTALL = "apt-get update && apt-get install -y chromium"


def _chromium() -> str:
    """The Chromium binary; skips (no ``CI``) or fails (``CI`` set) without one."""
    found = shutil.which("chromium")
    if found is None:
        message = f"headless Chromium is needed for the atlas page test: {INSTALL}"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return found


def browse(page) -> tuple[dict, list[str]]:
    """Load ``page`` in headless Chromium (inside :data:`HARNESS`, written beside it).

    Returns:
        ``(state, console)``: the page's title, ``<h2>`` texts and every image's ``[src,
        complete, naturalWidth]`` after its load event, and every console message it wrote.
    """
    harness = page.parent / "_harness.html"
    harness.write_text(HARNESS.replace("PAGE", page.name))
    run = subprocess.run(
        [_chromium(), "--headless", "--no-sandbox", "--disable-gpu",
         "--allow-file-access-from-files", "--enable-logging=stderr", "--v=0",
         "--virtual-time-budget=10000", "--dump-dom", harness.as_uri()],
        capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    state = re.search(r'<pre id="out">(.*?)</pre>', run.stdout, re.S)
    assert state and state.group(1), f"the harness saw no load event: {run.stdout[-2000:]}"
    console = [line for line in run.stderr.splitlines() if ":CONSOLE" in line]
    return json.loads(state.group(1).replace("&quot;", '"').replace("&amp;", "&")), console


def test_atlas_page_in_chromium(tmp_path):
    from mi_displace.core.io import write_image
    from mi_displace.evaluate import tradeoff as tr

    result = _synthetic(3)
    folder = tmp_path / "s"
    folder.mkdir()
    rng = np.random.default_rng(3)
    for i, p in enumerate(result["points"]):
        if p["ok"]:
            write_image(folder / f"point_{i}.png", rng.uniform(0, 1, (16, 24, 3)))
    tr.plot(result, folder / "tradeoff.png")
    page = atlas.write_html(tmp_path / "index.html", {"s": result}, tmp_path, {})
    state, console = browse(page)
    assert state["title"] == "mi_displace trade-off atlas" and "What to pick" in state["headings"]
    expected = 1 + sum(p["ok"] for p in result["points"])  # the plot and every point image
    assert len(state["images"]) == expected == page.read_text().count("<img ")
    assert all(complete and width > 0 for _, complete, width in state["images"]), state["images"]
    assert console == []
    # the check sees a missing image and a console error
    (folder / "point_0.png").unlink()
    broken = tmp_path / "broken.html"
    broken.write_text(page.read_text().replace("</body>", "<script>console.error('x')</script></body>"))
    state, console = browse(broken)
    assert [src for src, _, width in state["images"] if width == 0] == ["s/point_0.png"]
    assert len(console) == 1 and '"x"' in console[0]


def test_choosing_page_matches_the_atlas():
    """docs/choosing.md is what the generator writes from docs/atlas/atlas.json, and every
    pick it lists is one of that atlas's budget rows."""
    record = json.loads((atlas.DOCS / "atlas" / "atlas.json").read_text())
    page = (atlas.DOCS / "choosing.md").read_text()
    assert page == atlas.choosing_markdown(record), (
        "docs/choosing.md is stale: run python -m mi_displace.evaluate.atlas")
    picks = {(r["scene"], r["pick"]) for r in record["budgets"] if r["pick"]}
    for scene in record["scenes"]:
        assert f"### `{scene}`" in page
        assert any(f"| {pick} |" in page for name, pick in picks if name == scene)
