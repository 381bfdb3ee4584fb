"""The comparison protocol on a two-sphere scene (radius 1.0 vs 0.8, both sides `path`)."""
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from mi_displace.core.io import read_image
from mi_displace.evaluate import compare as cmp
from mi_displace.evaluate import metrics

DATA = Path(__file__).resolve().parents[1] / "data" / "compare"
SCENE = DATA / "two_spheres.xml"


@pytest.fixture
def no_render(monkeypatch):
    """Fail the test if the protocol gets as far as loading a scene."""
    def refuse(*args, **kwargs):
        raise AssertionError("a scene was loaded although the input is bad")

    monkeypatch.setattr(cmp.scenes, "load", refuse)


def test_compare_two_spheres(variant, tmp_path):
    result = cmp.compare(SCENE, tmp_path / "out", max_spp=256)
    out = tmp_path / "out"
    with open(out / "metrics.json") as f:
        saved = json.load(f)
    assert set(cmp.METRIC_KEYS) <= set(saved)
    assert saved["width"] == saved["height"] == 32
    assert saved["variant"] == variant
    assert saved["approximation_integrator"] == saved["reference_integrator"] == "path"
    assert saved["approximation_spp"] == 64
    for key in ("flip_mean", "relmse", "psnr", "ssim", "noise_floor_flip", "reference_time_s",
                "approx_time_cold_s", "approx_time_warm_s", "speedup"):
        assert isinstance(saved[key], float) and math.isfinite(saved[key]) and saved[key] > 0, key

    # the radius differs by 20 %: a real error, well above the reference's noise floor
    assert saved["flip_mean"] > 0.05
    assert saved["noise_floor_flip"] < saved["flip_mean"]
    assert not saved["within_noise_floor"]
    if saved["converged"]:
        assert saved["noise_floor_flip"] <= 0.2 * saved["flip_mean"]
    else:
        assert saved["spp_capped"]

    # spp doubles each round, starting from 2 x the scene's 16 spp, and stays within max_spp
    spps = [r["spp"] for r in saved["reference_rounds"]]
    assert spps == [32 * 2 ** i for i in range(len(spps))]
    assert saved["reference_spp"] == spps[-1] <= 256
    assert saved["noise_floor_flip"] == saved["reference_rounds"][-1]["noise_floor_flip"]

    # times add up as documented
    assert saved["reference_time_s"] == pytest.approx(saved["reference_build_s"] + saved["reference_render_s"])
    assert saved["approx_time_cold_s"] == pytest.approx(saved["approx_build_cold_s"] + saved["approx_render_cold_s"])
    assert saved["speedup"] == pytest.approx(saved["reference_time_s"] / saved["approx_time_warm_s"])

    # the stored images are finite and reproduce the stored metrics
    reference, approximation = read_image(out / "reference.exr"), read_image(out / "approximation.exr")
    assert reference.shape == approximation.shape == (32, 32, 3)
    metrics.assert_finite(reference, "reference.exr")
    assert metrics.relmse(reference, approximation) == pytest.approx(saved["relmse"], rel=1e-6)
    assert metrics.flip(reference, approximation)[0] == pytest.approx(saved["flip_mean"], rel=1e-6)
    # the reference sphere is larger: more pixels differ from the background corner colour
    background = reference[0, 0]
    covered = [np.sum(np.abs(img - background).max(axis=2) > 0.02) for img in (reference, approximation)]
    assert covered[0] > covered[1] * (1.0 / 0.8) ** 2 * 0.8

    panel = Image.open(out / "panel.png")
    assert panel.width > 2 * panel.height
    assert result["flip_mean"] == saved["flip_mean"]


def test_compare_caps_the_reference_spp(variant, tmp_path):
    result = cmp.compare(SCENE, tmp_path, max_spp=4)
    # 4 spp in total: two seeds of 2 spp, far too noisy to reach the ratio
    assert result["spp_capped"] and not result["converged"]
    assert result["reference_spp"] == 4 and len(result["reference_rounds"]) == 1


def test_compare_with_the_denoised_path_curve(variant_llvm, tmp_path):
    """``denoise``: the reference integrator's curve raw and denoised against the reference,
    and where each reaches the approximation's FLIP (by brute force along the curve)."""
    result = cmp.compare(SCENE, tmp_path, max_spp=64, denoise="fast")
    raw, denoised = result["path_curve"], result["denoised_curve"]
    spps = [2 ** k for k in range(int(math.log2(result["reference_spp"] // 4)) + 1)]
    assert [c["spp"] for c in raw] == [c["spp"] for c in denoised] == spps
    for name, curve in (("path", raw), ("denoised", denoised)):
        assert all(math.isfinite(c["flip"]) and 0 < c["flip"] < 1 for c in curve)
        reached = [i for i, c in enumerate(curve) if c["flip"] <= result["flip_mean"]]
        if not reached:
            assert result[f"{name}_crossover_s"] is None
            continue
        around = curve[max(0, reached[0] - 1):reached[0] + 1]
        times = [c["time_s"] for c in around]
        assert min(times) * (1 - 1e-9) <= result[f"{name}_crossover_s"] <= max(times) * (1 + 1e-9)
    assert "denoised path tracing" in result["denoised_verdict"]
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert [c["flip"] for c in saved["denoised_curve"]] == pytest.approx([c["flip"] for c in denoised])


def test_protocol_settings_from_xml_defaults_and_params():
    settings = cmp.protocol_settings(SCENE, {"res": 16, "approximation_spp": 2})
    assert settings == {"xml_params": {"res": "16"}, "reference_integrator": "path",
                        "approximation_integrator": "path", "approximation_spp": 2}


def test_bad_input_fails_before_rendering(tmp_path, no_render):
    with pytest.raises(FileNotFoundError, match="missing.xml"):
        cmp.compare(tmp_path / "missing.xml", tmp_path / "out")
    with pytest.raises(ValueError, match="must declare <default name=...> for mode, integrator"):
        cmp.compare(DATA / "parts" / "sphere_reference.xml", tmp_path / "out")
    with pytest.raises(ValueError, match="mode is set by the comparison protocol"):
        cmp.compare(SCENE, tmp_path / "out", params={"mode": "reference"})
    with pytest.raises(ValueError, match="max_spp"):
        cmp.compare(SCENE, tmp_path / "out", max_spp=1)
    with pytest.raises(ValueError, match="target_ratio"):
        cmp.compare(SCENE, tmp_path / "out", target_ratio=0.0)
    with pytest.raises(ValueError, match="denoise: quality"):
        cmp.compare(SCENE, tmp_path / "out", denoise="max")
    with pytest.raises(ValueError, match="approximation_spp"):
        cmp.compare(SCENE, tmp_path / "out", params={"approximation_spp": "many"})
    broken = tmp_path / "broken.xml"
    broken.write_text("<scene><default name='mode'")
    with pytest.raises(ValueError, match="broken.xml' is not valid XML"):
        cmp.compare(broken, tmp_path / "out")
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is not a folder"):
        cmp.compare(SCENE, tmp_path / "file")


def test_copied_scene_keeps_its_parts(variant, tmp_path):
    """Includes resolve relative to the scene file, wherever the process runs."""
    shutil.copytree(DATA, tmp_path / "copy")
    result = cmp.compare(tmp_path / "copy" / "two_spheres.xml", tmp_path / "out",
                         params={"res": 8}, max_spp=4)
    assert (result["width"], result["height"]) == (8, 8)
    assert result["params"] == {"res": "8"}
