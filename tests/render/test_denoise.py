"""Path tracing plus Open Image Denoise: it helps where the noise is Monte Carlo noise, and it
must not hide lost relief.

Independent truths: a reference converged from two seed streams far from the test images'
seeds; the relief region is where that reference has fine detail (its high-pass magnitude),
found from the reference alone, not from the denoiser.
"""
import sys

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from mi_displace.core.extras import MissingExtraError
from mi_displace.core.resources import scene_path
from mi_displace.evaluate import metrics
from mi_displace.render import denoise as dn
from mi_displace.render import scene as scenes


def _reference(scene, spp: int) -> np.ndarray:
    """Two independent seed streams averaged (seeds the test images do not use)."""
    return 0.5 * (scenes.render(scene, spp=spp, seed=0)[0] + scenes.render(scene, spp=spp, seed=1)[0])


def _smooth_scene():
    """A diffuse sphere on a floor under a uniform sky, two bounces: smooth surfaces, and
    the noise of a few spp is Monte Carlo noise of the soft light (64 x 64)."""
    import mitsuba as mi

    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 1.5], target=[0, 0, 0.3],
                                                              up=[0, 0, 1]),
                   "sampler": {"type": "independent", "sample_count": 4},
                   "film": {"type": "hdrfilm", "width": 64, "height": 64,
                            "rfilter": {"type": "box"}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.8, 0.85, 1.0]}},
        "ball": {"type": "sphere", "center": [0, 0, 0.6], "radius": 0.6,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.4, 0.3]}}},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([3, 3, 1]),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}},
    })


def test_denoiser_lowers_flip_on_a_smooth_scene(variant_llvm):
    scene = _smooth_scene()
    reference = _reference(scene, 1024)
    denoised, noisy, times = dn.render_denoised(scene, 4, seed=7, quality="high")
    metrics.assert_finite(denoised, "denoised image")
    # the colour of the AOV pass is the plain render with the same seed
    assert np.array_equal(noisy, scenes.render(scene, spp=4, seed=7)[0])
    raw_flip, _ = metrics.flip(reference, noisy)
    denoised_flip, _ = metrics.flip(reference, denoised)
    assert denoised_flip < 0.9 * raw_flip, (denoised_flip, raw_flip)
    assert times["render_s"] > 0 and times["denoise_s"] > 0
    again, _, _ = dn.render_denoised(scene, 4, seed=7, quality="high")
    assert np.array_equal(again, denoised)  # deterministic


def test_denoiser_blurs_mortar_of_true_displacement(variant_llvm):
    """Thin mortar under true displacement (the showcase's brick sphere, 128 x 128): at 64
    spp the denoised image is further from the converged reference than the raw one in the
    relief region — the FLIP map shows the detail the denoiser smeared."""
    scene, _ = scenes.load(scene_path("bump_vs_displaced.xml"), mode="reference",
                           integrator="path", res=128, resolution=1024)
    reference = _reference(scene, 256)
    luminance = reference.mean(axis=-1)
    detail = np.abs(luminance - gaussian_filter(luminance, 1.0))
    relief = detail > np.quantile(detail[luminance > 0], 0.8)  # the sharpest fifth
    assert 0.05 < relief.mean() < 0.3
    denoised, noisy, _ = dn.render_denoised(scene, 64, seed=11, quality="high")
    metrics.assert_finite(denoised, "denoised image")
    _, raw_map = metrics.flip(reference, noisy)
    _, denoised_map = metrics.flip(reference, denoised)
    assert np.isfinite(denoised_map).all()
    raw_relief, denoised_relief = raw_map[relief].mean(), denoised_map[relief].mean()
    assert denoised_relief > 1.05 * raw_relief, (denoised_relief, raw_relief)
    again, _, _ = dn.render_denoised(scene, 64, seed=11, quality="high")
    assert np.array_equal(again, denoised)


def test_bad_quality_named(variant_llvm):
    with pytest.raises(ValueError, match="denoise: quality must be one of fast, balanced, high"):
        dn.check_quality("ultra")


def test_missing_pyoidn_is_a_one_line_cli_error(monkeypatch, capsys, tmp_path):
    """Without the extra, ``--denoise`` stops before anything renders, naming the install line."""
    from mi_displace import cli

    monkeypatch.setitem(sys.modules, "pyoidn", None)  # as if not installed
    with pytest.raises(MissingExtraError, match=r"pip install 'mi-displace\[denoise\]'"):
        dn.check_quality("high")
    monkeypatch.setattr(scenes, "load", lambda *a, **k: pytest.fail("a scene was loaded"))
    with pytest.raises(SystemExit) as e:
        cli.main(["--variant", "llvm_ad_rgb", "tradeoff", str(scene_path("bump_vs_displaced.xml")),
                  "--denoise", "high", "--out", str(tmp_path)])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "mi-displace: error: the denoiser needs 'pyoidn', which is not installed: "
        "pip install 'mi-displace[denoise]'"]
