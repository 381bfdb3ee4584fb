"""Normals of the mapped tiles T(D) (HDDM §3.2), three ways.

* ``tangent`` — the paper's method: map the two precomputed tangent points
  Ṽ_j = V + ε T_j (T_1 x T_2 = N) and take (T(Ṽ_1) - T(V)) x (T(Ṽ_2) - T(V)).
  Triples the number of mapped points.
* ``jacobian`` — the analytic differential of T(u, v, w) = S + n w: with J = dT/d(x, y, z)
  the tile normal maps by the cofactor matrix, n' = det(J) J^-T N
  = N_x (a_y x a_z) + N_y (a_z x a_x) + N_z (a_x x a_y) for the columns a of J.  Exact for
  ``exact`` mode, exact per texel for ``maps`` (the bilinear P, N are piecewise bilinear).
* ``naive`` — T(V + ε N) - T(V): what the paper rejects, because T is not conformal, so the
  mapped normal direction is not orthogonal to the mapped tangent plane.

All return unnormalised vectors; :func:`finish` normalises and falls back to the base
normal where the result is degenerate (zero / NaN, e.g. a tile normal at a fold).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

METHODS = ("tangent", "jacobian", "naive")


def cofactor_normal(a_x, a_y, a_z, n):
    """det(J) J^-T n for J = [a_x a_y a_z] (mi.Vector3f each)."""
    return n.x * dr.cross(a_y, a_z) + n.y * dr.cross(a_z, a_x) + n.z * dr.cross(a_x, a_y)


def finish(normal, fallback) -> mi.Vector3f:
    """Unit normal, or ``fallback`` (unit) where ``normal`` is zero or not finite."""
    length = dr.norm(normal)
    ok = (length > 1e-20) & dr.isfinite(length)
    return dr.select(ok, normal / dr.select(ok, length, 1.0), fallback)


def angle_error_deg(a, b):
    """Angle between unit vectors a and b in degrees (mi.Float), robust near 0 and 180."""
    return dr.rad2deg(2 * dr.atan2(dr.norm(a - b), dr.norm(a + b)))
