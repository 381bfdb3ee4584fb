"""Inverse displacement on a real mesh (issue 14): the bunny's map recovered from images of
its true geometry, against the map ``mi-displace bake`` produced.

The pair is the baker's (``scenes/parts/bake_bunny/``: ``low.obj``, 4,856 faces with UVs,
and ``d16.png`` baked from the 69,451-face scan ``data/bunny/stanford-bunny.obj``).  The
targets are renders of the *scan* from ``views`` cameras around it, under each of two
directional lights.  The model is a ``displaced`` shape over ``low.obj`` (base ``mesh``,
``subdivision`` 2) whose height is a bitmap of ``map_size``^2 texels, h in [0, 1] meaning a
displacement of ``2 max_distance (h - 0.5)`` object units along the interpolated normal
(the baked map converted to those units is the comparison map).  The optimisation
(:func:`mi_displace.inverse.recover.optimise`) starts from h = 0.5 (the bare low-poly).

Reported: the map error (RMS over the baked map's valid texels, divided by the baked map's
range there) per iteration, the image loss, and the restoration error of each map (the
``displaced`` mesh against the scan: :func:`mi_displace.evaluate.metrics.mesh_distance`,
Hausdorff and RMS relative to the scan's bounding-box diagonal), next to the bare low-poly.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import mitsuba as mi
import numpy as np

from mi_displace.core.resources import data_path, scene_path
from mi_displace.inverse import recover

BAKE = scene_path("parts", "bake_bunny")
SCAN = data_path("bunny", "stanford-bunny.obj")
CENTRE, UP = [-0.017, 0.095, 0.0], [0, 1, 0]


def baked_map(size: int, folder: Path = BAKE) -> tuple[np.ndarray, np.ndarray, float]:
    """(h (size, size) in the model's units, valid (size, size) bool, scale = 2 max_distance)
    from the baker's ``d16.png`` and ``valid.png`` (box-downsampled; a texel is valid when
    every texel under it was)."""
    side = json.loads((folder / "d16.png.json").read_text())
    w, h = side["width"], side["height"]
    if w % size or h % size or w != h:
        raise ValueError(f"'size' must divide the {w}x{h} baked map, got {size}")
    raw = np.asarray(mi.Bitmap(str(folder / side["file"])), np.float64).reshape(h, w, -1)[..., 0]
    d = side["displacement"]["offset"] + side["displacement"]["scale"] * raw
    valid = np.asarray(mi.Bitmap(str(folder / side["valid"])), np.float64).reshape(h, w, -1)[..., 0] > 0
    scale = 2 * side["max_distance"]
    k = w // size
    pool = lambda a: a.reshape(size, k, size, k).mean(axis=(1, 3))  # noqa: E731
    return (pool(d / scale + 0.5).astype(np.float32), pool(valid.astype(np.float64)) == 1, scale)


def origins(views: int, distance: float = 0.42) -> list:
    """Camera origins on a ring around the bunny (y up), 25 degrees above its centre."""
    el = math.radians(25)
    return [[CENTRE[0] + distance * math.cos(el) * math.sin(2 * math.pi * i / views + 0.6),
             CENTRE[1] + distance * math.sin(el),
             CENTRE[2] + distance * math.cos(el) * math.cos(2 * math.pi * i / views + 0.6)]
            for i in range(views)]


def _model(height: np.ndarray, scale: float) -> dict:
    return {"type": "displaced", "base": "mesh", "filename": str(BAKE / "low.obj"),
            "subdivision": 2, "scale": scale, "midlevel": 0.5,
            "height": recover.bitmap_height(height)}


def restoration_error(height: np.ndarray, scale: float, samples: int = 20000) -> dict:
    """The ``displaced`` low-poly over ``height`` against the scan (mesh_distance)."""
    import trimesh

    from mi_displace.evaluate import metrics

    params = mi.traverse(mi.load_dict(_model(height, scale)))
    mesh = (np.asarray(params["vertex_positions"]).reshape(-1, 3),
            np.asarray(params["faces"]).reshape(-1, 3))
    d = metrics.mesh_distance(trimesh.load(str(SCAN), force="mesh"), mesh, samples=samples)
    return {k: d[k] for k in ("hausdorff_rel", "rms_rel", "hausdorff", "rms")}


def recover_bunny(map_size: int = 64, iterations: int = 30, views: int = 4,
                  image_size: int = 96, spp: int = 8, target_spp: int = 64,
                  integrator: str = "prb_projective", learning_rate: float = 0.002,
                  seed: int = 0, log=None) -> recover.Recovery:
    """Optimise the bunny's map from renders of the scan.  The Recovery's ``truth`` is the
    baked map, ``rms`` the map error against it over valid texels / its range there;
    ``settings`` holds ``image_loss`` and ``restoration`` (mesh_distance against the scan)
    of the bare low-poly, the baked map and the optimised map."""
    baked, valid, scale = baked_map(map_size)
    view_origins = origins(views)
    common = (view_origins, CENTRE, UP, 30, image_size)
    targets, scenes = [], []
    for light in recover.LIGHTS:
        lit = [light[0], light[2], light[1]]   # the plane's z-up directions, turned y-up
        scan = mi.load_dict(recover.lit_scene({"type": "obj", "filename": str(SCAN)},
                                              integrator, lit, *common, target_spp))
        targets += [mi.render(scan, sensor=i, spp=target_spp, seed=1000 + i)
                    for i in range(views)]
        scenes.append(mi.load_dict(recover.lit_scene(
            _model(np.full_like(baked, 0.5), scale), integrator, lit, *common, spp)))
    span = float(baked[valid].max() - baked[valid].min())

    def error(h):
        return float(np.sqrt(np.mean((h[valid] - baked[valid]) ** 2)) / span)

    run = recover.optimise(scenes, targets, recover.KEY, np.full_like(baked, 0.5), iterations,
                           views, spp, learning_rate, seed, error, log)
    rec = recover.Recovery(baked, run["estimate"], run["loss"], run["rms"], run["seconds"],
                           settings=dict(map_size=map_size, views=views,
                                         lights=len(recover.LIGHTS), image_size=image_size,
                                         spp=spp, target_spp=target_spp, integrator=integrator,
                                         learning_rate=learning_rate))
    # the image loss of each map against the same targets (8x the samples, one seed)
    param_sets = [mi.traverse(sc) for sc in scenes]
    losses = {}
    for name, h in (("low_poly", np.full_like(baked, 0.5)), ("baked", baked),
                    ("optimised", run["estimate"])):
        for params in param_sets:
            params[recover.KEY] = mi.TensorXf(h[..., None])
            params.update()
        losses[name] = float(recover.image_loss(scenes, param_sets, targets, views, 8 * spp,
                                                seed + 5).array[0])
    rec.settings["image_loss"] = losses
    rec.settings["restoration"] = {name: restoration_error(h, scale) for name, h in (
        ("low_poly", np.full_like(baked, 0.5)), ("baked", baked), ("optimised", run["estimate"]))}
    return rec
