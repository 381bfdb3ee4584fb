"""Inverse displacement (issue 14): recover a height map from images of a ``displaced`` plane.

The target: a ``displaced`` plane (base [-1, 1]^2, z up) whose height is a bitmap texture
holding a real height map (ambientCG Bricks102, CC0, box-downsampled to ``map_size``^2),
rendered from several views under two directional lights.  The unknown: the same bitmap's
``data`` (``map_size``^2 texels in [0, 1]), started flat at 0.5.  Each iteration renders
every view with a projective integrator (gradients of the silhouettes included), takes the
mean L2 image loss over the views, back-propagates through the re-displaced tessellation
(:mod:`plugins.displaced`) into the texels and takes one ``mi.ad.Adam`` step; the texels
are clamped to [0, 1] (the texture's range).

Reported per iteration: image loss, height-map RMS error relative to the true map's range
(max - min), and wall time.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.resources import data_path

BRICKS = data_path("textures", "Bricks102_1K-JPG_Displacement.jpg")
KEY = "surface.height.data"


def load_height_map(path: Path | str = BRICKS, size: int = 64) -> np.ndarray:
    """A square height map in [0, 1]: the image's left square, box-downsampled.

    Returns float32 (size, size); raises FileNotFoundError / ValueError on bad input."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"height map not found: {path}")
    if int(size) != size or size < 2:
        raise ValueError(f"'size' must be an integer >= 2, got {size}")
    bmp = mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.Y, mi.Struct.Type.Float32,
                                       srgb_gamma=False)
    img = np.asarray(bmp, np.float32).reshape(bmp.height(), bmp.width())
    side = min(img.shape) // size * size
    if side == 0:
        raise ValueError(f"{path} is smaller than {size}^2")
    img = img[:side, :side]
    k = side // size
    return img.reshape(size, k, size, k).mean(axis=(1, 3)).astype(np.float32)


def view_origins(views: int, elevation_deg: float = 55.0, distance: float = 3.2) -> list:
    """Camera origins on a ring around the plane's normal at ``elevation_deg`` above it
    (plus one straight above when ``views`` is odd)."""
    if views < 1:
        raise ValueError(f"'views' must be >= 1, got {views}")
    ring = views - views % 2
    el = math.radians(elevation_deg)
    out = [[distance * math.cos(el) * math.cos(2 * math.pi * (i + 0.125) / ring),
            distance * math.cos(el) * math.sin(2 * math.pi * (i + 0.125) / ring),
            distance * math.sin(el)] for i in range(ring)]
    if views % 2:
        out.append([1e-3, 0.0, distance])
    return out


LIGHTS = ([-0.5, -0.3, -1.0], [0.6, 0.4, -0.7])   # directions of the two directional lights


def scene_dict(height: np.ndarray, views: int = 3, image_size: int = 64, spp: int = 8,
               integrator: str = "prb_projective", resolution: int | None = None,
               scale: float = 0.15, light: int = 0, grazing_deg: float | None = None) -> dict:
    """The scene: ``displaced`` plane (key ``surface``) over the bitmap ``height``
    (float (n, n) in [0, 1], midlevel 0.5, ``scale`` object units per unit height),
    ``views`` cameras (``sensor0``...; ``grazing_deg``: their elevation, default 55), lit by
    directional light ``light`` of :data:`LIGHTS` alone (one light per scene: no light
    selection noise; the recovery renders every view under each light, as in photometric
    stereo).  ``resolution``: tessellation cells per side (default 2 per texel).

    ``grazing_deg`` with ``views`` 1 is a ValueError: the single view is the top one, which
    has no elevation to set."""
    if views == 1 and grazing_deg is not None:
        raise ValueError(f"'grazing_deg' ({grazing_deg}) needs 'views' >= 2: the single view "
                         "looks straight down and has no elevation to set")
    n = height.shape[0]
    resolution = 2 * n if resolution is None else resolution
    surface = {"type": "displaced", "base": "plane", "resolution": int(resolution),
               "scale": float(scale), "midlevel": 0.5, "height": bitmap_height(height)}
    origins = view_origins(views, 55.0 if grazing_deg is None else grazing_deg)
    return lit_scene(surface, integrator, LIGHTS[light], origins, [0, 0, 0], [0, 0, 1],
                     34, image_size, spp)


