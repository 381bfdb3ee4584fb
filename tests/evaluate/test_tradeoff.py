"""Trade-off sweeps, tune and the atlas on a tiny displaced-sphere scene (32x32).

The approximation is the same displaced sphere tessellated coarser (`resolution` knob) under
`raster`; the reference is a 256 tessellation under `path`.  Independent truths: a finer
tessellation is closer to the reference; the crossover of a power-law curve is known in
closed form; the Pareto front is checked by brute force; a run on a two-worker local Dask
cluster must give bit-identical raster images.
"""
import json
import math
import shutil

import numpy as np
import pytest

import mi_displace
from mi_displace.core.resources import scene_path
from mi_displace.evaluate import atlas as atlas_mod
from mi_displace.evaluate import tradeoff as tr

DATA = scene_path("tradeoff")
SCENE = DATA / "bumpy_sphere.xml"
SWEEP = dict(max_spp=128, warm_repeats=3)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """One local sweep of resolution = 6, 24, 96 (shared by the tests below)."""
    mi_displace.init("llvm_ad_rgb")
    root = tmp_path_factory.mktemp("sweep")
    result = tr.tradeoff(SCENE, [tr.parse_knob("resolution=6,24,96")], out_dir=root / "out",
                         cache_dir=root / "cache", **SWEEP)
    return result, root


