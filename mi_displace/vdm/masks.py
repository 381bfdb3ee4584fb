"""Evaluation masks derived from the reference geometry (the paper's Table 1 effects).

Per pixel centre (one ray each, the raster integrator's sub-sample pattern aside):

* **silhouette**: the reference (true displacement) and the coarse base disagree on
  coverage — one hits the object, the other misses it — dilated by ``dilate`` pixels;
* **shadow**: both hit, and the reference's visible point is hidden from the key light by
  the reference geometry (a shadow ray), while the base point is not (shadows the base
  itself casts are not mesostructure effects);
* **occlusion**: both hit and the visible mesostructure point lies more than
  ``occlusion_shift`` tile units (in texture space) from the base's texture coordinate at
  that pixel — the view ray met the relief elsewhere than straight below P (parallax,
  self-occlusion).

All masks are (H, W) bool NumPy arrays.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy import ndimage

from mi_displace.render import pixel_order
from mi_displace.render.raster import pixel_rays


def _key_light(scene: mi.Scene) -> mi.Emitter:
    for e in scene.emitters():
        if mi.has_flag(e.flags(), mi.EmitterFlags.Delta):
            return e
    raise ValueError("masks: the scene has no delta light (the shadow mask needs one)")


def geometry_masks(reference: mi.Scene, base: mi.Scene, tiling, occlusion_shift: float,
                   dilate: int = 1) -> dict[str, np.ndarray]:
    """Silhouette, shadow and occlusion masks (module doc) for two scenes with the same
    sensor and lights: ``reference`` holds the displaced geometry, ``base`` the coarse mesh.

    Args:
        tiling: (u, v) texture periods per unit uv (tile units = uv * tiling).
        occlusion_shift: threshold [tile units].
        dilate: silhouette dilation [pixels].
    """
    sensor = reference.sensors()[0]
    ray, _, w, h = pixel_rays(sensor, 1)
    si_r = reference.ray_intersect(ray)
    si_b = base.ray_intersect(ray)
    light = _key_light(reference)
    hit_r, hit_b = si_r.is_valid(), si_b.is_valid()
    both = hit_r & hit_b

    def shadowed(scene, si, hit):
        ds, _ = light.sample_direction(si, mi.Point2f(0.5), hit)
        return hit & scene.ray_test(si.spawn_ray_to(ds.p), hit)

    shadow = both & shadowed(reference, si_r, hit_r) & ~shadowed(base, si_b, hit_b)
    du = (si_r.uv.x - si_b.uv.x) * float(tiling[0])
    dv = (si_r.uv.y - si_b.uv.y) * float(tiling[1])
    # texture coordinates are periodic per tile: compare the wrapped difference
    du, dv = du - dr.round(du), dv - dr.round(dv)
    occl = both & (dr.sqrt(du * du + dv * dv) > occlusion_shift)
    shape = (h, w)
    hit_r, hit_b, shadow, occl = (pixel_order.rows(m, w, h) for m in (hit_r, hit_b, shadow, occl))
    hr, hb = np.asarray(hit_r).reshape(shape), np.asarray(hit_b).reshape(shape)
    sil = hr != hb
    if dilate > 0:
        sil = ndimage.binary_dilation(sil, iterations=dilate)
    return {"silhouette": sil,
            "shadow": np.asarray(shadow).reshape(shape) & ~sil,
            "occlusion": np.asarray(occl).reshape(shape) & ~sil,
            "object": hr | hb}


def masked_mean(error_map: np.ndarray, mask: np.ndarray) -> float | None:
    """Mean of ``error_map`` over ``mask`` (None when the mask is empty)."""
    return float(error_map[mask].mean()) if mask.any() else None
