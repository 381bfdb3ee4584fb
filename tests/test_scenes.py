"""The XML scenes in scenes/: reference and approximation agree as closely as the guides say,
at a small resolution; the tessellated references are converged in tessellation (DESIGN
protocol item 3).

Agreement (issue 19 item 3).  Both sides are rendered by the GPU-style ``raster``
integrator: the reference geometry under raster is the path-traced reference up to the
path tracer's noise (DESIGN protocol item 4, checked here on ``displaced_sphere``, the
consistency scene, against ``path`` itself), and raster is deterministic, so the FLIP
between the two sides is the technique's error alone and needs no noise margin.  Each
scene's bound is the error its guide documents for that scene, at 256² (:data:`BOUNDS`,
with the sentence it comes from); the test runs at 64², where every scene measured below
its documented figure.  Each bound is also shown to be tight enough to fail: the same
approximation misregistered by one pixel must exceed it (except in :data:`COARSE`).

The reference scene is also path traced (2 spp) to catch a plugin that renders under raster
only; every image is finite and lit.
"""
import re
from pathlib import Path

import flip_evaluator as flip
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.io import to_srgb
from mi_displace.evaluate import metrics
from mi_displace.evaluate.compare import protocol_settings, scene_defaults

ALL_SCENES = sorted((Path(__file__).resolve().parents[1] / "scenes").glob("*.xml"))
#: Volume scenes: their sides render under their own integrators (volpath or path on the
#: iso-surface, volume_slicer), not under raster (test_volume_scene_agrees_as_documented).
VOLUME_SCENES = [p for p in ALL_SCENES if p.stem.startswith("volume_")]
SCENES = [p for p in ALL_SCENES if p not in VOLUME_SCENES]
RES = 64

#: scene -> (FLIP bound, where the guide documents it).
BOUNDS = {
    "bake_bunny": (0.0145, "docs/bake.md, Rendering: FLIP 0.0145 (256², path reference)"),
    "bump_vs_displaced": (0.121, "README showcase table: FLIP 0.121, Mitsuba's bumpmap vs true "
                                 "displacement"),
    "ddm_chains_spot": (0.0074, "docs/ddm.md, Images: ddm_chains_spot FLIP 0.0074"),
    "ddm_genus1": (0.0082, "docs/ddm.md, UV charts: ddm_genus1 FLIP 0.0082 (clamp and drop)"),
    "ddm_stone_wall": (0.0129, "docs/ddm.md, Images: ddm_stone_wall FLIP 0.0129 (maps are exact "
                               "on the plane: the pipelines' agreement)"),
    "ddm_teapot_morph": (0.014, "docs/ddm.md, trade-off over map_resolution: FLIP 0.014 at 128, "
                                "this scene's map_resolution"),
    "ddm_thorns_sphere": (0.048, "docs/ddm.md, Images: FLIP 0.048 at map_resolution 32"),
    # dicing rates are in pixels of the film: at 64² a 1 px micro-edge is the 256² table's 4 px
    "displaced_horizon": (0.0392, "docs/displaced.md, dicing sweep at 256²: displaced_horizon, "
                                  "dicing 4 px FLIP 0.0392 against the 0.5 px reference"),
    "displaced_thin_shell": (0.0193, "docs/displaced.md, thin shell: FLIP of bumpmap 0.0193"),
    "slicing_cup_depth": (0.118, "docs/slicing.md, compare: slicing_cup_depth FLIP 0.118"),
    "slicing_cup_hull": (0.107, "docs/slicing.md, compare: slicing_cup_hull FLIP 0.107"),
    "slicing_donut": (0.124, "docs/slicing.md, compare: slicing_donut FLIP 0.124"),
    "slicing_plane_grazing": (0.031, "docs/slicing.md, compare: slicing_plane_grazing FLIP 0.031"),
    "slicing_spot_depth": (0.077, "docs/slicing.md, compare: slicing_spot_depth FLIP 0.077"),
    # the guide's claim at 82°: VDM (0.0590) is no worse than relief mapping (0.0597); measured
    # here at 256² after the last VDM commits: 0.0593
    "vdm_bricks_grazing": (0.0597, "docs/vdm.md, unseen-style scenes: vdm_bricks_grazing at "
                                   "82°, relief FLIP 0.0597 (raster 256²)"),
    "vdm_corner_normals": (0.0581, "docs/vdm.md, unseen-style scenes: vdm_corner_normals, VDM "
                                   "FLIP 0.0581"),
    "vdm_spot": (0.0274, "docs/vdm.md, Table 1 on Spot: VDM FLIP 0.0274 (raster vs raster)"),
    "vdm_torus": (0.0694, "docs/vdm.md, Table 1 on the torus: VDM FLIP 0.0694 (raster 256²)"),
}
#: Scenes whose documented error is as large as a one-pixel misregistration's (bump mapping's
#: missing relief, 0.121; measured at 64²: 0.091, shifted 0.100): there the bound only catches
#: gross disagreement; the bump map's gradient sign is checked in
#: tests/plugins/test_height_textures.py.
COARSE = {"bump_vs_displaced"}
#: The consistency scene: same geometry on both sides, raster must match path (protocol item 4).
CONSISTENCY = "displaced_sphere"

