"""Procedural inverse displacement maps D (eq. 3: p = p' + D(p')) with their α masks (§4.1).

Every primitive is written in its own local frame, where the region it displaces is (about)
the unit cube, and evaluates at local points ℓ' the *inverse* displacement D(ℓ') and the exact
mask α(ℓ') ∈ {0, 1} (0 where ℓ' has no pre-image: the opening of a cut).  Where the true
inverse does not exist (inside a cut) D is the C0 pseudo-inverse of §4.1: points of the gap map
onto the cut face (the "stretching" of Fig. 3), so D is continuous wherever matter is kept.

Primitives (parameters in local units, angles in degrees):

* ``gaussian``  Gaussian pull, eq. 8: D = (0, 0, -amount · z · g(x, y)), g a Gaussian of
  width ``sigma`` at (0.5, 0.5) shifted to vanish on the cube's sides; above z = 1 the pull
  fades out linearly by z = 2 (C0; that space must be empty).  Invertible for amount < 1.
* ``peel``  (Fig. 1, §4.3.1) the lid — the part above the cut plane z = ``height`` left of the
  hinge x = ``hinge`` — curls open about the hinge (an axis along y): a lid point at distance
  r from the hinge turns by θ(r) = ``angle`` · (1 - ``curl`` + ``curl`` · r / ``radius``)
  (0..85°).  With ``curl`` = 1 (the default) the rotation grows from 0 at the hinge to
  ``angle`` at ``radius``, so a flat lid rolls into a spiral whose far end turns over (its
  underside, once facing down, faces up: the paper's Fig. 4b peel, whose "underside of the
  cut surface ... is facing the light"); ``curl`` = 0 is a rigid hinge.  Each circle about the
  hinge maps onto itself (r is kept), so the inverse is closed-form and the map keeps volume.
  The wedge the lid leaves (0 < φ' < θ(r)) is the cut (α = 0).  Limited to 0 <= y <= 1 and to
  ``radius`` around the hinge (the rotation fades out by 1.2 ``radius``).
* ``slabs``  (Fig. 6) cuts along z into ``count`` slabs of the unit height, slab k moved up
  by k · ``gap``; the gaps are cuts.
* ``wave``  D = (0, 0, amount · sin(2π (frequency x + phase))) · w(x) w(y), w a flat-top
  window; D does not depend on z, so the forward map is p' = p - D(p) in closed form.
* ``seam``  (Fig. 7) opens the plane x = 0.5 by a half-width w = amount · z · sin(π y)
  (0 <= y <= 1, z clamped to [0, 1]), compressing each side of the seam into [0, 1] in x.

:class:`Placement` is the 4x4 matrix M of §6: the map acts in world space as
p = p' + M D(M⁻¹ p') (M applied to D as a vector).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

#: Parameters (name: default) of each primitive, in local units; angles in degrees.
PRIMITIVES = {
    "gaussian": {"amount": 0.5, "sigma": 0.15},
    "peel": {"angle": 60.0, "hinge": 1.0, "height": 0.5, "radius": 1.5, "curl": 1.0},
    "slabs": {"count": 4.0, "gap": 0.1},
    "wave": {"amount": 0.05, "frequency": 2.0, "phase": 0.0},
    "seam": {"amount": 0.15},
}
#: Default D_k resolution (x, y, z) of each primitive (Table 2 analogues).
DEFAULT_RESOLUTION = {
    "gaussian": (32, 32, 32),
    "peel": (64, 16, 64),
    "slabs": (4, 4, 128),
    "wave": (128, 32, 2),
    "seam": (64, 64, 64),
}
MAX_PEEL_ANGLE = 85.0


def check_params(kind: str, params: dict) -> dict:
    """Complete and validate the parameters of primitive ``kind`` (clear ValueError)."""
    if kind not in PRIMITIVES:
        raise ValueError(f"displacement map type {kind!r} is not one of {', '.join(PRIMITIVES)}")
    unknown = set(params) - set(PRIMITIVES[kind])
    if unknown:
        raise ValueError(f"{kind}: unknown parameter(s) {', '.join(sorted(unknown))}; "
                         f"expected {', '.join(PRIMITIVES[kind])}")
    out = {**PRIMITIVES[kind], **{k: float(v) for k, v in params.items()}}
    for name, value in out.items():
        if not math.isfinite(value):
            raise ValueError(f"{kind}: parameter {name!r} must be finite, got {value}")
    if kind == "gaussian" and (not 0 <= abs(out["amount"]) < 1 or out["sigma"] <= 0):
        raise ValueError(f"gaussian: need |amount| < 1 (eq. 8 stays invertible) and sigma > 0, got {out}")
    if kind == "peel" and (not 0 <= out["angle"] <= MAX_PEEL_ANGLE or out["radius"] <= 0
                           or not 0 <= out["curl"] <= 1):
        raise ValueError(f"peel: angle must lie in [0, {MAX_PEEL_ANGLE}] degrees, radius > 0 and "
                         f"curl in [0, 1], got {out}")
    if kind == "slabs" and (out["count"] != int(out["count"]) or not 1 <= out["count"] <= 64 or out["gap"] < 0):
        raise ValueError(f"slabs: count must be an integer in [1, 64] and gap >= 0, got {out}")
    if kind == "seam" and not 0 <= out["amount"] < 0.5:
        raise ValueError(f"seam: amount must lie in [0, 0.5), got {out['amount']}")
    return out


def support(kind: str, q: dict) -> tuple[np.ndarray, np.ndarray]:
    """Local box outside which D = 0 and α = 1 (or D is constant along the open axes)."""
    if kind == "gaussian":
        return np.zeros(3), np.array([1.0, 1.0, 2.0])
    if kind == "peel":
        r = 1.2 * q["radius"]  # the rotation fades out between radius and 1.2 radius
        return (np.array([q["hinge"] - r, 0.0, q["height"]]),
                np.array([q["hinge"] + r, 1.0, q["height"] + r]))
    if kind == "slabs":
        return np.zeros(3), np.array([1.0, 1.0, 1.0 + (q["count"] - 1) * q["gap"] + 0.5])
    return np.zeros(3), np.ones(3)


def _window(t):
    """Flat-top window on [0, 1]: 0 outside, ramps over 0.1 at both ends (C0)."""
    return dr.clip(dr.minimum(t, 1.0 - t) / 0.1, 0.0, 1.0)


def evaluate(kind: str, q: dict, l: mi.Point3f) -> tuple[mi.Vector3f, mi.Float]:
    """Inverse displacement D(ℓ') and exact mask α(ℓ') of primitive ``kind`` at local points.

    Args:
        kind: primitive name; q: its parameters (Python floats or opaque ``mi.Float``).
        l: local points ℓ' (unit cube frame).
    Returns:
        (D as ``mi.Vector3f`` in local units, α as ``mi.Float`` in {0, 1}).
    """
    x, y, z = l.x, l.y, l.z
    zero = dr.zeros(mi.Float, dr.width(x))
    one = zero + 1.0
    if kind == "gaussian":  # eq. 8, shifted so that D = 0 on the cube's sides
        s2 = 2.0 * q["sigma"] ** 2
        edge = dr.exp(-0.25 / s2)
        g = dr.exp(-((x - 0.5) ** 2 + (y - 0.5) ** 2) / s2)
        g = dr.select((x >= 0) & (x <= 1) & (y >= 0) & (y <= 1), dr.maximum(g - edge, 0.0) / (1.0 - edge), 0.0)
        zf = dr.select(z <= 1.0, dr.clip(z, 0.0, 1.0), dr.clip(2.0 - z, 0.0, 1.0))
        return mi.Vector3f(zero, zero, -q["amount"] * zf * g), one
    if kind == "peel":  # Fig. 1: turn the lid back by beta(r, phi'); the wedge 0 < phi' < theta(r) is cut
        u, w = x - q["hinge"], z - q["height"]
        phi = dr.atan2(w, -u)   # polar angle about the hinge, from -u (the lid side) towards +w
        r = dr.sqrt(u * u + w * w)
        radius = q["radius"]
        # the lid's rotation at distance r (kept by the map): grows with r when curled, faded
        # out between radius and 1.2 radius
        fade = dr.clip((1.2 * radius - r) / (0.2 * radius), 0.0, 1.0)
        theta = q["angle"] * (dr.pi / 180.0) * (1.0 - q["curl"] + q["curl"] * dr.minimum(r / radius, 1.0)) * fade
        # lid phi in [0, pi/2] went to [theta, theta + pi/2] (gap phi' < theta: onto the cut face
        # phi = 0, the C0 pseudo-inverse of §4.1); the rest above the plane, [pi/2, pi], was
        # squeezed into [theta + pi/2, pi]
        ramp_from = theta + 0.5 * dr.pi
        beta = dr.select(phi <= ramp_from, dr.clip(phi, 0.0, theta),
                         theta * (dr.pi - phi) / dr.maximum(dr.pi - ramp_from, 1e-6))
        inside = (y >= 0) & (y <= 1)
        beta = dr.select(inside, beta, 0.0)
        c, s = dr.cos(beta), dr.sin(beta)
        # rotating (u, w) back by beta: from angle phi to phi - beta (phi measured from -u to +w)
        ur, wr = u * c - w * s, w * c + u * s
        cut = inside & (phi > 0) & (phi < theta) & (r < radius)
        return mi.Vector3f(ur - u, zero, wr - w), dr.select(cut, 0.0, 1.0)
    if kind == "slabs":  # Fig. 6: slab k of height 1/n lifted by k * gap; gaps are cuts
        n, gap = q["count"], q["gap"]
        h = 1.0 / n
        period = h + gap
        k = dr.clip(dr.floor(z / period), 0.0, n - 1.0)
        local = z - k * period
        in_gap = (local > h) & (k < n - 1.0)
        top = (n - 1.0) * period + h
        dz = dr.select(in_gap, (k + 1.0) * h - z, -k * gap)
        dz = dr.select(z < 0, 0.0, dz)
        dz = dr.select(z > top, -(n - 1.0) * gap * dr.clip((top + 0.5 - z) / 0.5, 0.0, 1.0), dz)
        return mi.Vector3f(zero, zero, dz), dr.select(in_gap & (z >= 0), 0.0, 1.0)
    if kind == "wave":
        dz = q["amount"] * dr.sin(2.0 * dr.pi * (q["frequency"] * x + q["phase"])) * _window(x) * _window(y)
        return mi.Vector3f(zero, zero, dz), one
    if kind == "seam":  # Fig. 7: the seam x = 0.5 opens by 2w, each side compressed into [0, 1]
        inside = (x >= 0) & (x <= 1) & (y >= 0) & (y <= 1)
        w = q["amount"] * dr.clip(z, 0.0, 1.0) * dr.sin(dr.pi * dr.clip(y, 0.0, 1.0))
        d = x - 0.5
        gap = dr.abs(d) < w
        side = dr.sign(d)
        # |d| in [w, 0.5] maps linearly onto [0, 0.5]
        px = 0.5 + side * (dr.abs(d) - w) * 0.5 / (0.5 - w)
        dx = dr.select(gap, 0.5 - x, px - x)
        return mi.Vector3f(dr.select(inside, dx, 0.0), zero, zero), dr.select(inside & gap, 0.0, 1.0)
    raise ValueError(f"displacement map type {kind!r} is not one of {', '.join(PRIMITIVES)}")


class Placement:
    """The 4x4 placement matrix M of §6 (local map frame -> world).

    Raises:
        ValueError: M is not finite, not affine (last row 0 0 0 1) or singular.
    """

    def __init__(self, matrix=None, what: str = "to_world"):
        m = np.eye(4) if matrix is None else np.asarray(matrix, dtype=float)
        if m.shape != (4, 4):
            raise ValueError(f"{what}: expected a 4x4 matrix, got shape {m.shape}")
        if not np.isfinite(m).all():
            raise ValueError(f"{what}: the placement matrix M has non-finite entries:\n{m}")
        if not np.allclose(m[3], [0, 0, 0, 1]):
            raise ValueError(f"{what}: M must be affine (last row 0 0 0 1), got {m[3]}")
        lin = m[:3, :3]
        scale = max(np.abs(lin).max(), 1e-300)
        if abs(np.linalg.det(lin / scale)) < 1e-9:
            raise ValueError(f"{what}: the placement matrix M is singular (det {np.linalg.det(lin):.3g}); "
                             "M^-1 p' of §6 needs an invertible M")
        self.matrix = m
        self.inverse = np.linalg.inv(m)
        self.linear = lin

    def to_local(self, p: mi.Point3f) -> mi.Point3f:
        """M⁻¹ p' (affine)."""
        return _affine(self.inverse, p)

    def to_world(self, p) -> mi.Point3f:
        """M ℓ (affine)."""
        return _affine(self.matrix, p)

    def vector_to_world(self, v: mi.Vector3f) -> mi.Vector3f:
        """M v for a displacement vector (no translation)."""
        a = self.linear.tolist()
        return mi.Vector3f(*(a[i][0] * v.x + a[i][1] * v.y + a[i][2] * v.z for i in range(3)))

    def world_box(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """World bounding box of the local box [lo, hi]."""
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        w = corners @ self.matrix.T
        return w[:, :3].min(0), w[:, :3].max(0)


def _affine(m: np.ndarray, p) -> mi.Point3f:
    m = m.tolist()  # Python floats: a NumPy scalar times a symbolic Dr.Jit value would evaluate it
    return mi.Point3f(*(m[i][0] * p.x + m[i][1] * p.y + m[i][2] * p.z + m[i][3] for i in range(3)))
