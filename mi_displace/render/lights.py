"""The emitters `raster` draws, GPU-style, and the check that refuses the others.

* **Delta lights** (``point``, ``spot``, ``directional``, ``projector``: every emitter with
  a delta position or direction and no surface) — one hard-shadowed sample each
  (:mod:`.raster`).
* **Area lights** (``area`` on any shape: rectangle, sphere, disk, mesh…) — a fixed set of
  ``area_samples`` points on the light, the same for every pixel and every frame (the
  "many point lights" of a GPU): the points are the shape's own
  ``sample_position`` at a Hammersley pattern shifted by half a cell, so one sample is the
  centre of a rectangle's parameter domain; each shades like a point light with the
  radiance the emitter sends toward the receiver (``eval_direction``) and its own hard
  shadow (a shadow ray or a cube shadow map, :mod:`.raster`).
* **Ambient lights** — unoccluded: ``constant`` adds albedo × L; ``envmap`` adds
  albedo × E(n)/π, with E the irradiance of its order-2 spherical-harmonic projection
  (Ramamoorthi & Hanrahan 2001, "An efficient representation for irradiance environment
  maps", eq. 7 and 13), n the shading normal on the viewer's side.

Any other emitter (``directionalarea``, ``sunsky``, a plugin's) is refused by
:func:`emitter_problem` before anything renders: raster never drops a light silently.  The
``volume_slicer`` integrator (delta lights and ``constant`` ambient only) is checked the
same way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

#: Largest ``area_samples`` (per area emitter).
MAX_AREA_SAMPLES = 4096


def is_delta(emitter: mi.Emitter) -> bool:
    flags = emitter.flags()
    return (mi.has_flag(flags, mi.EmitterFlags.Delta)
            and not mi.has_flag(flags, mi.EmitterFlags.Surface))


def is_area(emitter: mi.Emitter) -> bool:
    return emitter.class_name() == "AreaLight"


def is_constant(emitter: mi.Emitter) -> bool:
    return emitter.class_name() == "ConstantBackgroundEmitter"


def is_envmap(emitter: mi.Emitter) -> bool:
    return emitter.class_name() == "EnvironmentMapEmitter"


#: Per GPU-style integrator: which emitters it draws, the list its message names and the
#: Mitsuba integrator it suggests instead.
DRAWS = {
    "raster": (lambda e: is_delta(e) or is_area(e) or is_constant(e) or is_envmap(e),
               "point, spot, directional, projector and area lights and constant/envmap "
               "ambient light", "path"),
    "volume_slicer": (lambda e: is_delta(e) or is_constant(e),
                      "point, spot, directional and projector lights and constant ambient "
                      "light", "volpath"),
}


def emitter_problem(scene: mi.Scene, integrator: str = "raster") -> str | None:
    """One line naming the first emitter ``integrator`` (a key of :data:`DRAWS`) cannot
    draw, or ``None``."""
    drawn, models, instead = DRAWS[integrator]
    for e in scene.emitters():
        if not drawn(e):
            return (f"{integrator}: cannot draw emitter {e.id() or '(unnamed)'!r} of class "
                    f"{e.class_name()}: the {integrator} integrator models {models}; remove "
                    f"it or render the scene with {instead!r}")
    return None


def sample_pattern(n: int) -> mi.Point2f:
    """``n`` points of the unit square: Hammersley, ((k + ½)/n, φ₂(k) + ½/n mod 1)."""
    k = dr.arange(mi.UInt32, n)
    y = mi.radical_inverse_2(k, mi.UInt32(0)) + 0.5 / n
    return mi.Point2f((mi.Float(k) + 0.5) / n, y - dr.floor(y))


@dataclass
class AreaSamples:
    """The fixed light points of every area emitter of a scene (width K = emitters × n).

    Attributes:
        ps: (K,) positions, normals, uv and area densities [1 / scene units²].
        emitter: (K,) the emitter of each point.
        per_emitter: points per emitter (n); each point carries 1/n of its light.
    """
    ps: mi.PositionSample3f
    emitter: mi.EmitterPtr
    per_emitter: int

    @property
    def count(self) -> int:
        return dr.width(self.ps.pdf) if self.per_emitter else 0


def _widen(value, kind, n):
    return kind(value) + dr.zeros(kind, n)   # a width-1 field (a rectangle's normal) to n


def area_samples(scene: mi.Scene, n: int) -> AreaSamples:
    """The ``n`` fixed points (:func:`sample_pattern`) on each area emitter's shape."""
    u = sample_pattern(n)
    parts, index = [], []
    emitters = scene.emitters()
    for i, e in enumerate(emitters):   # the scene's emitters, not elements
        if is_area(e):
            ps = e.get_shape().sample_position(0.0, u)
            parts.append((_widen(ps.p, mi.Point3f, n), _widen(ps.n, mi.Normal3f, n),
                          _widen(ps.uv, mi.Point2f, n), _widen(ps.pdf, mi.Float, n)))
            index.append(dr.full(mi.UInt32, i, n))
    if not parts:   # width 1, not empty: an empty array aborts dr.freeze (docs/platform.md)
        return AreaSamples(dr.zeros(mi.PositionSample3f, 1), dr.zeros(mi.EmitterPtr, 1), 0)
    ps = dr.zeros(mi.PositionSample3f, n * len(parts))
    ps.p, ps.n, ps.uv, ps.pdf = (dr.concat([p[j] for p in parts]) for j in range(4))
    emitter = dr.gather(mi.EmitterPtr, scene.emitters_dr(), dr.concat(index))
    dr.eval(ps, emitter)
    return AreaSamples(ps, emitter, n)


