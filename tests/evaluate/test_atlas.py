"""The atlas's options by name and its budget table.

Names come from the scene files (the technique plugin each point renders) and the points'
build statistics; the pick within a budget is checked by brute force over every option of a
synthetic sweep (approximation points, raw and denoised path points with random errors and
times), and the portable units against the curve's own 1-spp render time.
"""
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
               "build_stats": []} for v in values]
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
            "denoised_curve": curve({"denoise_s": 0.01}), "denoise": "fast"}


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
        approx = [o for o in fits if o[0].startswith("displaced")]
        assert row["technique"] == (min(approx, key=lambda o: (o[1], o[2]))[0] if approx else None)
        for kind in ("path", "denoised_path"):
            other = [o for o in fits if o[0].startswith("path")
                     and o[0].endswith("OIDN fast") == (kind == "denoised_path")]
            assert row[f"{kind}_flip"] == (min(o[1] for o in other) if other else None)
