"""GPU-style rendering: one deterministic sample per pixel (or a fixed N x N pattern),
local illumination of the first visible surface.

For each primary ray: an alpha test passes through surfaces whose BSDF's null
transmission is >= 1/2 (cut-outs, silhouettes of per-pixel techniques), then the first
opaque surface is shaded with its BSDF's ``eval`` (which includes the cosine) under every
delta light (point, spot, directional) with a hard shadow ray, plus an unoccluded
ambient term albedo x L_amb for each ``constant`` emitter.  Rays that miss see the
environment, rays that hit an area light see its radiance.  Area and environment lights
do not illuminate (they are not delta lights).  Shadow rays are blocked by every surface,
null BSDFs included, exactly as the emitter sampling of Mitsuba's ``path``; a technique's
BSDF can add its own shadow test inside ``eval`` (VDM does).

Nothing is random: two renders are bit-identical.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


def _is_delta(emitter: mi.Emitter) -> bool:
    return mi.has_flag(emitter.flags(), mi.EmitterFlags.Delta)


def _is_ambient(emitter: mi.Emitter) -> bool:
    return emitter.class_name() == "ConstantBackgroundEmitter"


def first_opaque_hit(scene: mi.Scene, ray: mi.Ray3f, max_layers: int,
                     active: mi.Bool) -> tuple[mi.SurfaceInteraction3f, mi.Ray3f]:
    """Trace ``ray`` through up to ``max_layers`` surfaces that pass the alpha test.

    Alpha test: the hit's BSDF null transmission (channel mean) >= 0.5 lets the ray go on.

    Returns:
        The first opaque (or last) interaction and the ray that found it.
    """

    def cond(ray, layer, going):
        return going

    def body(ray, layer, going):
        si = scene.ray_intersect(ray, going)
        bsdf = si.bsdf(ray)
        null = dr.mean(bsdf.eval_null_transmission(si, going & si.is_valid()), axis=0)
        passes = going & si.is_valid() & (null >= 0.5) & (layer + 1 < max_layers)
        ray = dr.select(passes, si.spawn_ray(ray.d), ray)
        return ray, layer + 1, passes

    ray, _, _ = dr.while_loop(state=(mi.Ray3f(ray), mi.UInt32(0), mi.Bool(active)),
                              cond=cond, body=body, labels=("ray", "layer", "going"),
                              label="raster_alpha_test")
    return scene.ray_intersect(ray, active), ray


def shade(scene: mi.Scene, ray: mi.Ray3f, max_layers: int = 8,
          active: mi.Bool = True) -> mi.Color3f:
    """Radiance [scene units] along primary rays under local illumination (module doc)."""
    active = mi.Bool(active)
    si, ray = first_opaque_hit(scene, ray, max_layers, active)
    hit = active & si.is_valid()
    L = dr.zeros(mi.Color3f, dr.width(ray.d))
    # Directly visible emitters: area lights on the hit, the environment on a miss.
    emitter = si.emitter(scene, active)
    L += dr.select(active, mi.Color3f(emitter.eval(si, active)), 0.0)
    bsdf = si.bsdf(ray)
    ctx = mi.BSDFContext()
    for e in scene.emitters():
        if _is_delta(e):
            ds, weight = e.sample_direction(si, mi.Point2f(0.5), hit)
            lit = hit & (ds.pdf > 0)
            lit &= ~scene.ray_test(si.spawn_ray_to(ds.p), lit)
            f = bsdf.eval(ctx, si, si.to_local(ds.d), lit)
            L += dr.select(lit, f * weight, 0.0)
        elif _is_ambient(e):
            albedo = bsdf.eval_diffuse_reflectance(si, hit)
            L += dr.select(hit, albedo * e.eval(si, hit), 0.0)
    return L


def pixel_rays(sensor: mi.Sensor, aa: int) -> tuple[mi.Ray3f, mi.Color3f, int, int]:
    """Primary rays through a fixed aa x aa pattern of each pixel (sub-cell centres).

    Returns:
        (rays, weights, width, height); the rays of pixel p are p*aa^2 ... p*aa^2+aa^2-1.
    """
    film = sensor.film()
    w, h = film.crop_size()
    n = aa * aa
    idx = dr.arange(mi.UInt32, w * h * n)
    pixel, sub = idx // n, idx % n
    x = mi.Float(pixel % w) + (mi.Float(sub % aa) + 0.5) / aa
    y = mi.Float(pixel // w) + (mi.Float(sub // aa) + 0.5) / aa
    ray, weight = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / w, y / h), mi.Point2f(0.5))
    return ray, mi.Color3f(weight), int(w), int(h)


def render(scene: mi.Scene, sensor: mi.Sensor, aa: int = 1, max_layers: int = 8) -> mi.TensorXf:
    """Render ``scene`` GPU-style; returns a (height, width, 3) linear RGB tensor.

    The aa x aa sub-samples of a pixel are averaged with equal weights (box filter);
    the film's own reconstruction filter is not used.
    """
    ray, weight, w, h = pixel_rays(sensor, aa)
    L = shade(scene, ray, max_layers) * weight
    n = aa * aa
    if n > 1:
        # evaluate the shading once: each channel's block_reduce would otherwise launch
        # its own copy of the whole shading kernel (3x the work for costly BSDFs)
        dr.eval(L)
        L = mi.Color3f([dr.block_reduce(dr.ReduceOp.Add, c, n) / n for c in L])
    return mi.TensorXf(dr.ravel(L), (h, w, 3))