def area_sample_toward(samples: AreaSamples, k: mi.UInt32, si: mi.SurfaceInteraction3f,
                       active: mi.Bool) -> tuple[mi.DirectionSample3f, mi.Color3f]:
    """Light point ``k`` seen from ``si``: the direction sample (``d`` unit, ``dist``) and
    its weight, radiance × |cos θ_light| / (dist² × area density × n) — the contribution of
    one of the light's n equal parts, as ``sample_direction``'s radiance / pdf (solid
    angle) divided by n."""
    ps = dr.gather(mi.PositionSample3f, samples.ps, k, active)
    ds = mi.DirectionSample3f(ps)
    to_light = ps.p - si.p
    dist2 = dr.squared_norm(to_light)
    ds.dist = dr.sqrt(dist2)
    ds.d = to_light / ds.dist
    ds.emitter = dr.gather(mi.EmitterPtr, samples.emitter, k, active)
    radiance = ds.emitter.eval_direction(si, ds, active)   # 0 behind the light's face
    weight = radiance * (dr.abs(dr.dot(ds.d, ds.n)) / (dist2 * ps.pdf * samples.per_emitter))
    return ds, dr.select(active & (dist2 > 0), weight, 0.0)


# --- environment maps as ambient light ----------------------------------------------------

#: Ramamoorthi & Hanrahan 2001, eq. 8: the clamped cosine's SH coefficients Â_l, per band.
_A_HAT = (math.pi, 2 * math.pi / 3, math.pi / 4)


def _sh9(d: mi.Vector3f) -> list:
    """The nine real SH basis functions Y_lm(d) of bands 0-2 (Ramamoorthi & Hanrahan eq. 3),
    ordered (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2)."""
    x, y, z = d.x, d.y, d.z
    return [0.282095 + 0 * x, 0.488603 * y, 0.488603 * z, 0.488603 * x,
            1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1),
            1.092548 * x * z, 0.546274 * (x * x - y * y)]


_BAND = (0, 1, 1, 1, 2, 2, 2, 2, 2)


def envmap_sh(emitter: mi.Emitter) -> list:
    """Irradiance coefficients of an environment emitter: nine (r, g, b) tuples
    c_lm = Â_l L_lm / π, so that Σ c_lm Y_lm(n) is the radiance a white Lambertian surface
    with normal n reflects (eq. 13 divided by π).

    L_lm = ∫ L(ω) Y_lm(ω) dω by the midpoint rule (in z = cos θ and φ) over a
    latitude-longitude grid with exact cell solid angles (a constant environment is
    reproduced to float rounding), 2 cells per texel of the emitter's bitmap in each
    direction (64 × 128 at least, 1024 × 2048 at most: a map of more than 512 rows is read
    at cell centres coarser than its texels, and a sun smaller than a cell may be missed).
    """
    params = mi.traverse(emitter)
    rows = int(params["data"].shape[0]) if "data" in params.keys() else 64
    n_theta = min(max(2 * rows, 64), 1024)
    n_phi = 2 * n_theta
    idx = dr.arange(mi.UInt32, n_theta * n_phi)
    i, j = mi.Float(idx // n_phi), mi.Float(idx % n_phi)
    cos0, cos1 = dr.cos(i * (dr.pi / n_theta)), dr.cos((i + 1) * (dr.pi / n_theta))
    d_omega = (cos0 - cos1) * (2 * dr.pi / n_phi)
    z = 0.5 * (cos0 + cos1)   # the cell's mid-height: band 0 and 1 integrate exactly
    sin_theta = dr.safe_sqrt(1.0 - z * z)
    phi = (j + 0.5) * (2 * dr.pi / n_phi)
    d = mi.Vector3f(sin_theta * dr.cos(phi), sin_theta * dr.sin(phi), z)
    si = dr.zeros(mi.SurfaceInteraction3f, dr.width(idx))
    si.wi = -d
    L = mi.Color3f(emitter.eval(si)) * d_omega
    coeffs = [[dr.sum(c * y) for c in L] for y in _sh9(d)]
    dr.eval(coeffs)
    return [tuple(_A_HAT[_BAND[m]] / math.pi * float(v[0]) for v in coeffs[m]) for m in range(9)]


def sh_irradiance(coeffs: list, n: mi.Vector3f) -> mi.Color3f:
    """Σ c_lm Y_lm(n) for unit normals ``n`` (:func:`envmap_sh`), clamped at 0."""
    E = dr.zeros(mi.Color3f, dr.width(n))
    for c, y in zip(coeffs, _sh9(n)):   # 9 terms
        E += mi.Color3f(c) * y
    return dr.maximum(E, 0.0)


@dataclass
class Lights:
    """What `raster` precomputes about a scene's emitters once per frame."""
    area: AreaSamples
    envmaps: dict = field(default_factory=dict)   # id(emitter) -> envmap_sh coefficients


def check(scene: mi.Scene, integrator: str = "raster") -> None:
    """Raises ValueError naming the first emitter ``integrator`` cannot draw (no kernel
    runs)."""
    problem = emitter_problem(scene, integrator)
    if problem:
        raise ValueError(problem)


def prepare(scene: mi.Scene, n_area: int) -> Lights:
    """Area-light points and environment SH coefficients of a checked scene."""
    return Lights(area_samples(scene, n_area),
                  {id(e): envmap_sh(e) for e in scene.emitters() if is_envmap(e)})