def bitmap_height(height: np.ndarray) -> dict:
    """A raw, bilinear, clamped ``bitmap`` texture over ``height`` (float (n, m))."""
    return {"type": "bitmap", "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp",
            "bitmap": mi.Bitmap(np.ascontiguousarray(np.asarray(height)[..., None], np.float32))}


def lit_scene(surface: dict, integrator: str, light_direction, origins, target, up,
              fov: float, image_size: int, spp: int, albedo: float = 0.7) -> dict:
    """Scene dict: ``surface`` (diffuse ``albedo``) under one directional light (irradiance 2),
    one perspective camera per origin (``sensor0``...) looking at ``target``."""
    # sppi 0: under a directional light the indirect silhouettes carry next to nothing
    integ = {"type": integrator, "sppi": 0}
    if integrator != "direct_projective":
        integ["max_depth"] = 2
    d = {"type": "scene", "integrator": integ,
         "light": {"type": "directional", "direction": list(light_direction),
                   "irradiance": {"type": "rgb", "value": 2.0}},
         "surface": {**surface, "bsdf": {"type": "diffuse",
                                         "reflectance": {"type": "rgb", "value": albedo}}}}
    for i, o in enumerate(origins):
        d[f"sensor{i}"] = {
            "type": "perspective", "fov": fov,
            "to_world": mi.ScalarTransform4f().look_at(origin=o, target=target, up=up),
            "film": {"type": "hdrfilm", "width": image_size, "height": image_size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb",
                     "sample_border": True},
            "sampler": {"type": "independent", "sample_count": spp}}
    return d


def height_rms(estimate: np.ndarray, truth: np.ndarray) -> float:
    """RMS of (estimate - truth) over the texels, divided by the truth's range."""
    span = float(truth.max() - truth.min())
    return float(np.sqrt(np.mean((np.asarray(estimate) - truth) ** 2)) / max(span, 1e-12))


@dataclass
class Recovery:
    """History of one recovery: per iteration ``loss`` (mean L2 over views),
    ``rms`` (height RMS / range, *before* that iteration's step; one extra entry at the end)
    and ``seconds``; ``truth`` / ``estimate`` (n, n); the settings."""
    truth: np.ndarray
    estimate: np.ndarray
    loss: list = field(default_factory=list)
    rms: list = field(default_factory=list)
    seconds: list = field(default_factory=list)
    settings: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {**self.settings, "iterations": len(self.loss),
                "loss_first": self.loss[0], "loss_last": self.loss[-1],
                "rms_first": self.rms[0], "rms_last": self.rms[-1],
                "seconds_per_iteration": float(np.median(self.seconds))}


def render_targets(scenes, views: int, spp: int, seed: int = 1000) -> list:
    """One detached render per (light, view): the target images, light-major."""
    return [mi.render(sc, sensor=i, spp=spp, seed=seed + 97 * k + i)
            for k, sc in enumerate(scenes) for i in range(views)]


def image_loss(scenes, param_sets, targets, views: int, spp: int, seed: int):
    """Mean over (light, view) of the mean squared pixel error (a differentiable mi.Float)."""
    loss, j = 0, 0
    for k, (sc, params) in enumerate(zip(scenes, param_sets)):
        for i in range(views):
            image = mi.render(sc, params, sensor=i, spp=spp, seed=seed + 97 * k + i)
            loss = loss + dr.mean(dr.square(image - targets[j]), axis=None)
            j += 1
    return loss / j


