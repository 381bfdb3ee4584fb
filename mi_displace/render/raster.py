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

Shadow rays and alpha-test continuations leave the surface by :func:`spawn_offset`, a
float32 error bound of the hit point (a fixed number of ulps of the hit triangle's largest
coordinate), not Mitsuba's ``(1 + max|p|) x RayEpsilon``: that offset is absolute near
the origin and grows with the distance from it, so small or distant models lost their
contact shadows (issue 12 item 8, measured in ``docs/raster.md``).

Nothing is random: two renders are bit-identical.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


def _is_delta(emitter: mi.Emitter) -> bool:
    return mi.has_flag(emitter.flags(), mi.EmitterFlags.Delta)


def _is_ambient(emitter: mi.Emitter) -> bool:
    return emitter.class_name() == "ConstantBackgroundEmitter"


#: Half-ulps (2^-24 relative) of the hit triangle's largest coordinate by which a secondary
#: ray's origin leaves the surface along the geometric normal.  Barycentric interpolation of
#: float32 vertices is exact to a few half-ulps; on the thorn sphere acne appears below 8 and
#: contact shadows of a model 1000 units from the origin shrink above ~32 (docs/raster.md).
SPAWN_HALF_ULPS = 32


def spawn_offset(si: mi.SurfaceInteraction3f, d: mi.Vector3f,
                 active: mi.Bool = True) -> mi.Point3f:
    """Origin of a ray leaving ``si`` toward ``d``: ``si.p`` moved off the surface along the
    geometric normal (to the side of ``d``) by ``SPAWN_HALF_ULPS`` x 2^-24 x the largest
    absolute coordinate of the hit point and, on meshes, of the hit triangle's vertices.

    Scale invariant: a model scaled by k gets an offset scaled by k, anywhere in space.
    """
    active = mi.Bool(active)
    scale = dr.max(dr.abs(si.p))
    on_mesh = active & si.is_valid() & si.shape.is_mesh()
    mesh = mi.MeshPtr(si.shape)
    face = mesh.face_indices(si.prim_index, on_mesh)
    for k in range(3):
        vertex = mesh.vertex_position(face[k], on_mesh)
        scale = dr.select(on_mesh, dr.maximum(scale, dr.max(dr.abs(vertex))), scale)
    n = dr.mulsign(mi.Vector3f(si.n), dr.dot(si.n, d))
    return si.p + n * (scale * (SPAWN_HALF_ULPS * 2.0**-24))


def spawn_ray(si: mi.SurfaceInteraction3f, d: mi.Vector3f, active: mi.Bool = True) -> mi.Ray3f:
    """A ray from ``si`` along ``d`` (unbounded), origin by :func:`spawn_offset`."""
    return mi.Ray3f(spawn_offset(si, d, active), d, si.time, si.wavelengths)


def spawn_ray_to(si: mi.SurfaceInteraction3f, target: mi.Point3f,
                 active: mi.Bool = True) -> mi.Ray3f:
    """A shadow ray from ``si`` to ``target`` ending ``ShadowEpsilon`` (relative) short of it."""
    o = spawn_offset(si, target - si.p, active)
    ray = mi.Ray3f(o, target - o, si.time, si.wavelengths)
    ray.maxt = 1.0 - mi.math.ShadowEpsilon
    return ray


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
        ray = dr.select(passes, spawn_ray(si, ray.d, passes), ray)
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
            lit &= ~scene.ray_test(spawn_ray_to(si, ds.p, lit), lit)
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
