"""``bench frames``' parts: the orbit turns the camera about its up axis around the scene's
centre, the main parameter is found by its key, the kernel share counts Dr.Jit's launches."""
import time

import numpy as np
import pytest


def test_orbit_turns_the_camera_about_its_up_axis_around_the_scene_centre(variant_llvm):
    import mitsuba as mi

    from mi_displace.bench import frames
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    scene, _ = load(scene_path("vdm_torus.xml"), mode="bump", integrator="raster", res=16)
    loaded = np.array(scene.sensors()[0].world_transform().matrix).reshape(4, 4)
    centre = np.array(scene.bbox().center())
    poses = [np.array(t.matrix).reshape(4, 4) for t in frames._orbit(scene, np.linspace(-frames.ORBIT_DEG, frames.ORBIT_DEG, 5))]

    np.testing.assert_allclose(poses[2], loaded, atol=1e-5)          # angle 0: the loaded view
    distance = np.linalg.norm(loaded[:3, 3] - centre)
    for pose in poses:
        assert np.linalg.norm(pose[:3, 3] - centre) == pytest.approx(distance, rel=1e-5)
        np.testing.assert_allclose(pose[:3, 1], loaded[:3, 1], atol=1e-5)   # same up axis
    forward = [pose[:3, 2] for pose in poses]   # unit view directions, turned about "up"
    turn = np.degrees(np.arccos(np.clip(forward[0] @ forward[-1], -1, 1)))
    up = loaded[:3, 1]
    flat = [f - (f @ up) * up for f in (forward[0], forward[-1])]
    cosine = flat[0] @ flat[1] / np.linalg.norm(flat[0]) / np.linalg.norm(flat[1])
    assert np.degrees(np.arccos(np.clip(cosine, -1, 1))) == pytest.approx(2 * frames.ORBIT_DEG, abs=1e-3)
    assert turn <= 2 * frames.ORBIT_DEG + 1e-3


def test_edit_key_is_one_scene_parameter_or_a_one_line_error(variant_llvm):
    from mi_displace.bench.frames import _edit_key

    params = {"object_1.bsdf.scale": 1.0, "vdm_height.radius": 0.4, "a.to_world": 0, "b.to_world": 0}
    assert _edit_key(params, "bsdf.scale") == "object_1.bsdf.scale"
    assert _edit_key(params, "vdm_height.radius") == "vdm_height.radius"
    for key, count in (("to_world", 2), ("depth", 0)):
        with pytest.raises(ValueError, match=f"edit_key '{key}': {count} matching"):
            _edit_key(params, key)


def test_kernel_share_counts_launches_and_their_time(variant_llvm):
    import drjit as dr
    import mitsuba as mi

    from mi_displace.bench.frames import _profile

    idle = _profile(lambda: time.sleep(0.05))   # no kernel: all of the frame is host time
    assert idle["kernels"] == idle["cache_misses"] == 0 and idle["kernel_share"] == 0.0
    assert idle["profiled_frame_s"] >= 0.05

    seed = 1.0 + time.time_ns() % 10**9 * 1e-12   # a constant no earlier kernel (nor run) saw
    busy = _profile(lambda: dr.eval(dr.sum(dr.sin(dr.arange(mi.Float, 2_000_000) * seed))))
    assert busy["kernels"] >= busy["cache_misses"] >= 1 and busy["compile_ms"] > 0
    again = _profile(lambda: dr.eval(dr.sum(dr.sin(dr.arange(mi.Float, 2_000_000) * seed))))
    assert again["kernels"] == busy["kernels"] and again["cache_misses"] == again["compile_ms"] == 0
    assert 0.0 < busy["kernel_share"] <= 1.0 + 1e-6


def test_spread_puts_one_value_in_each_stratum_new_each_run():
    from mi_displace.bench.frames import _spread

    low, high, count = -20.0, 20.0, 10
    first, second = (_spread(low, high, count, np.random.default_rng(seed)) for seed in (1, 2))
    for values in (first, second):
        strata = np.floor((values - low) / (high - low) * count)
        np.testing.assert_array_equal(strata, np.arange(count))   # one per stratum, in order
    assert not np.intersect1d(first, second).size                 # another run, other values


class _Gain:
    """A value a frozen function cannot see change (neither an input nor in its closure)."""
    k = 2.0


def _scaled(x):
    import drjit as dr
    return x * _Gain.k + dr.sum(x)