#: Per-side parameters that keep the test fast, each within what the guides measured:
#: tessellation 1024 (bricks) / 512 (cells on the torus) instead of 2048 changes the 64²
#: reference by FLIP 0.015 / 0.0075 (measured; below each scene's margin to its bound),
#: vdm_res 64 instead of 128 costs FLIP 0.0001 (docs/vdm.md, table sizes: 0.0695 vs 0.0694).
FAST = {
    "bump_vs_displaced": {"reference": {"resolution": 1024}},
    "displaced_sphere": {"reference": {"resolution": 512}, "approximation": {"resolution": 512}},
    "vdm_torus": {"reference": {"resolution": 512}, "approximation": {"vdm_res": 64}},
    "vdm_spot": {"approximation": {"vdm_res": 64}},
}
#: Scenes whose 64² error is above the figure their guide measured at 256² (the depth
#: objects' view-dependent texturing blends three images whose texel footprint grows as the
#: film shrinks): rendered at 128² instead.
for _name in ("slicing_cup_depth", "slicing_cup_hull", "slicing_spot_depth"):
    FAST[_name] = {"reference": {"res": 128}, "approximation": {"res": 128}}
#: ... and at the guide's own 256²: the grazing brick plane (several brick rows per pixel
#: below it: 0.0605 at 128²) and the thin bowl (its rim a pixel wide: 0.0198 at 128²).
for _name in ("vdm_bricks_grazing", "displaced_thin_shell"):
    FAST[_name] = {"reference": {"res": 256}, "approximation": {"res": 256}}
PATH = {"type": "path", "max_depth": 2}


def shoot(scene, spp, seed=0, integrator=None):
    """Render a loaded scene to a finite (H, W, 3) NumPy image."""
    img = np.array(mi.render(scene, spp=spp, seed=seed, integrator=integrator))[..., :3]
    assert np.all(np.isfinite(img)), "non-finite pixels"
    return img


def render(path, spp, seed=0, **params):
    return shoot(mi.load_file(str(path), **{k: str(v) for k, v in params.items()}), spp, seed)


def load_side(path, mode, integrator="raster"):
    """One side of a comparison scene at :data:`RES` with its fast parameters."""
    params = {"res": RES, **FAST.get(path.stem, {}).get(mode, {})}
    return mi.load_file(str(path), mode=mode, integrator=integrator,
                        **{k: str(v) for k, v in params.items()})


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


def misregistered(image):
    """The image moved by one pixel along both axes (a pixel-grid fault)."""
    return np.roll(image, (1, 1), axis=(0, 1))


def test_every_scene_has_a_documented_bound():
    assert {p.stem for p in SCENES} == set(BOUNDS) | {CONSISTENCY}


@pytest.mark.parametrize("path", [p for p in SCENES if p.stem != CONSISTENCY], ids=lambda p: p.stem)
def test_approximation_agrees_with_reference_as_documented(variant, path, elsewhere):
    bound, source = BOUNDS[path.stem]
    reference_scene = load_side(path, "reference")
    reference = shoot(reference_scene, 1)
    traced = shoot(reference_scene, 2, integrator=mi.load_dict(PATH))  # renders under path too
    del reference_scene
    approximation = shoot(load_side(path, "approximation"), 1)
    for what, img in (("reference", reference), ("path-traced reference", traced),
                      ("approximation", approximation)):
        assert img.mean() > 0.01, f"{path.name}: {what} is black"
    error = metrics.flip(reference, approximation)[0]
    assert error <= bound, f"{path.stem}: FLIP {error:.4f} above the documented {bound} ({source})"
    # the bound can fail: a one-pixel misregistration of the same image exceeds it
    shifted = metrics.flip(reference, misregistered(approximation))[0]
    assert (shifted > bound) != (path.stem in COARSE), (shifted, bound)