def test_sweep_measures_every_point(sweep):
    result, root = sweep
    points = result["points"]
    assert [p["label"] for p in points] == ["resolution=6", "resolution=24", "resolution=96"]
    assert all(p["ok"] and not p["cached"] for p in points)
    for p in points:
        for key in ("flip", "relmse", "time_warm_s", "time_cold_s"):
            assert math.isfinite(p[key]) and p[key] > 0, key
    # a finer tessellation of the same displaced sphere is closer to the 256 reference
    flips = [p["flip"] for p in points]
    assert flips[0] > flips[1] > flips[2]
    # the reference resolves the best point, or says it was capped
    assert result["noise_floor_flip"] <= 0.2 * min(flips) or result["spp_capped"]
    # the path curve: spp 1, 2, 4, ... up to a quarter of the reference's, error falling
    curve = result["path_curve"]
    assert [c["spp"] for c in curve] == [2 ** k for k in range(
        int(math.log2(result["reference_spp"] // 4)) + 1)]
    assert curve[-1]["flip"] < curve[0]["flip"]
    out = root / "out"
    saved = json.loads((out / "tradeoff.json").read_text())
    assert [p["flip"] for p in saved["points"]] == pytest.approx(flips)
    assert len((out / "tradeoff.csv").read_text().strip().splitlines()) == 1 + len(points)
    for i in range(3):
        assert (out / f"point_{i}.png").is_file()
    assert (out / "tradeoff.png").stat().st_size > 10_000


def test_a_progress_line_per_point(sweep, caplog):
    """Scripts and notebooks see each point through the mi_displace logger."""
    import logging

    _, root = sweep
    with caplog.at_level(logging.INFO, logger="mi_displace"):
        tr.tradeoff(SCENE, [tr.parse_knob("resolution=6,24,96")], out_dir=root / "again",
                    cache_dir=root / "cache", progress=None, **SWEEP)
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("point ")]
    assert lines == [f"point {i}/3: resolution={r}: cached" for i, r in ((1, 6), (2, 24), (3, 96))]


def test_pareto_front_brute_force(sweep):
    points = sweep[0]["points"]
    for p in points:
        dominated = any(q["time_warm_s"] <= p["time_warm_s"] and q["flip"] <= p["flip"]
                        and (q["time_warm_s"], q["flip"]) != (p["time_warm_s"], p["flip"])
                        for q in points)
        assert p["pareto"] == (not dominated)
    assert tr.pareto_front([1, 2, 3, 4], [4, 1, 2, 0.5]) == [True, True, False, True]


def test_crossover_power_law():
    # flip = 1 / sqrt(spp), time = 0.5 + 0 * spp ... use time = spp / 100: log-log linear
    curve = [{"spp": s, "time_s": s / 100, "flip": 1 / math.sqrt(s)} for s in (1, 2, 4, 8, 16, 32)]
    seconds, spp = tr.crossover(curve, 1 / math.sqrt(10))
    assert spp == pytest.approx(10, rel=1e-9) and seconds == pytest.approx(0.1, rel=1e-9)
    assert tr.crossover(curve, 2.0) == (0.01, 1.0)        # reached at once
    assert tr.crossover(curve, 0.01) == (None, None)      # not within the curve


def test_cache_resumes_and_ignores_other_code(sweep, monkeypatch):
    result, root = sweep
    again = tr.tradeoff(SCENE, [tr.parse_knob("resolution=6,24,96")], cache_dir=root / "cache",
                        **SWEEP)
    assert all(p["cached"] for p in again["points"])
    assert [p["flip"] for p in again["points"]] == [p["flip"] for p in result["points"]]
    assert [p["time_warm_s"] for p in again["points"]] == [p["time_warm_s"] for p in result["points"]]
    # a cache written by another code version is never read
    monkeypatch.setattr("mi_displace.core.version.code_version", lambda: "0" * 16)
    other = tr.tradeoff(SCENE, [tr.parse_knob("resolution=6")], cache_dir=root / "cache", **SWEEP)
    assert not other["points"][0]["cached"]


def vertex_count(scene) -> dict:
    """Vertices of the displaced approximation mesh (a per-point ``inspect`` measurement)."""
    import mitsuba as mi

    return {"vertices": int(mi.traverse(scene)["ball.vertex_positions"].shape[0] // 3)}


def test_explicit_points_inspect_and_noise_floor_target(sweep, tmp_path):
    """One parameter at a time (points naming different knobs), a per-point measurement of
    the loaded scene, and a reference that stops at an absolute noise-floor target."""
    result, root = sweep
    target = 0.06
    points = [{"resolution": 6}, {"resolution": 24}, {"resolution": 24, "ball.scale": 0}]
    r = tr.tradeoff(SCENE, None, points=points, out_dir=tmp_path, cache_dir=root / "cache",
                    inspect=vertex_count, noise_floor=target, **SWEEP)
    assert [p["label"] for p in r["points"]] == ["resolution=6", "resolution=24",
                                                 "resolution=24,ball.scale=0"]
    counts = [p["inspected"]["vertices"] for p in r["points"]]
    assert counts[0] < counts[1] == counts[2]    # a finer tessellation, the same one
    assert r["points"][2]["flip"] > r["points"][1]["flip"]  # undisplaced is further off
    # the reference doubled exactly until its floor met the target (or the ratio rule)
    rounds, best = r["reference_rounds"], min(p["flip"] for p in r["points"])
    assert all(x["noise_floor_flip"] > max(target, 0.2 * best) for x in rounds[:-1])
    assert rounds[-1]["noise_floor_flip"] <= max(target, 0.2 * best) or r["spp_capped"]
    assert r["noise_floor_target"] == target
    header = (tmp_path / "tradeoff.csv").read_text().splitlines()[0]
    assert header.endswith(",vertices")
    with pytest.raises(ValueError, match="points"):
        tr.tradeoff(SCENE, [tr.parse_knob("resolution=6")], points=[{"resolutio": 6}],
                    cache_dir=tmp_path)
    with pytest.raises(ValueError, match="noise-floor"):
        tr.tradeoff(SCENE, [tr.parse_knob("resolution=6")], noise_floor=0, cache_dir=tmp_path)


def test_invalid_value_is_skipped_and_recorded(variant_llvm, tmp_path):
    result = tr.tradeoff(SCENE, [tr.parse_knob("resolution=0,12")], cache_dir=tmp_path, **SWEEP)
    bad, good = result["points"]
    assert not bad["ok"] and "resolution" in bad["error"]
    assert good["ok"] and math.isfinite(good["flip"])


def test_unknown_knob_refused_before_rendering(variant_llvm, monkeypatch, tmp_path):
    def refuse(*args, **kwargs):
        raise AssertionError("rendered although the knob is bad")

    monkeypatch.setattr(tr.cmp, "converge_reference", refuse)
    monkeypatch.setattr(tr.jobs_mod, "run_jobs", refuse)
    with pytest.raises(ValueError, match="resolutio"):
        tr.tradeoff(SCENE, [tr.parse_knob("resolutio=1,2")], cache_dir=tmp_path)
    with pytest.raises(ValueError, match="bal.scale"):
        tr.tradeoff(SCENE, [tr.parse_knob("bal.scale=0.1")], cache_dir=tmp_path)
    with pytest.raises(ValueError, match="resolutio"):  # an explicit point's knob too
        tr.tradeoff(SCENE, None, points=[{"resolution": 8}, {"resolutio": 8}], cache_dir=tmp_path)
    for text in ("resolution", "resolution=", "=1,2", "resolution=1,1", "a b=1"):
        with pytest.raises(ValueError, match="--knob"):
            tr.parse_knob(text)
    with pytest.raises(ValueError, match="cluster"):
        tr.tradeoff(SCENE, [tr.parse_knob("resolution=8")], cache_dir=tmp_path, cluster="local:0")
    with pytest.raises(ValueError, match="denoise: quality"):
        tr.tradeoff(SCENE, [tr.parse_knob("resolution=8")], cache_dir=tmp_path, denoise="best")


def test_traverse_knob(variant_llvm, tmp_path):
    # ID.PARAM edits the loaded approximation: scale 0 is the bare sphere, far from the
    # displaced reference; the reference's own scale (0.15) is closer
    result = tr.tradeoff(SCENE, [tr.parse_knob("ball.scale=0,0.15")], cache_dir=tmp_path,
                         max_spp=32)
    flat, true = result["points"]
    assert flat["ok"] and true["ok"] and flat["flip"] > true["flip"]


def test_tune_picks_cheapest_within_budget(sweep, tmp_path):
    result, root = sweep
    points = result["points"]
    budget = 0.5 * (points[1]["flip"] + points[0]["flip"])  # resolution 24 and 96 meet it
    answer = tr.tune(SCENE, budget, [tr.parse_knob("resolution=6,24,96")], out_dir=tmp_path,
                     cache_dir=root / "cache", **SWEEP)
    meeting = [p for p in points if p["flip"] <= budget]
    assert answer["chosen"] == min(meeting, key=lambda p: p["time_warm_s"])["point"]
    assert answer["defines"] == [f"-D resolution={answer['chosen']['resolution']}"]
    assert answer["meets_budget"] == (answer["verified_flip"] <= budget)
    assert math.isfinite(answer["default_time_s"]) and answer["speedup_vs_default"] > 0
    assert json.loads((tmp_path / "tune.json").read_text())["chosen"] == answer["chosen"]
    none = tr.tune(SCENE, 1e-6, [tr.parse_knob("resolution=6")], cache_dir=root / "cache",
                   **SWEEP)
    assert none["chosen"] is None and none["defines"] == []


def test_denoised_path_curve_and_crossover(sweep, tmp_path):
    """``denoise``: the path curve measured twice (raw and denoised, same seeds), each point's
    crossover against both, and ``tune`` answering with the fastest of the three."""
    result, root = sweep
    r = tr.tradeoff(SCENE, [tr.parse_knob("resolution=6,24,96")], out_dir=tmp_path / "bumpy",
                    cache_dir=root / "cache", path_spps=[1, 4, 16], denoise="fast", **SWEEP)
    raw, denoised = r["path_curve"], r["denoised_curve"]
    assert [c["spp"] for c in raw] == [c["spp"] for c in denoised] == [1, 4, 16]
    build = raw[0]["time_s"] - raw[0]["render_s"]
    for c in denoised:  # the denoiser's time is part of the point's time
        assert c["denoise_s"] > 0 and math.isfinite(c["flip"]) and 0 < c["flip"] < 1
        assert c["time_s"] == pytest.approx(build + c["render_s"] + c["denoise_s"])
    for p in r["points"]:  # the denoised crossover by brute force along the curve
        reached = [c for c in denoised if c["flip"] <= p["flip"]]
        if not reached:
            assert p["denoised_crossover_s"] is None
            assert "does not reach" in p["denoised_verdict"]
        else:
            i = denoised.index(reached[0])  # interpolated between it and the point before
            around = denoised[max(0, i - 1):i + 1]
            for key, c_key in (("denoised_crossover_s", "time_s"), ("denoised_crossover_spp", "spp")):
                values = [c[c_key] for c in around]
                assert min(values) * (1 - 1e-9) <= p[key] <= max(values) * (1 + 1e-9)
            assert "denoised path tracing" in p["denoised_verdict"]
    header = (tmp_path / "bumpy" / "tradeoff.csv").read_text().splitlines()[0].split(",")
    assert {"denoised_crossover_s", "denoised_crossover_spp"} <= set(header)
    # the atlas: the denoised path's FLIP within each budget, by brute force
    page = atlas_mod.write_html(tmp_path / "index.html", {"bumpy": r}, tmp_path, {}).read_text()
    assert "denoised path needs" in page and "OIDN fast" in page
    for row in atlas_mod.budget_table({"bumpy": r}):
        within = [c["flip"] for c in denoised if c["time_s"] <= row["budget_s"]]
        assert row["denoised_path_flip"] == (min(within) if within else None)
    budget = max(c["flip"] for c in denoised)  # every curve point meets it
    answer = tr.tune(SCENE, budget, [tr.parse_knob("resolution=6,24,96")], verify=False,
                     cache_dir=root / "cache", path_spps=[1, 4, 16], denoise="fast", **SWEEP)
    chosen = answer["denoised_path"]
    assert chosen["flip"] <= budget and chosen["spp"] in (1, 4, 16)
    fastest = min(chosen["time_s"], answer["path"]["time_s"] if answer["path"] else math.inf,
                  answer.get("sweep_time_s") or math.inf)
    assert answer["answer"].endswith(f"({fastest:.3g} s)")
    if fastest == chosen["time_s"]:
        assert answer["answer"].startswith(f"path trace at {chosen['spp']} spp with the denoiser")


def test_atlas_page(sweep, tmp_path):
    result, root = sweep
    scenes = tmp_path / "scenes"
    shutil.copytree(DATA, scenes)
    scene = scenes / "bumpy_sphere.xml"
    scene.write_text(scene.read_text().replace("<!-- tradeoff:", "<!-- showcase -->\n<!-- tradeoff:"))
    record = atlas_mod.atlas(tmp_path / "atlas", scenes_dir=scenes, cache_dir=root / "cache",
                             max_spp=SWEEP["max_spp"])
    assert list(record["scenes"]) == ["bumpy_sphere"] and not record["failures"]
    page = (tmp_path / "atlas" / "index.html").read_text()
    points = record["scenes"]["bumpy_sphere"]["points"]
    for link in ["bumpy_sphere/tradeoff.png"] + [f"bumpy_sphere/point_{i}.png"
                                                 for i, p in enumerate(points) if p["ok"]]:
        assert f'<a href="{link}">' in page and (tmp_path / "atlas" / link).is_file()
    assert "What to pick" in page
    rows = [r for r in record["budgets"] if r["setting"] is not None]
    for r in rows:  # the most accurate setting within the budget, by brute force
        fits = [p for p in points if p["ok"] and p["time_warm_s"] <= r["budget_s"]]
        assert r["flip"] == min(p["flip"] for p in fits)


def test_cluster_matches_local(sweep, tmp_path):
    """Two local worker processes: same images bit for bit (raster), hosts reported."""
    result, root = sweep
    remote = tr.tradeoff(SCENE, [tr.parse_knob("resolution=6,24,96")], out_dir=tmp_path / "out",
                         cache_dir=tmp_path / "cache", cluster="local:2", **SWEEP)
    assert not any(p["cached"] for p in remote["points"])
    assert all(p["host"] for p in remote["points"])
    for i in range(3):
        local_png = (root / "out" / f"point_{i}.png").read_bytes()
        assert (tmp_path / "out" / f"point_{i}.png").read_bytes() == local_png
    assert [p["flip"] for p in remote["points"]] == pytest.approx(
        [p["flip"] for p in result["points"]], abs=0.0)


def test_plot_groups_by_first_knob():
    """Mixed explicit points get one legend entry per first setting, the rest as labels;
    a one-knob sweep stays one group labelled in full."""
    def pt(**kv):
        return {"point": kv, "label": ",".join(f"{k}={v}" for k, v in kv.items())}

    mixed = [pt(direction="a", slices="4"), pt(direction="a", slices="12"),
             pt(mode="relief", relief_steps="8"), pt(mode="vdm")]
    groups = tr._plot_groups(mixed)
    assert list(groups) == ["direction=a: slices", "mode=relief: relief_steps", "mode=vdm"]
    assert [text for _, text in groups["direction=a: slices"]] == ["4", "12"]
    assert groups["mode=vdm"] == [(mixed[3], "")]
    single = [pt(resolution="6"), pt(resolution="24")]
    assert tr._plot_groups(single) == {"": [(single[0], "resolution=6"), (single[1], "resolution=24")]}
