"""Table sizes derived from the scene: the projected size of one tile on screen (issue 13).

``res = "auto"`` and ``theta = "auto"`` on the ``vdm`` BSDF (with ``<ref name="sensor"
id="..."/>``) pick the table's texels per tile side and its view polar samples from the
largest on-screen size of one texture tile over the faces of the ``vdm_mesh`` in view:

* ``tile_px`` = ``tile_world W / (2 z tan(fov_x / 2))`` at the smallest camera depth z of a
  face centre in front of the sensor and inside its field of view: the table's tile size
  (the mesh's mean, which the table assumes everywhere) over the width of the view there,
  times the film width W in pixels (the finest need, as Cycles dices for);
* ``res`` = the power of two >= ``tile_px`` (one table texel per pixel at the finest
  point; a coarser table is blurrier than the screen), in [16, 512];
* ``theta``: the step-2 offset of a point at depth D (tile units) seen at polar angle
  theta is D tan(theta) tiles, i.e. ``D tile_px tan(theta)`` pixels; at 60 deg its change
  over one theta spacing dtheta is about D tile_px sec^2(60 deg) dtheta = 4 D tile_px
  dtheta pixels.  One pixel per spacing gives ``n = (pi/2) / dtheta = 2 pi D tile_px``,
  rounded up to even, in [4, 16] (the appendix resampling compiles for minutes beyond;
  on the project's VDM scenes at 128^2 and more the rule asks for the cap, 16).
"""
from __future__ import annotations

import math

import numpy as np

RES_RANGE = (16, 512)
THETA_RANGE = (4, 16)


def projected_tile_pixels(sensor, positions: np.ndarray, faces: np.ndarray,
                          tile_size: float) -> float:
    """Largest on-screen size [pixels] of one tile over the faces in view (module doc).

    Args:
        sensor: a perspective (or thin-lens) ``mi.Sensor``.
        positions: (V, 3) world positions; faces: (F, 3).
        tile_size: world size of one tile (the table's, :func:`mesh_curvature.tile_scale`).

    Returns:
        pixels per tile side at the nearest face centre in view; 0 when none is.
    """
    import mitsuba as mi

    params = mi.traverse(sensor)
    if "x_fov" not in params:
        raise ValueError(f"vdm: 'res'/'theta' = 'auto' needs a perspective sensor, got "
                         f"{type(sensor).__name__}")
    width, height = (int(x) for x in sensor.film().size())
    tan_x = math.tan(math.radians(float(np.asarray(params["x_fov"]).ravel()[0])) / 2)
    tan_y = tan_x * height / width
    m = np.array(sensor.world_transform().inverse().matrix, np.float64).reshape(-1, 4, 4)[0]
    p = np.asarray(positions, np.float64)
    centre = p[np.asarray(faces, np.int64)].mean(1) @ m[:3, :3].T + m[:3, 3]
    z = centre[:, 2]
    seen = ((z > 1e-6) & (np.abs(centre[:, 0]) <= tan_x * z * 1.05)
            & (np.abs(centre[:, 1]) <= tan_y * z * 1.05))
    if not seen.any():
        return 0.0
    return float(tile_size * width / (2 * z[seen].min() * tan_x))


def auto_sizes(tile_px: float, depth_tile: float) -> dict:
    """``res`` and ``theta`` for a tile of ``tile_px`` pixels and depth D (module doc)."""
    lo, hi = RES_RANGE
    res = int(min(hi, max(lo, 2 ** math.ceil(math.log2(max(tile_px, 1.0))))))
    n = 2 * math.ceil(math.pi * depth_tile * tile_px)
    n_theta = int(min(THETA_RANGE[1], max(THETA_RANGE[0], n)))
    return {"tile_px": tile_px, "res": res, "theta": n_theta}
