"""The XML scenes in scenes/: load in both modes and render finite, lit images; the
tessellated references are converged in tessellation (DESIGN protocol item 3)."""
from pathlib import Path

import flip_evaluator as flip
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.io import to_srgb
from mi_displace.evaluate.compare import protocol_settings, scene_defaults

SCENES = sorted((Path(__file__).resolve().parents[1] / "scenes").glob("*.xml"))


def render(path, spp, seed=0, **params):
    scene = mi.load_file(str(path), **{k: str(v) for k, v in params.items()})
    img = np.array(mi.render(scene, spp=spp, seed=seed))[..., :3]
    assert np.all(np.isfinite(img)), f"{path.name}: non-finite pixels"
    return img


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """Run from an empty folder with a fresh file resolver (Mitsuba's holds the cwd of its
    start-up): a scene that names files relative to the cwd, not to itself, fails."""
    saved = mi.file_resolver()
    fresh = mi.FileResolver()
    fresh.clear()
    for folder in saved:  # keep Mitsuba's own folders (plugins), drop the start-up cwd
        if Path(str(folder)).resolve() != Path.cwd().resolve():
            fresh.append(folder)
    monkeypatch.chdir(tmp_path)
    mi.set_file_resolver(fresh)
    yield
    mi.set_file_resolver(saved)


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_scene_renders_both_sides(variant, path, elsewhere):
    # each side's integrator as the scene declares it (volume scenes: volpath / volume_slicer);
    # `resolution` (tessellation) exists on the reference side only in some scenes
    settings = protocol_settings(path)
    sides = {"reference": settings["reference_integrator"],
             "approximation": settings["approximation_integrator"]}
    tess = {"resolution": 64} if "resolution" in scene_defaults(path) else {}
    images = {mode: render(path, 4, mode=mode, integrator=integ, res=48,
                           **(tess if mode == "reference" else {}))
              for mode, integ in sides.items()}
    for mode, img in images.items():
        assert img.mean() > 0.01, f"{path.name} ({mode}) is black"
    assert abs(images["reference"].mean() / images["approximation"].mean() - 1) < 0.5


@pytest.mark.slow
def test_displaced_reference_is_converged_in_tessellation(variant):
    path = next(p for p in SCENES if p.stem == "displaced_sphere")
    kw = dict(mode="reference", integrator="path", res=128)
    a = [render(path, 256, seed=s, resolution=1024, **kw) for s in (0, 1)]
    b = [render(path, 256, seed=s, resolution=2048, **kw) for s in (2, 3)]
    noise_floor = flip.evaluate(to_srgb(a[0]), to_srgb(a[1]), "LDR")[1]
    doubling = flip.evaluate(to_srgb(0.5 * (a[0] + a[1])), to_srgb(0.5 * (b[0] + b[1])), "LDR")[1]
    assert doubling < noise_floor
