"""Tile animation (HDDM §4.2): texture-space transforms, w scaling and metamorphosis.

At time t (any unit) the canonical tile point (x, y, z) is placed at

    (x', y') = R(omega t) ((x, y) - c) + c + velocity t      (c = tile centre (1/2, 1/2))
    w        = height * (1 + w_amplitude sin(2 pi w_frequency t)) * z + w_offset

i.e. an affine transform of the tile in texture space (translation in tile units per time
unit, rotation ``rotation_rate`` rad per time unit) and a scale in the normal (w)
direction; with ``tile_target`` the tile itself is a metamorphosis (eq. 3)

    V = V1 (1 - alpha) + V2 alpha,   N = normalize(N1 (1 - alpha) + N2 alpha),
    alpha(t) = alpha0 + alpha_rate t,

evaluated vertex by vertex in Dr.Jit; alpha outside [0, 1] extrapolates, as the paper allows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mi_displace.ddm.tiles import Tile


@dataclass
class Animation:
    """Parameters of §4.2 animation; all finite floats.

    Attributes:
        velocity_u, velocity_v: tile translation [tile widths per time unit].
        rotation_rate: tile rotation about its centre [rad per time unit].
        w_amplitude, w_frequency: relative w scaling amplitude and its frequency [1/time].
        alpha0, alpha_rate: metamorphosis alpha(t) = alpha0 + alpha_rate t (eq. 3).
    """

    velocity_u: float = 0.0
    velocity_v: float = 0.0
    rotation_rate: float = 0.0
    w_amplitude: float = 0.0
    w_frequency: float = 1.0
    alpha0: float = 0.0
    alpha_rate: float = 0.0

    def __post_init__(self):
        for key, value in self.__dict__.items():
            if not math.isfinite(float(value)):
                raise ValueError(f"ddm: '{key}' must be finite, got {value!r}")

    def affine(self, t):
        """Texture-space transform at time t: ((a00, a01), (a10, a11)), (b0, b1) acting on
        tile coordinates as x' = A x + b.  ``t``: a float, or a Dr.Jit Float (then the
        entries are Dr.Jit expressions of it and differentiable)."""
        c, s = _cos(self.rotation_rate * t), _sin(self.rotation_rate * t)
        a = ((c, -s), (s, c))
        b = (0.5 - (c * 0.5 - s * 0.5) + self.velocity_u * t,
             0.5 - (s * 0.5 + c * 0.5) + self.velocity_v * t)
        return a, b

    def w_factor(self, t):
        """Multiplier of the tile height at time t (float or Dr.Jit Float)."""
        return 1.0 + self.w_amplitude * _sin(2 * math.pi * self.w_frequency * t)

    def alpha(self, t: float) -> float:
        """Metamorphosis weight alpha(t) (eq. 3); may leave [0, 1] (extrapolation)."""
        return self.alpha0 + self.alpha_rate * t


def _sin(x):
    return dr.sin(x) if dr.is_array_v(x) else math.sin(x)


def _cos(x):
    return dr.cos(x) if dr.is_array_v(x) else math.cos(x)


def check_compatible(a: Tile, b: Tile) -> None:
    """ValueError unless ``b`` can be a metamorphosis target of ``a`` (same vertex count,
    same faces), naming both tiles."""
    if not a.compatible_with(b):
        raise ValueError(
            f"ddm: metamorphosis needs topologically compatible tiles, but 'tile' {a.name!r} "
            f"({a.vertex_count} vertices, {a.face_count} faces) and 'tile_target' {b.name!r} "
            f"({b.vertex_count} vertices, {b.face_count} faces) do not match vertex for vertex")


def tangent_frame(n: mi.Vector3f):
    """Dr.Jit T1, T2 (unit, T1 x T2 = n) for unit normals n — same rule as
    :func:`mi_displace.ddm.tiles.tangent_frames`."""
    axis = dr.select(dr.abs(n.x) < 0.6, mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0))
    t1 = dr.normalize(dr.cross(axis, n))
    return t1, dr.cross(n, t1)


def metamorphose(p1, n1, p2, n2, alpha):
    """Eq. 3 on Dr.Jit vertex arrays: blended positions and unit normals.  Normals that
    cancel (N1 = -N2 at alpha = 1/2) fall back to N1."""
    if not dr.is_array_v(alpha):         # a Dr.Jit alpha (differentiable time) stays
        alpha = dr.opaque(mi.Float, alpha)   # one kernel for every frame
    p = p1 * (1 - alpha) + p2 * alpha
    nh = n1 * (1 - alpha) + n2 * alpha
    length = dr.norm(nh)
    n = dr.select(length > 1e-12, nh / dr.maximum(length, 1e-30), n1)
    return p, n
