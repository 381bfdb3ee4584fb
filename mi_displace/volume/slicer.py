"""The paper's renderer (§4.2): view-aligned slices through the displaced bounding box.

Slices are planes perpendicular to the camera's viewing axis f, ``spacing`` world units apart
(the sampling distance d; 1.0 object voxel by default), covering the depth range of the proxy
box (:meth:`DisplacedVolume.proxy_box`, grown to contain displaced matter).  Each pixel's
fragment on slice k is where its ray meets that plane; it is mapped through D_k/α
(:meth:`DisplacedVolume.lookup`), classified by the transfer function, shaded, and composited.
Compositing runs front to back with early termination once the transmittance drops below
:data:`EARLY_STOP` — the same sum as back-to-front "over" blending, stopped when what remains
can change a pixel by less than that fraction — and with empty-space skipping: slices inside
the empty cells of :func:`occupancy` are jumped over, a whole empty cube of cells at a time
(the paper's GPU had neither).  The D_k/O lookups run only in occupied cells and the shading
only at visible samples, in symbolic branches (``dr.if_stmt``), which skip a whole SIMD packet
on the LLVM backend as a warp on CUDA.  The loop over slices is one Dr.Jit symbolic loop;
nothing is random, so renders are bit-identical.

Light models (``model``):

* ``"scatter"``: single scattering in the medium, the model Mitsuba's ``volpath`` computes
  with ``max_depth=2`` for a ``heterogeneous`` medium of the same sigma_t (the volume plugin)
  and albedo a under delta lights:  L = Σ_k T_k (1 - e^{-σ_k Δt}) a Σ_l E_l T_l(x_k) / 4π,
  with the isotropic phase function and T_l the transmittance towards light l, read from a
  light-transmittance grid over the proxy box (marched once per frame through the same
  displaced density).  The background must be black: ``volpath`` would also scatter an
  environment, which this model does not.
* ``"surface"``: the paper's shading of volumes as surfaces: opacity σ = κ τ'(O'), τ' a
  narrow ramp at ``iso``, κ = ``sharpness`` / voxel, colour ρ/π Σ_l E_l max(0, n·l) T_l +
  ρ L_ambient with n from the chosen normal method, T_l from the grid of that opacity
  (``shadows``) or 1.  Its reference is the iso-surface mesh (:mod:`mi_displace.volume.isosurface`)
  under ``path`` with a diffuse BSDF of reflectance ρ.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.render.lights import check as check_emitters, is_constant, is_delta
from mi_displace.render import pixel_order
from mi_displace.render.raster import pixel_rays
from mi_displace.volume.displacement import Lookup
from mi_displace.volume.field import NORMALS, AlbedoField, DisplacedVolume

MODELS = ("scatter", "surface")
#: Front-to-back compositing stops once the transmittance is below this.
EARLY_STOP = 1e-4
#: Most slices (refused before rendering).
MAX_SLICES = 8192


class SliceSettings:
    """Renderer settings (module docstring); ``spacing`` in object voxels; ``albedo`` a
    constant or an :class:`~mi_displace.volume.field.AlbedoField` (then it is also the
    surface model's reflectance in place of ``color``).  ``reuse_lookup``: shade a visible
    sample with the D_k lookup of its density step (pre-image and read points) instead of
    reading the D_k again; False re-reads them (the same image bit for bit, tested; kept as a
    setting for the A/B of ``scripts/volume_overhead_ab.py``)."""

    def __init__(self, model="scatter", normals="jacobian", spacing=1.0, albedo=0.8,
                 color=(0.8, 0.7, 0.55), iso=0.5, sharpness=4.0, shadows=True,
                 light_resolution=None, aa=1, reuse_lookup=True):
        if model not in MODELS:
            raise ValueError(f"model: must be one of {MODELS}, got {model!r}")
        if normals not in NORMALS:
            raise ValueError(f"normals: must be one of {NORMALS}, got {normals!r}")
        if not (math.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing: must be > 0 voxels, got {spacing}")
        self.albedo_field = albedo if isinstance(albedo, AlbedoField) else None
        if self.albedo_field is None and not 0 <= albedo <= 1:
            raise ValueError(f"albedo: must lie in [0, 1] or be an albedo volume, got {albedo!r}")
        if not (0 < iso < 1 and sharpness > 0):
            raise ValueError(f"iso must lie in (0, 1) and sharpness > 0, got {iso}, {sharpness}")
        if aa < 1:
            raise ValueError(f"aa: must be >= 1, got {aa}")
        self.model, self.normals, self.spacing = model, normals, float(spacing)
        self.albedo = 1.0 if self.albedo_field is not None else float(albedo)
        self.color, self.iso, self.sharpness = tuple(float(c) for c in color), float(iso), float(sharpness)
        self.shadows, self.light_resolution, self.aa = bool(shadows), light_resolution, int(aa)
        self.reuse_lookup = bool(reuse_lookup)


def check_slices(vol: DisplacedVolume, s: SliceSettings) -> int:
    """Most slices any view can need (proxy diagonal / spacing); ValueError beyond MAX_SLICES.

    Call it when the integrator is built, so that the error comes before any kernel runs."""
    lo, hi = vol.proxy_box()
    count = int(math.ceil(float(np.linalg.norm(hi - lo)) / (s.spacing * float(vol.obj.voxel_size.min()))))
    if count > MAX_SLICES:
        raise ValueError(f"spacing: up to {count} slices through the proxy box, more than {MAX_SLICES}; "
                         "raise the spacing")
    return count


def extinction(vol: DisplacedVolume, s: SliceSettings, p: mi.Point3f, lookup=None) -> mi.Float:
    """Extinction [1/world unit] of the chosen model at world points."""
    if s.model == "scatter":
        return vol.density_scale * vol.density(p, lookup)
    r = lookup if lookup is not None else vol.lookup(p)
    v = vol.obj.density(r.p)
    ramp = dr.clip((v - s.iso) / 0.05 + 0.5, 0.0, 1.0)
    kappa = s.sharpness / float(vol.obj.voxel_size.min())
    return dr.select(r.alpha >= 0.5, kappa * ramp, 0.0)


#: Occupancy samples per proxy axis at most (empty-space skipping).
MAX_OCCUPANCY_SAMPLES = 192
#: Occupancy samples per cell along each axis.
CELL_SAMPLES = 2
#: Every occupied sample also marks its neighbours this many sample spacings away.
DILATION = 2


def occupancy(vol: DisplacedVolume, s: SliceSettings, lo, hi):
    """Empty-space skipping grid: for cells of the proxy box, whether the model's extinction
    is non-zero anywhere in them — sampled at about one object voxel (at most
    MAX_OCCUPANCY_SAMPLES per axis, CELL_SAMPLES per cell), every sample dilated by DILATION
    sample spacings so that matter between samples is kept (practically, not provably,
    conservative: a feature thinner than a sample spacing that no sample meets is lost; one
    spacing lost a pixel of the walnut bench at 2-sample cells, two did not) — stored as each
    cell's chessboard distance in cells to the nearest occupied cell (0: occupied).  That is a
    proximity cloud: the cube of cells nearer than that distance is empty, so a ray jumps to
    its exit instead of stepping cell by cell.  Cached per chain version and model.

    Returns:
        (cells per axis (3,), Float array of length cx * cy * cz, x fastest).
    """
    key = (vol.chain.version, vol.mode, s.model, s.iso, s.sharpness)
    cache = getattr(vol, "_occupancy", None)
    if cache is not None and cache[0] == key:
        return cache[1]
    from scipy.ndimage import distance_transform_cdt, maximum_filter

    extent = np.asarray(hi, float) - np.asarray(lo, float)
    voxel = float(vol.obj.voxel_size.min())
    cells = np.clip(np.ceil(extent / voxel / CELL_SAMPLES), 1, MAX_OCCUPANCY_SAMPLES // CELL_SAMPLES).astype(int)
    n = cells * CELL_SAMPLES
    axes = [lo[i] + (np.arange(n[i]) + 0.5) * extent[i] / n[i] for i in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    p = mi.Point3f(mi.Float(x.ravel()), mi.Float(y.ravel()), mi.Float(z.ravel()))
    full = maximum_filter(np.array(extinction(vol, s, p) > 0).reshape(n[2], n[1], n[0]), size=2 * DILATION + 1)
    occ = full.reshape(cells[2], CELL_SAMPLES, cells[1], CELL_SAMPLES, cells[0], CELL_SAMPLES).any(axis=(1, 3, 5))
    dist = distance_transform_cdt(~occ, metric="chessboard") if occ.any() else np.full(occ.shape, cells.max())
    result = (cells, mi.Float(dist.astype(np.float32).ravel()))
    vol._occupancy = (key, result)
    return result


def _opaque(value, kind=mi.Point3f):
    """``value`` (a number or (3,) array) as a Dr.Jit value of width 1 that kernels read as a
    parameter: a new view or a new proxy box (an edit of a map's amount) reuses the compiled
    kernels instead of tracing its numbers as constants."""
    out = kind(*np.ravel(value).tolist())
    dr.make_opaque(out)
    return out


def _box_intersect(lo: mi.Point3f, hi: mi.Point3f, ray: mi.Ray3f):
    """Ray parameters [t0, t1] (t0 >= 0) inside the box [lo, hi] (Point3f, world units)."""
    box = mi.BoundingBox3f(lo, hi)
    hit, t0, t1 = box.ray_intersect(ray)
    return hit & (t1 > 0), dr.maximum(t0, 0.0), t1


def light_grid(vol: DisplacedVolume, s: SliceSettings, lights, lo, hi, film_size: int = 96):
    """Transmittance from each grid node of the proxy box to each delta light (one channel per
    light), marched at the slice spacing through the model's extinction.  Nodes per axis:
    ``light_resolution``, else about one per object voxel but no more than the film's larger
    side (a finer shadow than the image resolves is wasted), clamped to [24, 96].

    Cached per chain version, model settings and light directions (a new frame of an animation
    rebuilds it; a new camera does not).

    Returns:
        (nodes per axis, texture), or (0, None) without lights.
    """
    if not lights:
        return 0, None
    probe = dr.zeros(mi.Interaction3f, 1)
    light_key = tuple(tuple(np.array(c).item() for c in e.sample_direction(probe, mi.Point2f(0.5))[0].d)
                      for e in lights)
    key = (vol.chain.version, vol.mode, s.model, s.iso, s.sharpness, s.spacing, s.light_resolution,
           light_key, tuple(np.round(lo, 6)), tuple(np.round(hi, 6)))
    cache = getattr(vol, "_light_grid", None)
    if cache is not None and cache[0] == key:
        return cache[1]
    n = s.light_resolution or int(np.clip(min(max(vol.obj.shape), film_size), 24, 96))
    n = int(n)
    axes = [np.linspace(lo[i], hi[i], n) for i in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    p = mi.Point3f(mi.Float(x.ravel()), mi.Float(y.ravel()), mi.Float(z.ravel()))
    step = s.spacing * float(vol.obj.voxel_size.min())
    channels = []
    for e in lights:
        it = dr.zeros(mi.Interaction3f, dr.width(p.x))
        it.p = p
        ds, _ = e.sample_direction(it, mi.Point2f(0.5))
        ray = mi.Ray3f(p, ds.d)
        _, _, t_exit = _box_intersect(_opaque(lo), _opaque(hi), ray)
        # a directional light's ds.dist depends on the scene's shapes (none under the slicer)
        directional = mi.has_flag(e.flags(), mi.EmitterFlags.DeltaDirection)
        t_end = t_exit if directional else dr.minimum(t_exit, ds.dist)

        def cond(t, tau):
            return (t < t_end) & (tau < 30.0)

        def body(t, tau):
            x = ray(t + 0.5 * step)
            tau += extinction(vol, s, x) * dr.minimum(step, t_end - t)
            return t + step, tau

        _, tau = dr.while_loop(state=(mi.Float(0.0) + 0.0 * p.x, mi.Float(0.0) + 0.0 * p.x),
                               cond=cond, body=body, label="volume_light_grid")
        channels.append(np.asarray(dr.exp(-tau)).reshape(n, n, n))
    grid = np.stack(channels, axis=-1).astype(np.float32)
    result = (n, mi.Texture3f(mi.TensorXf(grid), use_accel=False, filter_mode=dr.FilterMode.Linear,
                              wrap_mode=dr.WrapMode.Clamp))
    vol._light_grid = (key, result)
    return result


def _slice_frame(sensor: mi.Sensor, lo, hi, spacing):
    """Camera origin and axis; depth range of the proxy box along it; slice count."""
    m = np.array(sensor.world_transform().matrix, dtype=float).reshape(4, 4)
    origin, forward = m[:3, 3], m[:3, 2] / np.linalg.norm(m[:3, 2])
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    depth = (corners - origin) @ forward
    zmin, zmax = max(float(depth.min()), 0.0), float(depth.max())
    count = min(int(math.ceil(max(zmax - zmin, 0.0) / spacing)), MAX_SLICES)
    return origin, forward, zmin, count


def render(scene: mi.Scene, sensor: mi.Sensor, vol: DisplacedVolume, s: SliceSettings) -> mi.TensorXf:
    """Render the displaced volume by slicing; returns a (height, width, 3) linear tensor.

    Raises:
        ValueError: an emitter the slicer does not model (area lights, environment maps),
            before anything renders.
    """
    check_emitters(scene, "volume_slicer")
    vol.prepare()
    if s.albedo_field is not None:
        s.albedo_field.prepare()
    lo, hi = vol.proxy_box()
    spacing = s.spacing * float(vol.obj.voxel_size.min())
    origin, forward, zmin, count = _slice_frame(sensor, lo, hi, spacing)
    lights = [e for e in scene.emitters() if is_delta(e)]
    ambient = [e for e in scene.emitters() if is_constant(e)]
    film = max(sensor.film().crop_size())
    gn, grid = light_grid(vol, s, lights, lo, hi, film) if (s.model == "scatter" or s.shadows) else (0, None)
    ray, weight, w, h = pixel_rays(sensor, s.aa)
    # the view's and the proxy box's numbers are kernel parameters (_opaque)
    box_lo, box_hi = _opaque(lo), _opaque(hi)
    hit, t0, t1 = _box_intersect(box_lo, box_hi, ray)
    fwd = _opaque(forward, mi.Vector3f)
    zmin = _opaque(zmin, mi.Float)
    cos_f = dr.maximum(dr.dot(ray.d, fwd), 1e-6)
    z_ray = dr.dot(ray.o - _opaque(origin), fwd)
    # slice k sits at depth zmin + (k + 1/2) spacing; this ray's slices lie in [t0, t1]
    k0 = dr.maximum(dr.ceil((z_ray + t0 * cos_f - zmin) / spacing - 0.5), 0.0)
    k1 = dr.minimum(dr.floor((z_ray + t1 * cos_f - zmin) / spacing - 0.5), _opaque(count - 1.0, mi.Float))
    dt = spacing / cos_f
    rho = mi.Color3f(s.color)
    amb = mi.Color3f(0.0)
    for e in ambient:
        si = dr.zeros(mi.SurfaceInteraction3f)
        amb += mi.Color3f(e.eval(si))
    cells, occ = occupancy(vol, s, lo, hi)
    cx, cy = (_opaque(int(c), mi.Int32) for c in cells[:2])
    last_cell = _opaque(np.asarray(cells, int) - 1, mi.Vector3i)
    cell_size = _opaque((hi - lo) / cells, mi.Vector3f)
    inv_d = dr.rcp(ray.d)
    bias = _opaque(2.0 * (float((hi - lo).max()) / max(gn - 1, 1)) if gn else 0.0, mi.Float)

    # the density step's D_k lookup (pre-image, read points, α factors) goes on to the
    # shading of the same sample, which then reads no D_k again (only J and ∇α for the normal)
    own_albedo = s.albedo_field is not None and s.albedo_field.volume is vol
    reuse = s.reuse_lookup and vol.mode == "approximation" and (
        (s.model == "surface" and s.normals != "fd") or own_albedo)

    def shade(x, r):
        """Light scattered (scatter) or reflected (surface) towards the camera at x; ``r``:
        the density step's lookup of x (or None)."""
        S = mi.Color3f(0.0)
        if s.model == "surface":
            n = vol.normal(x, s.normals, -ray.d, lookup=r)
        colour = None
        if s.albedo_field is not None:
            colour = s.albedo_field.albedo(x, lookup=r if own_albedo else None)
        for i, e in enumerate(lights):
            it = dr.zeros(mi.Interaction3f)
            it.p = x
            ds, E = e.sample_direction(it, mi.Point2f(0.5))
            shadow = 1.0
            if grid is not None:
                # surfaces read the light grid a shadow bias towards the light (no self-shadowing)
                xl = x + ds.d * bias if s.model == "surface" else x
                shadow = grid.eval(mi.Point3f((xl - box_lo) / (box_hi - box_lo) * (gn - 1) / gn + 0.5 / gn))[i]
            if s.model == "scatter":
                S += mi.Color3f(E) * shadow / (4.0 * dr.pi)
            else:
                S += mi.Color3f(E) * shadow * dr.maximum(dr.dot(n, ds.d), 0.0) / dr.pi
        if s.model == "surface":
            return (colour if colour is not None else rho) * (S + amb)
        return (colour if colour is not None else s.albedo) * S

    def density(x):
        """Extinction at x and, with ``reuse``, its lookup as a tuple (if_stmt state)."""
        if not reuse:
            return extinction(vol, s, x), ()
        r = vol.lookup(x)
        return extinction(vol, s, x, r), (mi.Point3f(r.p), mi.Float(r.alpha), tuple(mi.Point3f(q) for q in r.points),
                                          tuple(mi.Float(a) for a in r.factors))

    def empty(x):
        """What an empty cell gives: no extinction; a lookup of the same structure (unused)."""
        if not reuse:
            return mi.Float(0.0), ()
        n = len(vol.chain.sampled_maps())
        return mi.Float(0.0), (mi.Point3f(x), mi.Float(1.0), (mi.Point3f(x),) * n, (mi.Float(1.0),) * n)

    def lookup(r):
        return Lookup(r[0], r[1], points=list(r[2]), factors=list(r[3])) if reuse else None

    def cond(k, T, L):
        return hit & (k <= k1) & (T > EARLY_STOP)

    def body(k, T, L):
        x = ray((zmin + (k + 0.5) * spacing - z_ray) / cos_f)
        # empty-space skipping: in an empty cell, jump to the first slice past the exit of
        # the empty cube around it
        c = dr.clip(mi.Vector3i(dr.floor((x - box_lo) / cell_size)), 0, last_cell)
        dist = dr.gather(mi.Float, occ, mi.UInt32(c.x + cx * (c.y + cy * c.z)))
        full = dist == 0
        # the cube of cells within dist - 1 of c is empty: its exit face along the ray
        far = box_lo + (mi.Vector3f(c) + dr.select(ray.d > 0, dist, 1.0 - dist)) * cell_size
        t_exit = dr.min((far - ray.o) * inv_d)
        k_skip = dr.ceil((z_ray + t_exit * cos_f - zmin) / spacing - 0.5)
        # symbolic branches (they skip a SIMD packet on the LLVM backend too, not only masked
        # lanes): the displaced density (D_k, then O) only in occupied cells, the shading
        # (normal, lights) only where the sample is visible
        sigma, r = dr.if_stmt(args=(x,), cond=full, true_fn=density, false_fn=empty, label="volume_slicer_sample")
        a = 1.0 - dr.exp(-sigma * dt)
        live = a > 0
        S = dr.if_stmt(args=(x, r), cond=live, true_fn=lambda x, r: shade(x, lookup(r)),
                       false_fn=lambda x, r: mi.Color3f(0.0), label="volume_slicer_shade")
        L = L + dr.select(live, T * a * S, 0.0)
        T = dr.select(live, T * (1.0 - a), T)
        return dr.select(full, k + 1.0, dr.maximum(k + 1.0, k_skip)), T, L

    k, T, L = dr.while_loop(state=(mi.Float(k0), dr.full(mi.Float, 1.0, dr.width(k0)),
                                   dr.zeros(mi.Color3f, dr.width(k0))),
                            cond=cond, body=body, label="volume_slicer")
    # what shows through: the environment on rays that leave
    si = dr.zeros(mi.SurfaceInteraction3f, dr.width(k0))
    si.wi = -ray.d
    env = mi.Color3f(0.0)
    for e in scene.emitters():
        if not is_delta(e):
            env += mi.Color3f(e.eval(si))
    L = (L + T * env) * weight
    n = s.aa * s.aa
    if n > 1:
        dr.eval(L)
        L = mi.Color3f([dr.block_reduce(dr.ReduceOp.Add, c, n) / n for c in L])
    return pixel_order.image(L, w, h)
