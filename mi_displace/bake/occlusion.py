"""Ambient occlusion of the high-poly, evaluated where each texel's ray found it.

For a surface point x with shading normal n, ambient occlusion is the cosine-weighted
fraction of the hemisphere around n from which x sees nothing within ``distance``::

    AO(x) = 1/pi * integral over the hemisphere of V(x, w, distance) (n . w) dw

estimated with ``samples`` cosine-distributed directions (Mitsuba's
``warp.square_to_cosine_hemisphere``), each a shadow ray against the high-poly only, so the
estimate is the plain mean of the visibilities.  1 = fully open, 0 = fully occluded; a plane
gives 1, the crease of a V groove with opening half-angle alpha gives sin(alpha), a floor
under a parallel ceiling at height h gives (h / distance)^2 for h < distance.

The point is the **high-poly hit** of the texel's projection ray, not the low-poly point: the
map then shows the high-poly's own crevices (what Blender's selected-to-active AO bake, xNormal
and Substance do: the shading is evaluated on the selected high-poly where the cage ray hits
it), and a low-poly that cuts through the high-poly does not occlude (or get occluded by) it.

Random numbers: one PCG32 stream per bake sample, seeded with ``seed`` and the sample's
global key (texel index and sub-sample, independent of how the map is cut into blocks), so a
bake is deterministic and the same seed gives the same map at any block size.  The sample
loop is a Dr.Jit symbolic loop: one kernel over all the texels of a block, ``samples``
iterations inside it.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

#: default search distance of the occlusion rays, as a fraction of the high-poly's diagonal
DEFAULT_DISTANCE_REL = 0.1


def check_settings(samples, distance, seed) -> None:
    """Validate the AO settings (ValueError naming the parameter)."""
    if isinstance(samples, bool) or int(samples) != samples or not 1 <= samples <= 1 << 16:
        raise ValueError(f"ao_samples: must be an integer in [1, 65536], got {samples!r}")
    if distance is not None and not (math.isfinite(distance) and distance > 0):
        raise ValueError(f"ao_distance: must be a positive finite distance, got {distance!r}")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"ao_seed: must be a non-negative integer, got {seed!r}")


@dr.syntax
def ambient_occlusion(scene: mi.Scene, x: mi.Point3f, n_geo: mi.Vector3f, n: mi.Vector3f,
                      key: mi.UInt64, samples: int, distance, offset, seed: int) -> mi.Float:
    """AO in [0, 1] of points ``x`` (one per lane).

    Args:
        scene: what occludes (the high-poly's scene).
        x: points on the surface [object units].
        n_geo: geometric normal at x, any length, on the side of ``n`` (rays start at
            x + offset * n_geo / |n_geo| so the surface itself is not hit at t = 0).
        n: unit shading normal: the hemisphere's axis.
        key: per-lane stream id of the random numbers (unique per bake sample).
        samples: directions per point.
        distance, offset: ray length and start offset [object units] (Python floats or
            opaque mi.Float: they do not enter the kernel as constants).
        seed: the stream's initial state.
    """
    frame = mi.Frame3f(n)
    origin = x + dr.normalize(n_geo) * offset
    rng = mi.PCG32(dr.width(x))
    rng.seed(mi.UInt64(seed), key)   # not the constructor's seeding: it adds the lane index
    open_count = mi.Float(0.0)
    i = mi.UInt32(0)
    count = dr.opaque(mi.UInt32, samples)
    while i < count:
        u = mi.Point2f(rng.next_float32(), rng.next_float32())
        d = frame.to_world(mi.warp.square_to_cosine_hemisphere(u))
        blocked = scene.ray_test(mi.Ray3f(origin, d, distance, 0.0, []))
        open_count += dr.select(blocked, 0.0, 1.0)
        i += 1
    return open_count / mi.Float(count)