def optimise(scenes, targets, key: str, start: np.ndarray, iterations: int, views: int,
             spp: int, learning_rate: float, seed: int, error, log=None) -> dict:
    """Adam on the texels ``key`` (shared by every scene in ``scenes``) from ``start``
    (float (n, m)), clamped to [0, 1] after each step.

    ``error(texels (n, m)) -> float``: the height error logged before each step and after
    the last.  Returns {estimate, loss, rms, seconds} (lists per iteration)."""
    param_sets = [mi.traverse(sc) for sc in scenes]
    opt = mi.ad.Adam(lr=learning_rate)
    opt[key] = mi.TensorXf(np.asarray(start, np.float32)[..., None])
    for params in param_sets:   # every scene displaces from the same optimised texels
        params.update(opt)
    out = {"loss": [], "rms": [], "seconds": []}
    for it in range(iterations):
        clock = time.perf_counter()
        out["rms"].append(error(np.asarray(opt[key])[..., 0]))
        # one backward over every render: they share the texels' graph to the vertices
        loss = image_loss(scenes, param_sets, targets, views, spp, seed + 7919 * it)
        dr.backward(loss)
        total = float(loss.array[0])
        if not math.isfinite(total):
            raise FloatingPointError(f"recover: image loss is {total} at iteration {it}")
        opt.step()
        opt[key] = dr.clip(opt[key], 0.0, 1.0)
        for params in param_sets:
            params.update(opt)
        out["loss"].append(total)
        out["seconds"].append(time.perf_counter() - clock)
        if log:
            log(f"iteration {it:3d}: loss {total:.4e}  height error {out['rms'][-1]:.4f}  "
                f"{out['seconds'][-1]:.2f} s")
    out["estimate"] = np.asarray(opt[key])[..., 0].copy()
    out["rms"].append(error(out["estimate"]))
    return out


def recover(truth: np.ndarray, iterations: int = 40, views: int = 3, lights: int = 2,
            image_size: int = 64, spp: int = 8, target_spp: int = 128,
            integrator: str = "prb_projective", learning_rate: float = 0.05,
            scale: float = 0.15, seed: int = 0, log=None) -> Recovery:
    """Recover ``truth`` (float (n, n) in [0, 1]) from ``views`` x ``lights`` renders,
    starting from the flat map h = 0.5.

    ``spp`` per render and iteration (fresh seed each iteration); targets at
    ``target_spp``; ``log``: optional callable(str) for progress lines."""
    truth = np.asarray(truth, np.float32)
    if truth.ndim != 2 or truth.shape[0] != truth.shape[1]:
        raise ValueError(f"'truth' must be a square 2-D height map, got shape {truth.shape}")
    if not np.all(np.isfinite(truth)):
        raise ValueError("'truth' holds NaN/Inf")
    if iterations < 1:
        raise ValueError(f"'iterations' must be >= 1, got {iterations}")
    if lights not in (1, 2):
        raise ValueError(f"'lights' must be 1 or 2, got {lights}")
    scenes = [mi.load_dict(scene_dict(truth, views, image_size, spp, integrator, scale=scale,
                                      light=k)) for k in range(lights)]
    targets = render_targets(scenes, views, target_spp)
    faces = int(mi.traverse(scenes[0])["surface.faces"].shape[0] // 3)
    run = optimise(scenes, targets, KEY, np.full_like(truth, 0.5), iterations, views, spp,
                   learning_rate, seed, lambda h: height_rms(h, truth), log)
    rec = Recovery(truth, run["estimate"], run["loss"], run["rms"], run["seconds"], settings=dict(
        map_size=truth.shape[0], views=views, lights=lights, image_size=image_size, spp=spp,
        target_spp=target_spp, integrator=integrator, learning_rate=learning_rate,
        scale=scale, faces=faces))
    # the loss floor: the true map rendered at ``spp`` against the targets (noise alone)
    param_sets = [mi.traverse(sc) for sc in scenes]
    for params in param_sets:
        params[KEY] = mi.TensorXf(truth[..., None])
        params.update()
    rec.settings["loss_noise_floor"] = float(
        image_loss(scenes, param_sets, targets, views, spp, seed + 1).array[0])
    return rec