def test_freeze_lever_times_both_and_sees_a_baked_value(variant_llvm, monkeypatch):
    """``freeze_lever``: frozen and plain frames timed, images equal when only the frozen
    function's inputs change; a value baked into the recording (as Mitsuba's ``bumpmap``
    scale) shows as unequal images; a refused recording gives Dr.Jit's reason, a frame
    drawn unfrozen (``refused()``) its own."""
    import drjit as dr
    import mitsuba as mi

    from mi_displace.bench.frames import freeze_lever

    state = {"x": dr.arange(mi.Float, 1000)}

    def move():
        state["x"] = dr.arange(mi.Float, 1000) * 0.5

    def lever(changes, frozen=_scaled, refused=lambda: None):
        recorded = dr.freeze(frozen)
        return freeze_lever(lambda: _scaled(state["x"]), lambda: recorded(state["x"]), changes, 3,
                            refused)

    inputs = lever([move])
    assert inputs["frozen_identical"] is True and inputs["frozen_error"] is None
    assert inputs["frozen_frame_s"] > 0 and inputs["frozen_ratio"] > 0
    monkeypatch.setattr(_Gain, "k", 2.0)
    baked = lever([lambda: monkeypatch.setattr(_Gain, "k", 3.0)])
    assert baked["frozen_identical"] is False
    refused = lever([], frozen=lambda x: x * dr.sum(x)[0])   # a read-back inside
    assert refused["frozen_frame_s"] is refused["frozen_ratio"] is refused["frozen_identical"] is None
    assert "frozen function" in refused["frozen_error"]
    unfrozen = lever([], refused=lambda: "drawn unfrozen")
    assert unfrozen["frozen_error"] == "drawn unfrozen" and unfrozen["frozen_ratio"] is None


def test_fixed_cost_renders_a_tiny_film(variant_llvm):
    """``fixed_cost`` sets the film to FIXED_RES² and times frames there."""
    import mitsuba as mi

    from mi_displace.bench import frames
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    scene, _ = load(scene_path("vdm_torus.xml"), mode="bump", integrator="raster", res=16)
    sensor = mi.traverse(scene.sensors()[0])
    sizes = []

    def frame():
        image = mi.render(scene, integrator=mi.load_dict({"type": "raster", "aa": 1}), spp=1)
        sizes.append(image.shape[:2])

    record = frames.fixed_cost(sensor, frame, 3)
    assert set(sizes) == {(frames.FIXED_RES, frames.FIXED_RES)} and len(sizes) == 5
    assert record["fixed_frame_s"] > 0 and 0 <= record["fixed_kernel_share"] <= 1 and record["fixed_kernels"] >= 1


def test_volume_slicer_row_draws_one_ray_a_pixel(variant_llvm):
    """The volume slicer row renders at one ray a pixel (the scene's own ``aa`` is 2): the
    same image as a slicer made with ``aa`` 1 and the scene's other settings."""
    import mitsuba as mi

    from mi_displace.bench import frames
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    row = next(r for r in frames.ROWS if r.name == "volume_slicer")
    scene, _ = load(scene_path(row.scene), **row.params, res=16)
    plugin = scene.integrator().plugin
    assert scene.integrator().settings.aa == 2
    mine = mi.render(scene, integrator=frames.frame_integrator(row, scene), spp=1)
    one = mi.load_dict({"type": "volume_slicer", "volume": plugin, "model": "scatter", "albedo": 0.8,
                        "spacing": 1.0, "aa": 1})
    assert np.isfinite(np.array(mine)).all()
    np.testing.assert_array_equal(np.array(mine), np.array(mi.render(scene, integrator=one, spp=1)))


def test_every_row_is_in_one_guide_and_the_guides_match_the_record():
    """Each row of ``ROWS`` appears in exactly one technique guide, and every guide's frames
    table is what :func:`frames.guide_table` makes of docs/figures/frames_bench.json (the
    numbers in the guides cannot drift from the recorded run)."""
    import json

    from mi_displace.bench import frames

    listed = [name for names in frames.GUIDES.values() for name in names]
    assert sorted(listed) == sorted(row.name for row in frames.ROWS)
    record = json.loads((frames.DOCS / "figures" / "frames_bench.json").read_text())
    for page, names in frames.GUIDES.items():
        text = (frames.DOCS / page).read_text()
        assert text == frames.guide_text(text, record, names), (
            f"docs/{page}: frames table is stale: run python -m mi_displace.bench.frames")
        for name in names:
            assert f"| `{name}` |" in text
