"""GPU-style rendering: one deterministic sample per pixel (or a fixed N x N pattern),
local illumination of the first visible surface.

For each primary ray: an alpha test passes through surfaces whose BSDF's null
transmission is >= 1/2 (cut-outs, silhouettes of per-pixel techniques), then the first
opaque surface is shaded with its BSDF's ``eval`` (which includes the cosine) under every
delta light (point, spot, directional, projector) with a hard shadow ray, under a fixed set
of ``area_samples`` points on each area light (:mod:`.lights`, a hard shadow per point),
plus an unoccluded ambient term per ``constant`` or ``envmap`` emitter.  Rays that miss see
the environment, rays that hit an area light see its radiance.  Any other emitter is
refused before the frame (:func:`.lights.emitter_problem`).  Shadow rays are blocked by
every surface, null BSDFs included, exactly as the emitter sampling of Mitsuba's ``path``;
a technique's BSDF can add its own shadow test inside ``eval`` (VDM does).

Shadow rays and alpha-test continuations leave the surface by :func:`spawn_offset`, a
float32 error bound of the hit point (a fixed number of ulps of the hit triangle's largest
coordinate), not Mitsuba's ``(1 + max|p|) x RayEpsilon``: that offset is absolute near
the origin and grows with the distance from it, so small or distant models lost their
contact shadows (measured in ``docs/raster.md``).

Visibility and shadows are chosen per scene (:class:`Options`): ray tracing through
Mitsuba's acceleration structure (the default) or the z-buffer of :mod:`.zbuffer`, shadow
rays or the shadow maps of :mod:`.shadow_map` (a cube map per area-light point); with
z-buffer and shadow maps no acceleration structure is needed
(:func:`render`'s ``shapes``).

A shape may draw itself GPU-style before the frame: :func:`render` calls
``raster_begin(sensor, aa)`` on every shape that has it before visibility and
``raster_end()`` after shading (the slicing shapes rasterise their slices there,
:mod:`mi_displace.slicing.rasterised`).  Under ``freeze`` that drawing stays outside the
recording (it reads back what it drew) and what it leaves is the recorded frame's input, so
it must be reachable from the shape as Dr.Jit arrays and PyTrees (dataclasses, tuples,
dicts; Dr.Jit does not look into a ``NamedTuple`` held by a plugin).

Nothing is random: two renders are bit-identical.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.render import lights, pixel_order, shadow_map, zbuffer

VISIBILITY = ("raytrace", "zbuffer")
SHADOWS = ("ray", "map", "none")


#: Half-ulps (2^-24 relative) of the hit triangle's largest coordinate by which a secondary
#: ray's origin leaves the surface along the geometric normal.  Barycentric interpolation of
#: float32 vertices is exact to a few half-ulps; on the thorn sphere acne appears below 8 and
#: contact shadows of a model 1000 units from the origin shrink above ~32 (docs/raster.md).
SPAWN_HALF_ULPS = 32
#: The frame's rays (primary rays and their alpha-test continuations in pixel order, shadow
#: rays from neighbouring points towards one light point) are traced as coherent rays:
#: Embree's packet traversal finds the same hits, bit for bit, in less time
#: (scripts/coherent_ab.py, 512^2, one sample a pixel: 0.70-0.75x the restored bunny's
#: frame, 0.75-0.77x the HDDM thorns', 0.83-0.91x relief's, 0.98-1.05x the 2048-tessellated
#: torus'; a path tracer's scattered rays are slower so).
COHERENT = True


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


def _pass_through_count(shapes) -> int:
    """Surfaces a ray may pass through among ``shapes`` (BSDF with a null component): the
    triangles of a mesh (a ray crosses a plane triangle at most once, :func:`spawn_offset`
    moves it past), 2 for any other shape (a quadric or a plane is crossed at most twice)."""
    count = 0
    for shape in shapes:   # a handful of shapes
        bsdf = shape.bsdf()
        if bsdf is not None and mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null):
            count += int(shape.face_count()) if shape.is_mesh() else 2
    return count


def layer_limit(shapes, scene: mi.Scene | None = None) -> int:
    """The most alpha-test pass-throughs a ray can need among ``shapes``: 1 + their
    pass-through surfaces, and with shape groups (their shapes are reachable only through
    ``scene``'s parameters, and Mitsuba 3.9.1 does not tell an instance from Python) those
    of every grouped shape once per top-level shape, a bound for any number of instances.
    The ``max_layers`` that never cuts a ray short; the loops run only as long as the
    longest chain of pass-throughs actually met."""
    shapes = list(shapes)
    limit = 1 + _pass_through_count(shapes)
    if scene is not None:
        top = {id(s) for s in shapes}
        grouped = {id(node): node for _, _, node, _ in mi.traverse(scene).properties.values()
                   if isinstance(node, mi.Shape) and id(node) not in top}
        limit += len(shapes) * _pass_through_count(grouped.values())
    return limit


def warn_exhausted(count: int, total: int, max_layers: int) -> None:
    """Warn that ``count`` of ``total`` samples met more pass-through surfaces than
    ``max_layers`` (they show the last one, not what lies behind it)."""
    if count:
        warnings.warn(f"raster: {count} of {total} samples crossed more than max_layers="
                      f"{max_layers} pass-through (alpha-tested) surfaces and show the last "
                      "one, not what lies behind it; raise 'max_layers' or leave it unset "
                      "(sized from the scene)", stacklevel=3)


def first_opaque_hit(scene: mi.Scene, ray: mi.Ray3f, max_layers: int | None,
                     active: mi.Bool) -> tuple[mi.SurfaceInteraction3f, mi.Ray3f, mi.Bool]:
    """Trace ``ray`` through up to ``max_layers`` surfaces that pass the alpha test
    (``None``: :func:`layer_limit` of the scene's shapes, never reached).

    Alpha test: the hit's BSDF null transmission (channel mean) >= 0.5 lets the ray go on.
    The loop keeps each ray's last interaction, so the interaction returned is the one the
    alpha test saw (what ``scene.ray_intersect`` of the returned ray gives, bit for bit),
    not built a second time.

    Returns:
        The first opaque (or last) interaction, the ray that found it, and per ray whether
        the limit stopped it on a surface that passes the alpha test (``exhausted``).
    """
    if max_layers is None:
        max_layers = layer_limit(scene.shapes(), scene)

    def cond(ray, si, layer, going, exhausted):
        return going

    def body(ray, si, layer, going, exhausted):
        si = scene.ray_intersect(ray, mi.RayFlags.All, COHERENT, going)
        bsdf = si.bsdf(ray)
        null = dr.mean(bsdf.eval_null_transmission(si, going & si.is_valid()), axis=0)
        clear = going & si.is_valid() & (null >= 0.5)
        passes = clear & (layer + 1 < max_layers)
        exhausted = clear & ~passes
        ray = dr.select(passes, spawn_ray(si, ray.d, passes), ray)
        return ray, si, layer + 1, passes, exhausted

    n = dr.width(ray)   # a ray component may be width 1 (a camera's origin or direction)
    miss = dr.zeros(mi.SurfaceInteraction3f, n)
    miss.t = dr.full(mi.Float, dr.inf, n)   # lanes never traced (inactive)
    ray, si, _, _, exhausted = dr.while_loop(
        state=(mi.Ray3f(ray), miss, mi.UInt32(0), mi.Bool(active), dr.zeros(mi.Bool, n)),
        cond=cond, body=body, labels=("ray", "si", "layer", "going", "exhausted"),
        label="raster_alpha_test")
    return si, ray, exhausted


@dataclass
class Options:
    """How `raster` finds what a pixel sees and what a light sees.

    Attributes:
        visibility: ``"raytrace"`` (one ray per sample through Mitsuba's acceleration
            structure) or ``"zbuffer"`` (triangles rasterised, :mod:`.zbuffer`).
        shadows: ``"ray"`` (a hard shadow ray per delta light), ``"map"`` (shadow maps,
            :mod:`.shadow_map`) or ``"none"`` (delta lights unshadowed).
        shadow_resolution: shadow-map texels per side (cube faces for point lights).
        shadow_bias, shadow_normal_offset: shadow-map depth bias and normal offset, in texels.
        area_samples: fixed light points per area emitter (:mod:`.lights`), each with a
            shadow ray (``shadows="ray"``) or a cube shadow map (``"map"``).
        area_shadow_resolution: texels per side of each area-light point's cube-map faces.
    """
    visibility: str = "raytrace"
    shadows: str = "ray"
    shadow_resolution: int = 2048
    shadow_bias: float = 0.5
    shadow_normal_offset: float = 0.5
    area_samples: int = 16
    area_shadow_resolution: int = 256

    def check(self) -> "Options":
        """Raises ValueError naming the first bad field."""
        if self.visibility not in VISIBILITY:
            raise ValueError(f"raster: 'visibility' must be one of {VISIBILITY}, "
                             f"got {self.visibility!r}")
        if self.shadows not in SHADOWS:
            raise ValueError(f"raster: 'shadows' must be one of {SHADOWS}, got {self.shadows!r}")
        for name in ("shadow_resolution", "area_shadow_resolution"):
            value = getattr(self, name)
            if not (isinstance(value, int) and 1 <= value <= 16384):
                raise ValueError(f"raster: {name!r} must be an integer in [1, 16384], "
                                 f"got {value!r}")
        for name in ("shadow_bias", "shadow_normal_offset"):
            value = getattr(self, name)
            if not (value >= 0 and value < float("inf")):
                raise ValueError(f"raster: {name!r} must be finite and >= 0, got {value!r}")
        if not (isinstance(self.area_samples, int)
                and 1 <= self.area_samples <= lights.MAX_AREA_SAMPLES):
            raise ValueError(f"raster: 'area_samples' must be an integer in "
                             f"[1, {lights.MAX_AREA_SAMPLES}], got {self.area_samples!r}")
        return self


def shade_hit(scene: mi.Scene, si: mi.SurfaceInteraction3f, ray: mi.Ray3f, active: mi.Bool,
              shadow_test, light_data: lights.Lights, area_shadow_test) -> mi.Color3f:
    """Local illumination of the visible interactions ``si`` (module doc).

    ``shadow_test(emitter, si, ds, lit) -> Bool`` says which points see a delta light;
    ``area_shadow_test(si, hit)`` returns ``test(k, ds, lit) -> Bool``, which points see
    area-light point ``k`` (:func:`area_shadow_test_of`).
    Every BSDF query of a sample for the delta and ambient lights (``eval`` per delta
    light, ``eval_diffuse_reflectance``) runs in one dispatch over the BSDFs, so a BSDF
    that prepares its interaction once (the mesostructure BSDFs' ``_prepare``: a slice
    walk, a VDM footprint) does it once per sample, not once per query; the area-light
    points are a loop of Mitsuba's own ``eval`` calls (one preparation per point).
    """
    hit = active & si.is_valid()
    L = dr.zeros(mi.Color3f, dr.width(ray))
    # Directly visible emitters: area lights on the hit, the environment on a miss.
    emitter = si.emitter(scene, active)
    L += dr.select(active, mi.Color3f(emitter.eval(si, active)), 0.0)
    ctx = mi.BSDFContext()
    deltas = []   # (weight, local direction to the light, lit) per delta light
    for e in scene.emitters():
        if lights.is_delta(e):
            ds, weight = e.sample_direction(si, mi.Point2f(0.5), hit)
            lit = hit & (ds.pdf > 0)
            lit &= shadow_test(e, si, ds, lit)
            deltas.append((weight, si.to_local(ds.d), lit))
    ambient = any(lights.is_constant(e) or lights.is_envmap(e) for e in scene.emitters())

    def queries(bsdf, si, wos, lits, hit):
        if bsdf is None:   # no BSDF exists (a scene without shapes): only the output types
            zero = dr.zeros(mi.Spectrum, dr.width(hit))
            return [zero] * len(wos), [zero] if ambient else []
        # asked first, in the dispatch's own scope (unread without an ambient light, then
        # left out of the kernel): a BSDF's cached per-interaction preparation is made
        # here and shared by the branches below, not made inside one of them
        albedo = bsdf.eval_diffuse_reflectance(si, hit)
        # eval under a symbolic if: a SIMD packet with no lit sample skips it, as the
        # separate vcall masked by ``lit`` did (si from the closure: the same variables)
        f = [dr.if_stmt((wo, lit), lit,
                        lambda wo, lit: bsdf.eval(ctx, si, wo, lit),
                        lambda wo, lit: dr.zeros(mi.Spectrum, dr.width(lit)), label="raster_eval")
             for wo, lit in zip(wos, lits)]
        return f, [albedo] if ambient else []

    bsdf = si.bsdf(ray)
    f, albedo = dr.dispatch(bsdf, queries, si, [wo for _, wo, _ in deltas],
                            [lit for *_, lit in deltas], hit)
    delta = iter(zip(f, deltas))
    if ambient:   # n on the viewer's side, for the envmaps' irradiance
        n = dr.mulsign(si.sh_frame.n, dr.dot(si.sh_frame.n, -ray.d))
    for e in scene.emitters():   # summed in the scene's emitter order
        if lights.is_delta(e):
            value, (weight, _, lit) = next(delta)
            L += dr.select(lit, value * weight, 0.0)
        elif lights.is_constant(e):
            L += dr.select(hit, albedo[0] * e.eval(si, hit), 0.0)
        elif lights.is_envmap(e):
            L += dr.select(hit, albedo[0] * lights.sh_irradiance(light_data.envmaps[id(e)], n),
                           0.0)
    if light_data.area.count:
        L += area_light(si, bsdf, hit, light_data.area, area_shadow_test(si, hit))
    return L


def area_light(si: mi.SurfaceInteraction3f, bsdf: mi.BSDFPtr, hit: mi.Bool,
               samples: lights.AreaSamples, visible) -> mi.Color3f:
    """Reflected radiance of the visible points ``si`` lit by the fixed area-light points
    ``samples``: Σ_k f(wo_k) × weight_k × visible(k, ds, lit), a symbolic loop over the
    K points."""
    ctx = mi.BSDFContext()
    count = samples.count

    def body(k, L):
        ds, weight = lights.area_sample_toward(samples, k, si, hit)
        lit = hit & (dr.max(weight) > 0)
        lit &= visible(k, ds, lit)
        f = bsdf.eval(ctx, si, si.to_local(ds.d), lit)
        return k + 1, L + dr.select(lit, f * weight, 0.0)

    n = dr.width(hit)
    _, L = dr.while_loop(state=(dr.zeros(mi.UInt32, n), dr.zeros(mi.Color3f, n)),
                         cond=lambda k, L: k < count, body=body, labels=("k", "L"),
                         label="raster_area_lights")
    return L


def ray_shadows(scene: mi.Scene):
    """Shadow test by one shadow ray per light through the scene's acceleration structure."""
    def test(emitter, si, ds, lit):
        return ~scene.ray_test(spawn_ray_to(si, ds.p, lit), COHERENT, lit)
    return test


def map_shadows(scene: mi.Scene, geom: zbuffer.Geometry, options: Options):
    """Shadow test by a shadow map per delta light (built here, once per render)."""
    if dr.width(geom.faces) == 0:
        return no_shadows   # nothing casts a shadow (and the scene has no bounds)
    maps = {}
    for e in scene.emitters():
        if lights.is_delta(e):
            maps[id(e)] = shadow_map.build(e, geom, options.shadow_resolution,
                                           options.shadow_bias, options.shadow_normal_offset)

    def test(emitter, si, ds, lit):
        return shadow_map.unshadowed(maps[id(emitter)], si, ds.d, lit)
    return test


def no_shadows(emitter, si, ds, lit):
    return mi.Bool(True)


def area_shadow_test_of(scene: mi.Scene, geom, options: Options,
                        samples: lights.AreaSamples):
    """``(si, hit) -> test(k, ds, lit)``: which visible points see area-light point k —
    a shadow ray (``shadows="ray"``), a lookup in the point's cube shadow map
    (``"map"``: the maps are rasterised when ``si`` is known, one point at a time, and
    their answers packed into bits), or everywhere (``"none"``)."""
    def rays(si, hit):
        return lambda k, ds, lit: ~scene.ray_test(spawn_ray_to(si, ds.p, lit), COHERENT, lit)

    def maps(si, hit):
        words = area_map_visibility(si, hit, geom, options, samples)
        words_per_lane = (samples.count + 31) // 32
        lane = dr.arange(mi.UInt32, dr.width(hit))

        def test(k, ds, lit):
            word = dr.gather(mi.UInt32, words, lane * words_per_lane + k // 32, lit)
            return ((word >> (k % 32)) & 1) != 0
        return test

    def everywhere(si, hit):
        return lambda k, ds, lit: mi.Bool(True)

    if options.shadows == "ray":
        return rays
    if options.shadows == "map" and samples.count and dr.width(geom.faces):
        return maps
    return everywhere


def area_map_visibility(si: mi.SurfaceInteraction3f, hit: mi.Bool, geom: zbuffer.Geometry,
                        options: Options, samples: lights.AreaSamples) -> mi.UInt32:
    """Which area-light points each visible point sees, by a cube shadow map per point
    (``options.area_shadow_resolution``, the delta lights' bias and normal offset).

    Returns:
        (n x W,) UInt32 words, W = ceil(K / 32): bit k % 32 of word lane x W + k // 32 is
        set where lane sees point k.
    """
    n, count = dr.width(hit), samples.count
    per_lane = (count + 31) // 32
    dr.eval(si, hit)   # the K lookups below read the interactions, not recompute them
    points = np.array(samples.ps.p).T   # (K, 3)
    words = [dr.zeros(mi.UInt32, n) for _ in range(per_lane)]
    res = options.area_shadow_resolution
    for k in range(count):   # the light points, one cube map each (not elements)
        sm = shadow_map.build_views(shadow_map.point_views(points[k], geom.bbox, res), geom,
                                    res, options.shadow_bias, options.shadow_normal_offset,
                                    f"the shadow map of area-light point {k}")
        # opaque: the K lookups share one compiled kernel
        point = dr.gather(mi.Point3f, samples.ps.p, dr.opaque(mi.UInt32, k))
        to_light = dr.normalize(point - si.p)
        seen = shadow_map.unshadowed(sm, si, to_light, hit)
        words[k // 32] |= dr.select(seen, dr.opaque(mi.UInt32, 1 << (k % 32)), 0)
        dr.eval(words[k // 32])
    flat = dr.zeros(mi.UInt32, n * per_lane)
    lane = dr.arange(mi.UInt32, n)
    for w, word in enumerate(words):   # ceil(K / 32) words
        dr.scatter(flat, word, lane * per_lane + w)
    return flat


def shadow_test_of(scene: mi.Scene, geom, options: Options):
    """The shadow test ``options.shadows`` names (shadow maps are built here)."""
    if options.shadows == "ray":
        return ray_shadows(scene)
    if options.shadows == "map":
        return map_shadows(scene, geom, options)
    return no_shadows


def light_masks(scene: mi.Scene, sensor: mi.Sensor, options: Options,
                aa: int = 1) -> tuple[mi.Bool, list]:
    """Which visible points (ray-traced visibility) each delta light reaches, by
    ``options.shadows`` — to measure shadow maps against shadow rays on the same points.

    Returns:
        (hit, masks): samples that see a surface, and one Bool per delta light (in
        ``scene.emitters()`` order) that is True where the light reaches the point.
    """
    options = options.check()
    ray, _, _, _ = pixel_rays(sensor, aa)
    si, ray, _ = first_opaque_hit(scene, ray, None, mi.Bool(True))
    hit = si.is_valid()
    geom = zbuffer.gather_geometry(scene.shapes()) if options.shadows == "map" else None
    test = shadow_test_of(scene, geom, options)
    masks = []
    for e in scene.emitters():
        if lights.is_delta(e):
            ds, _ = e.sample_direction(si, mi.Point2f(0.5), hit)
            lit = hit & (ds.pdf > 0)
            masks.append(lit & test(e, si, ds, lit))
    return hit, masks


def shade(scene: mi.Scene, ray: mi.Ray3f, max_layers: int | None = None,
          active: mi.Bool = True, area_samples: int = Options.area_samples) -> mi.Color3f:
    """Radiance [scene units] along primary rays: ray-traced visibility and shadows
    (``max_layers``: :func:`first_opaque_hit`; ``area_samples``: points per area light).

    Raises:
        ValueError: an emitter raster cannot draw (:func:`.lights.emitter_problem`).
    """
    lights.check(scene)
    light_data = lights.prepare(scene, area_samples)
    active = mi.Bool(active)
    si, ray, _ = first_opaque_hit(scene, ray, max_layers, active)
    area_test = area_shadow_test_of(scene, None, Options(), light_data.area)   # rays
    return shade_hit(scene, si, ray, active, ray_shadows(scene), light_data, area_test)


def pixel_rays(sensor: mi.Sensor, aa: int) -> tuple[mi.Ray3f, mi.Color3f, int, int]:
    """Primary rays through a fixed aa x aa pattern of each pixel (sub-cell centres).

    Returns:
        (rays, weights, width, height); the rays of the pixel at frame lane p
        (:mod:`.pixel_order`: 4 x 4 tiles; :func:`.pixel_order.image` makes the image) are
        p*aa^2 ... p*aa^2+aa^2-1, its sub-samples row by row.
    """
    w, h = (int(v) for v in sensor.film().crop_size())
    n = aa * aa
    idx = dr.arange(mi.UInt32, w * h * n)
    lane, sub = idx // n, idx % n
    px, py = pixel_order.pixel_of(lane, w, h)
    x = mi.Float(px) + (mi.Float(sub % aa) + 0.5) / aa
    y = mi.Float(py) + (mi.Float(sub // aa) + 0.5) / aa
    ray, weight = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / w, y / h), mi.Point2f(0.5))
    return ray, mi.Color3f(weight), int(w), int(h)


def zbuffer_hit(sensor: mi.Sensor, geom: zbuffer.Geometry, ray: mi.Ray3f, aa: int,
                max_layers: int = 8) -> tuple[mi.SurfaceInteraction3f, int]:
    """What each primary ray sees, by z-buffer: rasterise, resolve, build interactions.

    Alpha test: a fragment of a shape whose BSDF has a null component does not count where
    its null transmission (channel mean) is >= 1/2 — a GPU's fragment discard.  It is
    evaluated lazily, by depth peeling: only the winning fragment of each sample is tested
    and, where it is discarded, the sample is rasterised again keeping only fragments
    behind it (up to ``max_layers`` layers, like the ray-traced path), so the alpha shader
    runs once per sample and layer, not once per fragment.

    Returns:
        The interactions and how many samples still saw a discarded fragment after
        ``max_layers`` layers (they show it: :func:`warn_exhausted`).
    """
    view = zbuffer.view_from_sensor(sensor, aa)
    if dr.width(geom.faces) == 0:   # nothing to draw: every sample misses
        si = dr.zeros(mi.SurfaceInteraction3f, dr.width(ray))
        si.t, si.wi, si.wavelengths = dr.inf, -ray.d, ray.wavelengths
        return si, 0
    keys, clip = zbuffer.rasterise(view, geom, True, aa=aa)

    def resolve(index, keys, ray):
        """Interactions of the samples ``index`` whose keys are ``keys``."""
        hit = keys != zbuffer.EMPTY
        tri = mi.UInt32(keys & 0xFFFFFFFF)
        X, Y = zbuffer.sample_xy(view, index, aa)
        _, b1, b2, _ = zbuffer.fragment(view, clip, geom, tri, X, Y, hit)
        pi = zbuffer.preliminary(geom, tri, b1, b2, ray, hit)
        si = pi.compute_surface_interaction(ray, mi.RayFlags.All, hit)
        alpha = hit & dr.gather(mi.Bool, geom.alpha,
                                dr.gather(mi.UInt32, geom.shape_of, tri, hit), hit)
        return si, alpha

    everything = dr.arange(mi.UInt32, dr.width(keys))
    pending = everything   # samples whose winning fragment may be discarded

    def discarded(pending):
        r = dr.gather(mi.Ray3f, ray, pending)
        si, alpha = resolve(pending, dr.gather(mi.UInt64, keys, pending), r)
        null = dr.mean(si.bsdf(r).eval_null_transmission(si, alpha), axis=0)
        return dr.gather(mi.UInt32, pending, dr.compress(alpha & (null >= 0.5)))

    for _ in range(max_layers - 1 if geom.alpha_any else 0):
        pending = discarded(pending)
        if dr.width(pending) == 0:
            break
        floor = dr.full(mi.UInt64, zbuffer.EMPTY, dr.width(keys))
        dr.scatter(floor, dr.gather(mi.UInt64, keys, pending), pending)
        behind, _ = zbuffer.rasterise(view, geom, True, aa=aa, floor=floor)
        dr.scatter(keys, dr.gather(mi.UInt64, behind, pending), pending)
        dr.eval(keys)
    else:   # the limit ran out: the samples it cut short (none if nothing is alpha-tested)
        pending = discarded(pending) if geom.alpha_any else dr.zeros(mi.UInt32, 0)
    return resolve(everything, keys, ray)[0], dr.width(pending)


def _shaded(scene: mi.Scene, sensor: mi.Sensor, aa: int, limit: int, options: Options,
            light_data: lights.Lights, geom) -> tuple[mi.TensorXf, mi.Bool | int]:
    """The frame after the lights are prepared: pixel rays, visibility, shading, box filter.

    Returns:
        The (height, width, 3) image and the samples ``limit`` cut short (a Bool per sample
        when ray-traced, a count by z-buffer).
    """
    ray, weight, w, h = pixel_rays(sensor, aa)
    active = mi.Bool(True)
    if options.visibility == "raytrace":
        si, ray, cut = first_opaque_hit(scene, ray, limit, active)
    else:
        si, cut = zbuffer_hit(sensor, geom, ray, aa, limit)
    L = shade_hit(scene, si, ray, active, shadow_test_of(scene, geom, options),
                  light_data, area_shadow_test_of(scene, geom, options, light_data.area))
    L *= weight
    dr.eval(L, cut)   # one kernel: the alpha-test loop's outputs together
    n = aa * aa
    if n > 1:
        # the shading evaluated once (above): each channel's block_reduce would otherwise
        # launch its own copy of the whole shading kernel (3x the work for costly BSDFs)
        L = mi.Color3f([dr.block_reduce(dr.ReduceOp.Add, c, n) / n for c in L])
    return pixel_order.image(L, w, h), cut


def scalar_state(*nodes) -> tuple:
    """What a recorded frame would hold as constants: every ``mi.traverse`` parameter of
    ``nodes`` that is not a Dr.Jit array (a C++ scalar such as ``bumpmap``'s ``scale``, a
    film size, a plugin's scalar parameter), as ``(key, repr(value))`` pairs.  The Dr.Jit
    arrays (positions, colours, the sensor's ``to_world``) are inputs a frozen frame reads
    anew; a change of this tuple makes :class:`FrozenFrames` record the frame again."""
    state = []
    for node in nodes:   # the scene and its sensor
        params = mi.traverse(node)
        for key in params.keys():   # a scene's parameters, not elements
            value = params[key]
            if not dr.is_jit_v(getattr(value, "matrix", value)):   # transforms hold .matrix
                state.append((key, repr(value)))
    return tuple(state)


class FrozenFrames:
    """``dr.freeze`` of :func:`render`'s ray-traced frame (``raster``'s ``freeze``): the
    frame's kernels are recorded once per scene configuration and replayed, so a frame
    costs its kernels plus the lights' preparation, not Python tracing and launches.

    The recording is keyed on the frame's Dr.Jit inputs (traversed through the scene and
    the sensor: geometry, textures, the camera), on ``aa``, the layer limit and the options,
    and on :func:`scalar_state` (the values a kernel holds as constants): an edit through
    ``mi.traverse`` of any of them records the frame again.  Shapes that draw themselves
    (``raster_begin``: the slicing shapes rasterise their slices with read-backs) draw
    before the recorded frame, which reads what they drew.  Frames of scenes whose BSDFs
    say they cannot be recorded (a class attribute ``FREEZABLE = False``, for a user's
    plugin whose state Dr.Jit cannot traverse) and whose recording Dr.Jit refuses (an array
    a recording does not find among its inputs) are drawn unfrozen, with one warning per
    scene naming the reason.
    """

    #: Recordings kept (least recently used dropped): each holds a frame's kernels.
    LIMIT = 8

    def __init__(self):
        self.function = dr.freeze(self._frame, limit=self.LIMIT, warn_after=2**31 - 1)
        self.refused: dict[int, str] = {}   # id(scene) -> why its frames are not frozen

    @staticmethod
    def _frame(scene, sensor, aa, limit, options, light_data, state):
        image, cut = _shaded(scene, sensor, aa, limit, options, light_data, None)
        return image, dr.count(cut)

    @staticmethod
    def check(options: Options) -> Options:
        """``options`` if a frame under them can be frozen; else ValueError (one line)."""
        if options.visibility != "raytrace" or options.shadows == "map":
            raise ValueError("raster: 'freeze' needs visibility='raytrace' and shadows='ray' "
                             "or 'none' (the z-buffer and shadow maps size their passes from "
                             "what a frame finds)")
        return options

    def __call__(self, scene, sensor, aa, limit, options, light_data):
        """The frame, replayed (or recorded) as ``(image, samples cut short)``; ``None``
        when it cannot be frozen (the reason remembered for ``scene``, warned about once)."""
        if id(scene) not in self.refused:
            why = self.unrecordable(scene)
            if why is not None:
                self._refuse(scene, why)
        if id(scene) in self.refused:
            return None
        try:
            image, cut = self.function(scene, sensor, aa, limit, options, light_data,
                                       scalar_state(scene, sensor))
        except RuntimeError as error:   # the recording failed: nothing was replayed
            self._refuse(scene, "Dr.Jit refused to record it: "
                         + str(error.__cause__ or error).strip().splitlines()[0])
            return None
        return image, int(cut[0])

    @staticmethod
    def unrecordable(scene) -> str | None:
        """Why ``scene``'s frame must not be recorded, known before recording: a BSDF
        whose class says ``FREEZABLE = False`` (its state is not traversable: a recording
        over it may abort the process rather than raise).  ``None`` otherwise."""
        for shape in scene.shapes():   # a handful of shapes
            bsdf = shape.bsdf()
            if not getattr(bsdf, "FREEZABLE", True):
                return (f"BSDF {bsdf.id() or type(bsdf).__name__!r} is not recordable "
                        "(FREEZABLE = False)")
        return None

    def _refuse(self, scene, why: str) -> None:
        self.refused[id(scene)] = why
        warnings.warn(f"raster: freeze: this scene's frames are drawn unfrozen ({why})",
                      stacklevel=4)


def render(scene: mi.Scene, sensor: mi.Sensor, aa: int = 1, max_layers: int | None = None,
           options: Options | None = None, shapes=None,
           frozen: FrozenFrames | None = None) -> mi.TensorXf:
    """Render ``scene`` GPU-style; returns a (height, width, 3) linear RGB tensor.

    The aa x aa sub-samples of a pixel are averaged with equal weights (box filter);
    the film's own reconstruction filter is not used.

    Args:
        max_layers: alpha-test pass-throughs per sample; ``None``: :func:`layer_limit`
            of the drawn shapes (never reached).  Samples a given limit cuts short are
            counted and warned about (:func:`warn_exhausted`).
        options: visibility and shadow methods (default: ray tracing, shadow rays).
        shapes: the meshes to draw instead of ``scene.shapes()`` — with
            ``visibility="zbuffer"`` and ``shadows="map"|"none"`` the scene then needs no
            shapes at all, so Mitsuba builds no acceleration structure over them.
        frozen: replay the frame's recorded kernels (:class:`FrozenFrames`); needs
            ``visibility="raytrace"`` and ``shadows`` ``"ray"`` or ``"none"`` (hence no
            ``shapes``).

    Raises:
        ValueError: bad options, an emitter raster cannot draw, a film whose sample
            buffers exceed the memory budget (before anything is allocated), ``shapes``
            given to a method that traces rays through the scene, or ``frozen`` with
            other options (:meth:`FrozenFrames.check`).
    """
    options = (options or Options()).check()
    lights.check(scene)
    w, h = sensor.film().crop_size()
    zbuffer.check_memory(int(w) * int(h) * aa * aa, f"a {w}x{h} film at aa={aa}")
    traces = options.visibility == "raytrace" or options.shadows == "ray"
    if shapes is not None and traces:
        raise ValueError("raster: explicit 'shapes' need visibility='zbuffer' and "
                         "shadows='map' or 'none' (rays are traced through the scene's shapes)")
    if frozen is not None:
        FrozenFrames.check(options)
    light_data = lights.prepare(scene, options.area_samples)
    geom = None
    every = list(scene.shapes() if shapes is None else shapes)
    if options.visibility == "zbuffer" or options.shadows == "map":
        geom = zbuffer.gather_geometry(every)
    limit = layer_limit(every, scene if shapes is None else None) if max_layers is None else max_layers
    drawn = [s for s in every if hasattr(s, "raster_begin")]
    result = None
    try:
        for shape in drawn:   # a handful of shapes; outside a recording (they read back)
            shape.raster_begin(sensor, aa)
        if frozen is not None:
            result = frozen(scene, sensor, aa, limit, options, light_data)
        if result is None:
            result = _shaded(scene, sensor, aa, limit, options, light_data, geom)
    finally:
        for shape in drawn:
            shape.raster_end()
    image, cut = result
    warn_exhausted(int(dr.count(cut)[0]) if isinstance(cut, mi.Bool) else cut,
                   int(w) * int(h) * aa * aa, limit)
    return image

