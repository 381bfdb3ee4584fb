"""Parametric base surfaces S(u, v) with exact derivatives, normals and curvatures.

Every base maps texture coordinates (u, v) in [0, 1]^2 to object space and gives, per
point, the position S, the partial derivatives S_u, S_v, the outward unit normal n and
its derivatives n_u, n_v (Weingarten).  All quantities are Dr.Jit arrays of the length of
``u``; lengths are in object-space units, derivatives per unit of (u, v).

Sign convention for curvature: kappa > 0 where the surface bends away from its normal
(convex, centre of curvature below the surface): a sphere of radius r with outward
normals has kappa_1 = kappa_2 = +1/r.  With this convention the shape operator is
dn = W dS, i.e. n_u = W S_u.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mi_displace.core.properties import Param


@dataclass
class SurfaceSample:
    """Differential geometry of a base surface at a batch of (u, v).

    Attributes (each Dr.Jit, N entries):
        p: position S(u, v) [object units], mi.Point3f
        dp_du, dp_dv: dS/du, dS/dv [object units per unit uv], mi.Vector3f
        n: outward unit normal, mi.Normal3f
        dn_du, dn_dv: derivatives of the unit normal [per unit uv], mi.Vector3f
    """

    p: mi.Point3f
    dp_du: mi.Vector3f
    dp_dv: mi.Vector3f
    n: mi.Vector3f
    dn_du: mi.Vector3f
    dn_dv: mi.Vector3f


def principal_curvatures(s: SurfaceSample):
    """Principal curvatures and directions from the first fundamental form and dn.

    The shape operator in the (u, v) basis is W = I^-1 B with I = [[E, F], [F, G]]
    (E = S_u.S_u, F = S_u.S_v, G = S_v.S_v) and B = [[S_u.n_u, S_u.n_v],
    [S_v.n_u, S_v.n_v]] (symmetric).  Its eigenvalues are kappa_max >= kappa_min.

    Returns:
        (kappa_max, kappa_min, dir_max, dir_min): two mi.Float [1/object units] and two
        unit tangent mi.Vector3f.  At umbilics (sphere, plane) the directions are S_u and
        n x S_u.
    """
    E = dr.dot(s.dp_du, s.dp_du)
    F = dr.dot(s.dp_du, s.dp_dv)
    G = dr.dot(s.dp_dv, s.dp_dv)
    b11 = dr.dot(s.dp_du, s.dn_du)
    b12 = 0.5 * (dr.dot(s.dp_du, s.dn_dv) + dr.dot(s.dp_dv, s.dn_du))
    b22 = dr.dot(s.dp_dv, s.dn_dv)
    det_i = dr.maximum(E * G - F * F, 1e-30)
    # W = I^-1 B
    w11 = (G * b11 - F * b12) / det_i
    w12 = (G * b12 - F * b22) / det_i
    w21 = (E * b12 - F * b11) / det_i
    w22 = (E * b22 - F * b12) / det_i
    mean = 0.5 * (w11 + w22)
    # H^2 - K written without cancellation (umbilics give exactly 0)
    half_diff = 0.5 * (w11 - w22)
    disc = dr.sqrt(dr.maximum(half_diff * half_diff + w12 * w21, 0.0))
    k_max, k_min = mean + disc, mean - disc
    # Eigenvector of W for k_max in (u, v) coordinates: pick the better conditioned row.
    a1, b1 = w12, k_max - w11
    a2, b2 = k_max - w22, w21
    use_first = dr.abs(a1) + dr.abs(b1) >= dr.abs(a2) + dr.abs(b2)
    du = dr.select(use_first, a1, a2)
    dv = dr.select(use_first, b1, b2)
    d_max = s.dp_du * du + s.dp_dv * dv
    # |d_max| ~ |S_u| |W|: the umbilic test is relative to both (scale-free, unitless)
    w_sq = w11 * w11 + w12 * w12 + w21 * w21 + w22 * w22
    umbilic = dr.squared_norm(d_max) <= 1e-12 * (E + G) * w_sq + 1e-30
    d_max = dr.normalize(dr.select(umbilic, s.dp_du, d_max))
    d_min = dr.normalize(dr.cross(s.n, d_max))
    return k_max, k_min, d_max, d_min


class BaseSurface:
    """A parametric base surface over (u, v) in [0, 1]^2 (object space).

    Subclasses implement :meth:`sample`.  Class attributes describe the parameter
    domain for tessellation: ``periodic_u`` / ``periodic_v`` (S(u+1, v) == S(u, v)),
    ``poles`` (rows v = 0 and v = 1 collapse to points) and :meth:`extent`.
    """

    name = "base"
    periodic_u = False
    periodic_v = False
    poles = False

    def sample(self, u: mi.Float, v: mi.Float) -> SurfaceSample:
        raise NotImplementedError

    def extent(self) -> tuple[float, float]:
        """Lengths [object units] of the longest u- and v-isoparametric curves."""
        raise NotImplementedError

    def curvature_bounds(self) -> tuple[float, float]:
        """(min, max) principal curvature over the surface [1 / object units]."""
        raise NotImplementedError

    def thickness(self) -> float:
        """Shortest distance along -n from the surface to its other side [object units]."""
        return float("inf")


class Plane(BaseSurface):
    """The square [-1, 1]^2 at z = 0 (Mitsuba's ``rectangle``), normal +z.

    S(u, v) = (2u - 1, 2v - 1, 0).
    """

    name = "plane"

    def sample(self, u, v):
        zero = dr.zeros(mi.Vector3f, dr.width(u))
        return SurfaceSample(
            p=mi.Point3f(2 * u - 1, 2 * v - 1, 0),
            dp_du=mi.Vector3f(2, 0, 0) + zero,
            dp_dv=mi.Vector3f(0, 2, 0) + zero,
            n=mi.Vector3f(0, 0, 1) + zero,
            dn_du=zero,
            dn_dv=zero,
        )

    def extent(self):
        return 2.0, 2.0

    def curvature_bounds(self):
        return 0.0, 0.0


class Sphere(BaseSurface):
    """Sphere of ``radius`` r about the origin, Mitsuba's uv convention.

    phi = 2 pi u, theta = pi v;  S = r (sin theta cos phi, sin theta sin phi, cos theta),
    n = S / r, so n_u = S_u / r and kappa_1 = kappa_2 = 1 / r.
    """

    name = "sphere"
    periodic_u = True
    poles = True

    def __init__(self, radius: float = 1.0):
        if not radius > 0:
            raise ValueError(f"sphere: 'radius' must be > 0, got {radius}")
        self.radius = float(radius)

    def sample(self, u, v):
        r = self.radius
        sp, cp = dr.sincos(dr.two_pi * u)
        st, ct = dr.sincos(dr.pi * v)
        n = mi.Vector3f(st * cp, st * sp, ct)
        n_u = dr.two_pi * mi.Vector3f(-st * sp, st * cp, 0)
        n_v = dr.pi * mi.Vector3f(ct * cp, ct * sp, -st)
        return SurfaceSample(p=mi.Point3f(r * n), dp_du=r * n_u, dp_dv=r * n_v,
                             n=n, dn_du=n_u, dn_dv=n_v)

    def extent(self):
        return 2 * dr.pi * self.radius, dr.pi * self.radius

    def curvature_bounds(self):
        return 1 / self.radius, 1 / self.radius

    def thickness(self):
        return 2 * self.radius


class Cylinder(BaseSurface):
    """Open cylinder of ``radius`` r about the z axis from z = 0 to z = ``length``.

    S = (r cos phi, r sin phi, length v) with phi = 2 pi u; kappa = (1 / r, 0).
    """

    name = "cylinder"
    periodic_u = True

    def __init__(self, radius: float = 1.0, length: float = 2.0):
        if not radius > 0:
            raise ValueError(f"cylinder: 'radius' must be > 0, got {radius}")
        if not length > 0:
            raise ValueError(f"cylinder: 'length' must be > 0, got {length}")
        self.radius, self.length = float(radius), float(length)

    def sample(self, u, v):
        r = self.radius
        sp, cp = dr.sincos(dr.two_pi * u)
        n = mi.Vector3f(cp, sp, 0)
        n_u = dr.two_pi * mi.Vector3f(-sp, cp, 0)
        zero = dr.zeros(mi.Vector3f, dr.width(u))
        return SurfaceSample(p=mi.Point3f(r * cp, r * sp, self.length * v), dp_du=r * n_u,
                             dp_dv=mi.Vector3f(0, 0, self.length) + zero,
                             n=n, dn_du=n_u, dn_dv=zero)

    def extent(self):
        return 2 * dr.pi * self.radius, self.length

    def curvature_bounds(self):
        return 0.0, 1 / self.radius

    def thickness(self):
        return 2 * self.radius


class Torus(BaseSurface):
    """Torus about the z axis: ``major_radius`` R to the tube centre, ``minor_radius`` r.

    phi = 2 pi u (around z), psi = 2 pi v (around the tube);
    S = ((R + r cos psi) cos phi, (R + r cos psi) sin phi, r sin psi),
    n = (cos psi cos phi, cos psi sin phi, sin psi);
    kappa along u = cos psi / (R + r cos psi), along v = 1 / r.
    """

    name = "torus"
    periodic_u = True
    periodic_v = True

    def __init__(self, major_radius: float = 1.0, minor_radius: float = 0.4):
        if not minor_radius > 0:
            raise ValueError(f"torus: 'minor_radius' must be > 0, got {minor_radius}")
        if not major_radius > minor_radius:
            raise ValueError(
                f"torus: 'major_radius' ({major_radius}) must exceed 'minor_radius' "
                f"({minor_radius}) for a ring torus"
            )
        self.major_radius, self.minor_radius = float(major_radius), float(minor_radius)

    def sample(self, u, v):
        R, r = self.major_radius, self.minor_radius
        sp, cp = dr.sincos(dr.two_pi * u)
        ss, cs = dr.sincos(dr.two_pi * v)
        ring = R + r * cs
        n = mi.Vector3f(cs * cp, cs * sp, ss)
        around = mi.Vector3f(-sp, cp, 0)
        n_u = dr.two_pi * cs * around
        n_v = dr.two_pi * mi.Vector3f(-ss * cp, -ss * sp, cs)
        return SurfaceSample(p=mi.Point3f(ring * cp, ring * sp, r * ss),
                             dp_du=dr.two_pi * ring * around, dp_dv=r * n_v,
                             n=n, dn_du=n_u, dn_dv=n_v)

    def extent(self):
        R, r = self.major_radius, self.minor_radius
        return 2 * dr.pi * (R + r), 2 * dr.pi * r

    def curvature_bounds(self):
        R, r = self.major_radius, self.minor_radius
        return -1 / (R - r), 1 / r

    def thickness(self):
        return 2 * self.minor_radius


BASES = {"plane": Plane, "sphere": Sphere, "cylinder": Cylinder, "torus": Torus}


#: The float parameters of each parametric base, as plugins name them.
BASE_PARAMS = {"plane": (), "sphere": ("radius",), "cylinder": ("radius", "length"),
               "torus": ("major_radius", "minor_radius")}

#: The declared dimensions of the parametric bases (each optional: the class default applies).
BASE_DIMENSIONS = (
    Param("radius", "float", None, "sphere, cylinder: radius (default 1)", unit="object",
          low=0, open_low=True),
    Param("length", "float", None, "cylinder: length along z (default 2)", unit="object",
          low=0, open_low=True),
    Param("major_radius", "float", None, "torus: radius of the centre circle (default 1)",
          unit="object", low=0, open_low=True),
    Param("minor_radius", "float", None, "torus: radius of the tube (default 0.4, < major_radius)",
          unit="object", low=0, open_low=True),
)
#: A base mesh file instead of a parametric base.
BASE_FILENAME = Param("filename", "string", None, "base `mesh`: a PLY/OBJ with UVs (relative "
                      "to the scene file)")
#: A target edge length instead of a grid resolution.
EDGE_LENGTH = Param("edge_length", "float", None, "target edge length instead of `resolution`",
                    unit="object", low=0, open_low=True)


def base_param(default: str, bases: tuple[str, ...] = (*BASES, "mesh")) -> Param:
    """The ``base`` parameter of a plugin (``default`` when neither ``base`` nor
    ``filename`` is given; a ``filename`` alone means ``mesh``)."""
    return Param("base", "string", None, f"base surface (default: `mesh` with a `filename`, "
                 f"else `{default}`)", choices=bases)


def resolution_param(default: int | None, doc: str = "grid cells along u (v keeps the "
                     "base's aspect ratio)") -> Param:
    """The ``resolution`` parameter (``default`` ``None``: the plugin's rule, in ``doc``)."""
    return Param("resolution", "int", default, doc, low=1, high=1 << 20)


def base_name(plugin: str, values: dict, default: str, file_bases: tuple[str, ...] = ("mesh",)) -> str:
    """The base a plugin's read ``values`` name (:func:`base_param`), checking that
    ``filename`` goes with a base of ``file_bases`` and that ``mesh`` has one."""
    name = values["base"] or ("mesh" if values["filename"] else default)
    if values["filename"] is not None and name not in file_bases:
        raise ValueError(f"{plugin}: parameter 'filename' applies to base "
                         f"{' or '.join(map(repr, file_bases))} only (base is {name!r})")
    if name == "mesh" and values["filename"] is None:
        raise ValueError(f"{plugin}: base 'mesh' needs a 'filename' (PLY/OBJ with UVs)")
    return name


def base_params(plugin: str, name: str, values: dict, extra: dict | None = None) -> dict:
    """The dimensions (:data:`BASE_DIMENSIONS`) of base ``name`` that a plugin's read
    ``values`` give, as floats; ``extra`` adds bases of a plugin's own (``ddm``'s ``teapot``).

    Raises:
        ValueError: naming a dimension given for a base that has none of that name.
    """
    names = {**BASE_PARAMS, **(extra or {})}.get(name, ())
    for p in BASE_DIMENSIONS:
        if values.get(p.name) is not None and p.name not in names:
            raise ValueError(f"{plugin}: parameter {p.name!r} does not apply to base {name!r}")
    return {k: values[k] for k in names if values.get(k) is not None}


def make_base(name: str, **params) -> BaseSurface:
    """Construct a parametric base by name; ValueError for unknown names or parameters."""
    if name not in BASES:
        raise ValueError(
            f"unknown base {name!r}; expected one of {', '.join(sorted(BASES))} or 'mesh'"
        )
    try:
        return BASES[name](**params)
    except TypeError as e:
        raise ValueError(f"base {name!r}: bad parameters {sorted(params)}: {e}") from None
