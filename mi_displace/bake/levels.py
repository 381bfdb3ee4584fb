"""``levels="auto"`` of the ``restored`` shape (issue 13): subdivision from the map and the screen.

Restoration (§5) splits every low-poly triangle edge into 2^L micro-edges.  Two things bound
what a scene can use:

* **the map** — a micro-edge shorter than a texel samples nothing new: with ``e_tex`` the
  texels along a low-poly edge (its UV length times the map size), L_map = ceil(log2 e_tex);
* **the screen** — a micro-edge shorter than ``dicing_rate`` pixels (Cycles' meaning, 1 px by
  default) is invisible: with ``e_px`` the pixels a low-poly edge spans through the sensor
  (its world length over the pixel footprint at its distance), L_screen = ceil(log2(e_px / rate)).

Both use the 90th percentile over edges (over edges some sensor sees, for the screen), so
the few longest edges set the level, not the outliers; L = min(L_map, L_screen), clamped to
[0, 6].  With several sensors the finest need wins.  Without a sensor L = L_map.

The pixel footprint of a sensor comes from two rays through neighbouring pixels at the
film's centre (perspective: their angle times the distance; orthographic: their spacing),
measured by :func:`pixel_footprint` on any projective Mitsuba sensor.
"""
from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

PERCENTILE = 90
MAX_LEVELS = 6


def pixel_footprint(sensor) -> dict:
    """Origin (3,), unit view direction (3,), radians per pixel (perspective, else 0),
    world units per pixel (orthographic, else 0) and tan of the half field of view along x
    and y of a sensor (float64, world space)."""
    w, h = (int(c) for c in sensor.film().crop_size())
    # the centre, one pixel to its right and the middle of the right edge of the film
    xs = np.array([0.5, 0.5 + 1.0 / w, 1.0])
    ys = np.array([0.5, 0.5, 0.5])
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(mi.Float(xs), mi.Float(ys)), mi.Point2f(0.5, 0.5))
    o = np.broadcast_to(np.asarray(ray.o, np.float64).reshape(3, -1).T, (3, 3))
    d = np.broadcast_to(np.asarray(ray.d, np.float64).reshape(3, -1).T, (3, 3))
    angle = math.acos(min(1.0, float(d[0] @ d[1])))
    half = math.tan(math.acos(min(1.0, float(d[0] @ d[2]))))
    if angle > 1e-9:    # perspective: rays leave the near plane; their apex is the eye
        t = np.linalg.lstsq(np.stack([d[0], -d[2]], 1), o[0] - o[2], rcond=None)[0]
        return {"origin": o[0] - t[0] * d[0], "direction": d[0].copy(), "angle": angle,
                "spacing": 0.0, "tan_half": half, "aspect": h / w}
    return {"origin": o[0].copy(), "direction": d[0].copy(), "angle": 0.0,
            "spacing": float(np.linalg.norm(o[1] - o[0])), "tan_half": 0.0, "aspect": h / w}


def _edges(faces: np.ndarray) -> np.ndarray:
    return np.stack([faces, np.roll(faces, -1, axis=1)], 2).reshape(-1, 2)


def map_levels(low, map_shape) -> tuple[int, float]:
    """L_map and the 90th-percentile texels per low-poly edge for a (H, W) map."""
    H, W = map_shape[:2]
    e = _edges(low.faces)
    duv = (low.uvs[e[:, 1]] - low.uvs[e[:, 0]]) * [W, H]
    texels = float(np.percentile(np.linalg.norm(duv, axis=1), PERCENTILE))
    return max(0, math.ceil(math.log2(max(texels, 1.0)))), texels


def screen_levels(low, sensors, to_world: np.ndarray, dicing_rate: float) -> tuple[int | None, float]:
    """L_screen and the 90th-percentile pixels per visible low-poly edge over the sensors
    (the finest need wins); (None, 0) when no sensor sees the shape."""
    e = _edges(low.faces)
    p = low.positions.astype(np.float64) @ to_world[:3, :3].T + to_world[:3, 3]
    a, b = p[e[:, 0]], p[e[:, 1]]
    length, centre = np.linalg.norm(b - a, axis=1), 0.5 * (a + b)
    best = 0.0
    for sensor in sensors:
        f = pixel_footprint(sensor)
        rel = centre - f["origin"]
        depth = rel @ f["direction"]
        if f["angle"] > 0:   # perspective: inside the view cone (with a margin), in front
            dist = np.linalg.norm(rel, axis=1)
            lateral = np.sqrt(np.maximum(dist ** 2 - depth ** 2, 0))
            limit = 1.2 * f["tan_half"] * math.hypot(1.0, f["aspect"]) * np.maximum(depth, 0)
            seen = (depth > 0) & (lateral <= limit + length)
            px = length / np.maximum(dist * f["angle"], 1e-30)
        else:                # orthographic
            seen = np.ones(len(length), bool)
            px = length / f["spacing"]
        if seen.any():
            best = max(best, float(np.percentile(px[seen], PERCENTILE)))
    if best == 0.0:
        return None, 0.0
    return max(0, math.ceil(math.log2(max(best / dicing_rate, 1.0)))), best


def auto_levels(low, map_shape, sensors, to_world, dicing_rate: float = 1.0) -> tuple[int, dict]:
    """Subdivision levels for a restoration seen through ``sensors`` (see the module
    docstring); returns (levels, the figures behind them)."""
    if not (math.isfinite(dicing_rate) and dicing_rate > 0):
        raise ValueError(f"dicing_rate: must be a positive number of pixels, got {dicing_rate!r}")
    l_map, texels = map_levels(low, map_shape)
    l_screen, pixels = screen_levels(low, sensors, np.asarray(to_world, np.float64), dicing_rate)
    levels = l_map if l_screen is None else min(l_map, l_screen)
    levels = int(min(max(levels, 0), MAX_LEVELS))
    return levels, {"rule": "auto: min(map, screen)" if sensors else "auto: map (no sensor)",
                    "levels_map": l_map, "texels_per_edge_p90": texels,
                    "levels_screen": l_screen, "pixels_per_edge_p90": pixels,
                    "dicing_rate": dicing_rate, "sensors": len(sensors)}