#: volume scene -> (FLIP bound at 256², where docs/volume.md documents it).
VOLUME_BOUNDS = {
    "volume_consistency": (0.0060, "docs/volume.md, Accuracy: volume_consistency FLIP 0.0060"),
    "volume_walnut_peel": (0.0440, "docs/volume.md, Accuracy: volume_walnut_peel FLIP 0.0440"),
    "volume_nucleon_pull": (0.0100, "docs/volume.md, Accuracy: volume_nucleon_pull FLIP 0.0100"),
    "volume_piggy_seam": (0.0100, "docs/volume.md, Accuracy: volume_piggy_seam FLIP 0.0100"),
    "volume_composite_wave_peel": (0.0174,
                                   "docs/volume.md, Accuracy: volume_composite_wave_peel FLIP 0.0174"),
    "volume_composite_peel_wave": (0.0168,
                                   "docs/volume.md, Accuracy: volume_composite_peel_wave FLIP 0.0168"),
    "volume_piggy_surface": (0.0571, "docs/volume.md, Accuracy: volume_piggy_surface FLIP 0.0571"),
    "volume_piggy_albedo": (0.0101, "docs/volume.md, Accuracy: volume_piggy_albedo FLIP 0.0101"),
}


def test_every_volume_scene_has_a_documented_bound():
    assert {p.stem for p in VOLUME_SCENES} == set(VOLUME_BOUNDS)


@pytest.mark.parametrize("path", VOLUME_SCENES, ids=lambda p: p.stem)
def test_volume_scene_agrees_as_documented(variant, path, elsewhere):
    """Each side under the integrator the scene declares, at 48²: the path-traced reference
    at 2 x 16 spp is noisy, so the documented bound (a converged reference's error) is
    widened by this reference's own two-seed noise floor."""
    bound, source = VOLUME_BOUNDS[path.stem]
    settings = protocol_settings(path)
    load = lambda mode, integrator: mi.load_file(str(path), mode=mode, integrator=integrator,
                                                 res="48")
    reference_scene = load("reference", settings["reference_integrator"])
    a, b = (shoot(reference_scene, 16, seed=s) for s in (0, 1))
    del reference_scene
    approximation = shoot(load("approximation", settings["approximation_integrator"]), 1)
    for what, img in (("reference", a), ("approximation", approximation)):
        assert img.mean() > 0.005, f"{path.name}: {what} is black"
    noise_floor = metrics.flip(a, b)[0]
    error = metrics.flip(0.5 * (a + b), approximation)[0]
    assert error <= bound + noise_floor, (
        f"{path.stem}: FLIP {error:.4f} above the documented {bound} ({source}) + this "
        f"reference's noise floor {noise_floor:.4f}")


def slicer_part(path: Path) -> str:
    """The parts/ file a volume scene includes for its integrator, without the integrator."""
    return re.search(r"parts/(\w+)\$integrator", path.read_text()).group(1)


#: One volume scene per slicer part (each part passes ``$aa`` on by itself).
ONE_PER_SLICER_PART = list({slicer_part(p): p for p in reversed(VOLUME_SCENES)}.values())


@pytest.mark.parametrize("path", ONE_PER_SLICER_PART, ids=lambda p: p.stem)
def test_volume_scene_passes_aa_to_the_slicer(variant, path, elsewhere):
    """``-D aa=N`` reaches the slicer's sub-pixel grid (the knob docs/volume.md measures
    against volpath's box filter); without it the slicer gets the scene's declared ``aa``."""
    declared = int(scene_defaults(path)["aa"])
    integrator = protocol_settings(path)["approximation_integrator"]
    for define, expected in (({}, declared), ({"aa": str(declared + 1)}, declared + 1)):
        scene = mi.load_file(str(path), mode="approximation", integrator=integrator, res="8",
                             **define)
        assert scene.integrator().settings.aa == expected


def test_consistency_scene_raster_matches_path_within_noise(variant, elsewhere):
    """DESIGN protocol item 4 on the same geometry: FLIP(path, raster) <= path's noise floor
    (FLIP between two seeds), as the README's first showcase row documents."""
    path = next(p for p in SCENES if p.stem == CONSISTENCY)
    reference_scene = load_side(path, "reference", "path")
    a, b = (shoot(reference_scene, 16, seed=s) for s in (0, 1))
    del reference_scene
    raster = shoot(load_side(path, "approximation"), 1)
    noise_floor = metrics.flip(a, b)[0]
    error = metrics.flip(0.5 * (a + b), raster)[0]
    assert 0 < error <= noise_floor, (error, noise_floor)
    assert metrics.flip(0.5 * (a + b), misregistered(raster))[0] > noise_floor


@pytest.mark.slow
def test_displaced_reference_is_converged_in_tessellation(variant):
    path = next(p for p in SCENES if p.stem == "displaced_sphere")
    kw = dict(mode="reference", integrator="path", res=128)
    a = [render(path, 256, seed=s, resolution=1024, **kw) for s in (0, 1)]
    b = [render(path, 256, seed=s, resolution=2048, **kw) for s in (2, 3)]
    noise_floor = flip.evaluate(to_srgb(a[0]), to_srgb(a[1]), "LDR")[1]
    doubling = flip.evaluate(to_srgb(0.5 * (a[0] + a[1])), to_srgb(0.5 * (b[0] + b[1])), "LDR")[1]
    assert doubling < noise_floor
