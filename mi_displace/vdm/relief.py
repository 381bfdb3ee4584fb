"""Parallax occlusion / relief mapping (Policarpo et al. 2005): a per-pixel march in the
height field with no precomputed table.

From the reference point P (tile coordinate T, z = 0) the view ray descends as
``z(s) = -s cos(theta_V)``, ``T(s) = T - s sin(theta_V) u_V`` (tile units, u_V the unit
tile-space azimuth).  A linear search in ``steps`` equal depth slices over [0, D] finds the
first slice below the surface ``-D (1 - H(T(s)))``; ``refine`` bisection steps then locate
the intersection P'.  Self-shadows: a second linear march from P' towards L reports a
shadow if any sample lies below the surface.  The reference surface is treated as flat and
infinite: no curvature, hence no silhouettes (the known limitation of the method).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mi_displace.vdm.frame import TiledHeight

#: Smallest cos(theta) used for the march (the ray length D / cos theta is bounded).
MIN_COS = 0.02


def first_crossing(below, lo: mi.Float, hi: mi.Float, steps: int, refine: int,
                   label: str = "relief", active: mi.Bool | None = None) -> tuple[mi.Float, mi.Bool]:
    """First parameter in [lo, hi] where the predicate ``below(s)`` turns true.

    A linear search in ``steps`` equal steps finds the first sample below the surface,
    then ``refine`` bisections between it and the sample before it locate the crossing.
    Where no sample is below, the result is ``hi`` and ``found`` is false.  A lane stops
    the linear search once it has found its sample (the loop ends when every lane of a SIMD
    packet has): the same result as searching on.

    Args:
        below: callable Float -> Bool (the ray point at parameter s lies below the height
            field).
        lo, hi: the search interval per lane (same units as s).
        active: optional lanes to search; the others' results are unspecified.
    """
    n = dr.width(lo) if dr.width(lo) > 1 else dr.width(hi)
    ds = (hi - lo) / steps
    done = dr.zeros(mi.Bool, n) if active is None else ~mi.Bool(active) | dr.zeros(mi.Bool, n)

    def lin_body(i, a, b, found, done):
        s = lo + mi.Float(i + 1) * ds
        hit = ~found & below(s)
        b = dr.select(hit, s, b)
        a = dr.select(~found & ~hit, s, a)
        return i + 1, a, b, found | hit, done | hit

    _, a, b, found, _ = dr.while_loop(
        state=(mi.UInt32(0), lo + dr.zeros(mi.Float, n), hi + dr.zeros(mi.Float, n),
               dr.zeros(mi.Bool, n), done),
        cond=lambda i, a, b, found, done: (i < steps) & ~done, body=lin_body,
        labels=("i", "a", "b", "found", "done"), label=f"{label}_linear")

    def bis_body(i, a, b):
        mid = 0.5 * (a + b)
        m = below(mid)
        return i + 1, dr.select(m, a, mid), dr.select(m, mid, b)

    _, a, b = dr.while_loop(state=(mi.UInt32(0), a, b),
                            cond=lambda i, a, b: i < refine, body=bis_body,
                            labels=("i", "a", "b"), label=f"{label}_bisect")
    return 0.5 * (a + b), found


def march_view(height: TiledHeight, T: mi.Point2f, cos_t: mi.Float, dir_T: mi.Vector2f,
               D: float, steps: int, refine: int) -> tuple[mi.Point2f, mi.Float]:
    """Intersection of the view ray with the height field.

    Args:
        T: tile coordinate of P; cos_t: cos(theta_V); dir_T: tile-space unit direction of
            the view's tangential part (towards the viewer); D: depth [tile units].

    Returns:
        (T', h): tile coordinate and depth [tile units] of P'.
    """
    cos_t = dr.maximum(cos_t, MIN_COS)
    tan_t = dr.sqrt(dr.maximum(1.0 - cos_t * cos_t, 0.0)) / cos_t

    def at(depth):
        return mi.Point2f(T.x - depth * tan_t * dir_T.x, T.y - depth * tan_t * dir_T.y)

    def below(depth):
        return depth >= D * (1.0 - height.value(at(depth)))

    n = dr.width(cos_t)
    depth, _ = first_crossing(below, dr.zeros(mi.Float, n), dr.full(mi.Float, D, n), steps,
                              refine)
    return at(depth), depth


def march_shadow(height: TiledHeight, T: mi.Point2f, h: mi.Float, cos_l: mi.Float,
                 dir_T: mi.Vector2f, D: float, steps: int, active: mi.Bool | None = None) -> mi.Bool:
    """True where the segment from P' (depth h) up to the reference surface towards L
    passes below the height field (self-shadow).  A lane stops marching at its first
    sample below the relief (the loop ends when every lane of a SIMD packet has), and
    lanes outside ``active`` (optional) do not march: their answer is False."""
    cos_l = dr.maximum(cos_l, MIN_COS)
    tan_l = dr.sqrt(dr.maximum(1.0 - cos_l * cos_l, 0.0)) / cos_l
    eps = 0.5 * D / steps
    n = dr.width(h)
    run = dr.full(mi.Bool, True, n) if active is None else mi.Bool(active) | dr.zeros(mi.Bool, n)

    def body(i, shadow):
        depth = h * (1.0 - mi.Float(i + 1) / (steps + 1))
        rise = h - depth
        Ts = mi.Point2f(T.x + rise * tan_l * dir_T.x, T.y + rise * tan_l * dir_T.y)
        shadow |= depth > D * (1.0 - height.value(Ts)) + eps
        return i + 1, shadow

    _, shadow = dr.while_loop(state=(mi.UInt32(0), dr.zeros(mi.Bool, n)),
                              cond=lambda i, s: (i < steps) & ~s & run, body=body,
                              labels=("i", "shadow"), label="relief_shadow")
    return shadow
