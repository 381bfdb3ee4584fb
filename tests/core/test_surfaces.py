"""Base surfaces: derivatives and curvatures against finite differences and closed forms."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core import surfaces

BASES = {
    "plane": {},
    "sphere": {"radius": 1.3},
    "cylinder": {"radius": 0.7, "length": 2.0},
    "torus": {"major_radius": 1.0, "minor_radius": 0.35},
}


def uv_grid(n=23):
    # keep away from the sphere poles where S_u vanishes
    g = np.linspace(0.07, 0.93, n)
    u, v = np.meshgrid(g, g)
    return mi.Float(u.ravel()), mi.Float(v.ravel())



def fd(fn, u, v, axis, h=1e-3):
    """Central difference of fn(u, v) (-> mi vector) along u (axis 0) or v."""
    du, dv = (h, 0.0) if axis == 0 else (0.0, h)
    return (np.asarray(fn(u + du, v + dv)) - np.asarray(fn(u - du, v - dv))) / (2 * h)


@pytest.mark.parametrize("name", BASES)
def test_derivatives_match_finite_differences(variant, name):
    base = surfaces.make_base(name, **BASES[name])
    u, v = uv_grid()
    s = base.sample(u, v)
    scale = max(base.extent())
    for axis, analytic in ((0, s.dp_du), (1, s.dp_dv)):
        num = fd(lambda a, b: base.sample(a, b).p, u, v, axis)
        assert np.max(np.abs(num - np.asarray(analytic))) < 2e-3 * scale * 2 * np.pi
    for axis, analytic in ((0, s.dn_du), (1, s.dn_dv)):
        num = fd(lambda a, b: base.sample(a, b).n, u, v, axis)
        assert np.max(np.abs(num - np.asarray(analytic))) < 2e-2
    n = np.asarray(s.n)
    assert np.allclose(np.linalg.norm(n, axis=0), 1, atol=1e-6)
    assert np.max(np.abs(np.sum(n * np.asarray(s.dp_du), 0))) < 1e-5 * scale * 10
    assert np.max(np.abs(np.sum(n * np.asarray(s.dp_dv), 0))) < 1e-5 * scale * 10


def closed_form_curvatures(name, u, v):
    p = BASES[name]
    if name == "plane":
        return np.zeros_like(u), np.zeros_like(u)
    if name == "sphere":
        k = np.full_like(u, 1 / p["radius"])
        return k, k
    if name == "cylinder":
        return np.full_like(u, 1 / p["radius"]), np.zeros_like(u)
    R, r = p["major_radius"], p["minor_radius"]
    c = np.cos(2 * np.pi * v)
    k_ring, k_tube = c / (R + r * c), np.full_like(u, 1 / r)
    return np.maximum(k_ring, k_tube), np.minimum(k_ring, k_tube)


@pytest.mark.parametrize("name", BASES)
def test_principal_curvatures(variant, name):
    base = surfaces.make_base(name, **BASES[name])
    u, v = uv_grid()
    s = base.sample(u, v)
    k_max, k_min, d_max, d_min = surfaces.principal_curvatures(s)
    e_max, e_min = closed_form_curvatures(name, np.asarray(u), np.asarray(v))
    assert np.allclose(np.asarray(k_max), e_max, atol=1e-4)
    assert np.allclose(np.asarray(k_min), e_min, atol=1e-4)
    lo, hi = base.curvature_bounds()
    assert np.all(np.asarray(k_min) >= lo - 1e-4) and np.all(np.asarray(k_max) <= hi + 1e-4)
    # Independent check: normal curvature along each principal direction by finite
    # differences of S and n along the uv step that maps to that direction.
    E, F, G = (np.sum(np.asarray(a) * np.asarray(b), 0) for a, b in
               ((s.dp_du, s.dp_du), (s.dp_du, s.dp_dv), (s.dp_dv, s.dp_dv)))
    for d, k in ((d_max, k_max), (d_min, k_min)):
        d = np.asarray(d)
        a = np.sum(d * np.asarray(s.dp_du), 0)
        b = np.sum(d * np.asarray(s.dp_dv), 0)
        det = E * G - F * F
        du, dv = (G * a - F * b) / det, (E * b - F * a) / det  # d = du S_u + dv S_v
        h = 1e-3
        sp = base.sample(u + mi.Float(h * du), v + mi.Float(h * dv))
        sm = base.sample(u - mi.Float(h * du), v - mi.Float(h * dv))
        dS = np.asarray(sp.p) - np.asarray(sm.p)
        dn = np.asarray(sp.n) - np.asarray(sm.n)
        kappa = np.sum(dn * dS, 0) / np.sum(dS * dS, 0)
        assert np.allclose(kappa, np.asarray(k), atol=5e-3 * max(1.0, np.abs(e_max).max()))


def test_unknown_base_and_bad_parameters():
    with pytest.raises(ValueError, match="unknown base 'cube'"):
        surfaces.make_base("cube")
    with pytest.raises(ValueError, match="radius"):
        surfaces.Sphere(radius=-1)
    with pytest.raises(ValueError, match="major_radius"):
        surfaces.Torus(major_radius=0.3, minor_radius=0.5)


# ---------------------------------------------------------------------------------------
# Mutants that survived the tests above: every base is parametrised along its lines of
# curvature (F = 0 and b12 = 0), so the off-diagonal terms of the shape operator were never
# exercised.  A graph surface z = f(x, y) over a sheared (u, v) grid has neither.


def graph_sample(u, v):
    """S(u, v) = (x, y, f(x, y)), x = u + 0.3 v - 0.5, y = 0.8 v - 0.4, with
    f = 0.3 x^2 + 0.5 x y - 0.2 y^2 + 0.1 x^3; exact derivatives (NumPy, float64).
    Returns the SurfaceSample and (f_x, f_y, f_xx, f_xy, f_yy, w = |(-f_x, -f_y, 1)|)."""
    x, y = u + 0.3 * v - 0.5, 0.8 * v - 0.4
    fx, fy = 0.6 * x + 0.5 * y + 0.3 * x**2, 0.5 * x - 0.4 * y
    fxx, fxy, fyy = 0.6 + 0.6 * x, np.full_like(x, 0.5), np.full_like(x, -0.4)
    m = np.stack([-fx, -fy, np.ones_like(x)])
    w = np.linalg.norm(m, axis=0)
    n = m / w
    xu, yu, xv, yv = 1.0, 0.0, 0.3, 0.8

    def dn(xd, yd):
        md = np.stack([-(fxx * xd + fxy * yd), -(fxy * xd + fyy * yd), np.zeros_like(x)])
        return (md - n * np.sum(n * md, 0)) / w

    vec = lambda a: mi.Vector3f(*(mi.Float(c.astype(np.float32)) for c in a))
    one, zero = np.ones_like(x), np.zeros_like(x)
    s = surfaces.SurfaceSample(
        p=mi.Point3f(vec(np.stack([x, y, 0.3 * x**2 + 0.5 * x * y - 0.2 * y**2 + 0.1 * x**3]))),
        dp_du=vec(np.stack([xu * one, yu * one, fx * xu + fy * yu])),
        dp_dv=vec(np.stack([xv * one, yv * one, fx * xv + fy * yv])),
        n=vec(n), dn_du=vec(dn(xu, yu)), dn_dv=vec(dn(xv, yv)))
    return s, (fx, fy, fxx, fxy, fyy, w)


def test_principal_curvatures_of_a_skew_parametrised_graph(variant):
    """Closed-form mean and Gaussian curvature of a graph (do Carmo §3.3), with this module's
    sign (kappa > 0 bending away from n): kappa = -(H +- sqrt(H^2 - K))."""
    g = np.linspace(0.05, 0.95, 15)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    s, (fx, fy, fxx, fxy, fyy, w) = graph_sample(u, v)
    assert np.abs(np.asarray(dr.dot(s.dp_du, s.dp_dv))).min() > 0.05   # F != 0 everywhere
    k_max, k_min, d_max, d_min = (np.asarray(a) for a in surfaces.principal_curvatures(s))
    H = ((1 + fy**2) * fxx - 2 * fx * fy * fxy + (1 + fx**2) * fyy) / (2 * w**3)
    K = (fxx * fyy - fxy**2) / w**4
    root = np.sqrt(H**2 - K)
    assert root.min() > 0.05                                           # no umbilic
    assert np.allclose(k_max, -(H - root), atol=2e-5)
    assert np.allclose(k_min, -(H + root), atol=2e-5)
    n = np.asarray(s.n)
    for d, k in ((d_max, k_max), (d_min, k_min)):
        assert np.allclose(np.linalg.norm(d, axis=0), 1, atol=1e-5)
        assert np.abs(np.sum(d * n, 0)).max() < 1e-5                   # tangent
        # normal curvature along d from the second fundamental form in (x, y)
        dx, dy = d[0], d[1]
        assert np.allclose(-(fxx * dx**2 + 2 * fxy * dx * dy + fyy * dy**2) / w, k, atol=5e-5)
    # (d_max, d_min, n) is a right-handed orthonormal frame: d_min = n x d_max
    assert np.allclose(np.sum(np.cross(d_max.T, d_min.T) * n.T, 1), 1, atol=1e-5)


@pytest.mark.parametrize("name", BASES)
def test_extent_is_the_longest_isoparametric_curve(variant, name):
    """extent() against the length of the u- and v-curves measured as fine polylines,
    the longest over a sweep of the other parameter."""
    base = surfaces.make_base(name, **BASES[name])
    t = np.linspace(0, 1, 2001)
    other = np.linspace(0, 1, 41)
    lengths = []
    for axis in (0, 1):
        a, b = np.meshgrid(t, other)                   # a runs along the curve
        u, v = (a, b) if axis == 0 else (b, a)
        p = np.asarray(base.sample(mi.Float(u.ravel()), mi.Float(v.ravel())).p).reshape(3, 41, -1)
        lengths.append(np.linalg.norm(np.diff(p, axis=2), axis=0).sum(1).max())
    assert np.allclose(base.extent(), lengths, rtol=1e-4)


@pytest.mark.parametrize("name", BASES)
def test_curvature_bounds_are_attained(variant, name):
    """curvature_bounds() is the exact (min, max) of the principal curvatures, attained on
    the grid (the torus's inner equator v = 1/2 is a grid row)."""
    base = surfaces.make_base(name, **BASES[name])
    s = base.sample(*uv_grid())
    k_max, k_min, _, _ = surfaces.principal_curvatures(s)
    assert np.allclose(base.curvature_bounds(), (np.asarray(k_min).min(), np.asarray(k_max).max()),
                       atol=1e-4)


def test_thickness_is_the_distance_through_the_solid():
    """Along -n from a point of the surface to the other side: the diameter of a sphere or
    a cylinder, the tube's diameter for a torus; a plane has no other side."""
    assert surfaces.Sphere(1.3).thickness() == 2.6
    assert surfaces.Cylinder(0.7, 2.0).thickness() == 1.4
    assert surfaces.Torus(1.0, 0.35).thickness() == 0.7
    assert surfaces.Plane().thickness() == float("inf")


def test_each_invalid_parameter_is_named():
    cases = [
        (lambda: surfaces.Sphere(radius=0), r"^sphere: 'radius' must be > 0, got 0$"),
        (lambda: surfaces.Cylinder(radius=0), r"^cylinder: 'radius' must be > 0, got 0$"),
        (lambda: surfaces.Cylinder(length=0), r"^cylinder: 'length' must be > 0, got 0$"),
        (lambda: surfaces.Torus(minor_radius=0), r"^torus: 'minor_radius' must be > 0, got 0$"),
        (lambda: surfaces.Torus(1.0, 1.0), r"^torus: 'major_radius' \(1.0\) must exceed "
                                           r"'minor_radius' \(1.0\) for a ring torus$"),
        (lambda: surfaces.make_base("cube"), r"^unknown base 'cube'; expected one of cylinder, "
                                             r"plane, sphere, torus or 'mesh'$"),
        (lambda: surfaces.make_base("sphere", radius=1, size=2),
         r"^base 'sphere': bad parameters \['radius', 'size'\]: .*'size'"),
    ]
    for make, message in cases:
        with pytest.raises(ValueError, match=message):
            make()
    # the limits themselves are allowed just inside
    surfaces.Sphere(1e-6), surfaces.Cylinder(1e-6, 1e-6), surfaces.Torus(1.0 + 1e-6, 1.0)


@pytest.mark.parametrize("name", BASES)
def test_domain_flags_and_names_match_the_geometry(variant, name):
    """periodic_u / periodic_v: S(0, v) == S(1, v) (resp. in v); poles: the rows v = 0 and
    v = 1 are single points; each class is registered under its own name."""
    base = surfaces.make_base(name, **BASES[name])
    t = mi.Float(np.linspace(0.1, 0.9, 9))
    zero, one = dr.zeros(mi.Float, 9), dr.full(mi.Float, 1.0, 9)
    def same(a, b):
        return np.allclose(np.asarray(base.sample(*a).p), np.asarray(base.sample(*b).p), atol=1e-5)
    assert base.periodic_u == same((zero, t), (one, t))
    assert base.periodic_v == same((t, zero), (t, one))
    rows = [np.asarray(base.sample(t, c).p) for c in (zero, one)]
    assert base.poles == all(np.ptp(r, axis=1).max() < 1e-6 for r in rows)
    assert base.name == name and type(base) is surfaces.BASES[name]


@pytest.mark.parametrize("radius", [1e-3, 1.0, 1e3])
def test_umbilic_directions_are_s_u_and_n_cross_s_u(variant, radius):
    """Every direction is principal at an umbilic; the documented choice is S_u, n x S_u,
    at any scale (the umbilic test is relative to the first fundamental form)."""
    for base in (surfaces.Sphere(radius), surfaces.Plane()):
        s = base.sample(*uv_grid(9))
        _, _, d_max, d_min = (np.asarray(a) for a in surfaces.principal_curvatures(s))
        su = np.asarray(s.dp_du) / np.linalg.norm(np.asarray(s.dp_du), axis=0)
        assert np.allclose(d_max, su, atol=1e-5)
        assert np.allclose(d_min, np.cross(np.asarray(s.n).T, su.T).T, atol=1e-5)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_principal_directions_do_not_depend_on_the_units(variant, scale):
    """A torus in any unit: kappa_max = 1 / r along the tube (S_v), kappa_min along the ring
    (S_u).  (The umbilic test once compared a unitless |d|^2 with (E + G)^2 [length^4]: in
    metres-sized scenes given in millimetres every point was taken for an umbilic.)"""
    base = surfaces.Torus(1.0 * scale, 0.4 * scale)
    s = base.sample(*uv_grid(9))
    k_max, _, d_max, d_min = (np.asarray(a) for a in surfaces.principal_curvatures(s))
    assert np.allclose(k_max * scale, 1 / 0.4, rtol=1e-5)
    for d, t in ((d_max, s.dp_dv), (d_min, s.dp_du)):
        t = np.asarray(t) / np.linalg.norm(np.asarray(t), axis=0)
        assert np.allclose(np.abs(np.sum(d * t, 0)), 1, atol=1e-5)


@pytest.mark.parametrize("kind, base, props", [
    ("rectangle", surfaces.Plane(), {}),
    ("sphere", surfaces.Sphere(1.3), {"radius": 1.3}),
    ("sphere", surfaces.Sphere(), {}),            # both default to the unit sphere
])
def test_plane_and_sphere_follow_mitsubas_uv_convention(variant, kind, base, props):
    """Position and normal at (u, v) equal those of Mitsuba's own shape
    (Shape.eval_parameterization), so a texture lands where Mitsuba puts it."""
    u, v = uv_grid(7)
    si = mi.load_dict({"type": kind, **props}).eval_parameterization(mi.Point2f(u, v))
    assert np.all(np.asarray(si.is_valid()))
    s = base.sample(u, v)
    assert np.allclose(np.asarray(s.p), np.asarray(si.p), atol=1e-5)
    assert np.allclose(np.asarray(s.n), np.asarray(si.n), atol=1e-5)


def test_principal_direction_of_a_sheared_frame_with_a_vanishing_row(variant):
    """A strongly sheared frame (E = 4, F = 1.5, G = 1) whose shape operator W is lower
    triangular with w11 = kappa_max: the first row of W - kappa_max I vanishes and only the
    second gives the eigenvector.  Truth: the Rayleigh quotient II(d) / I(d) along d."""
    k1, k2 = 2.0, -0.5
    s_u, s_v = np.array([2.0, 0.0, 0.0]), np.array([0.75, np.sqrt(0.4375), 0.0])
    I = np.array([[s_u @ s_u, s_u @ s_v], [s_v @ s_u, s_v @ s_v]])
    W = np.array([[k1, 0.0], [I[0, 1] * (k2 - k1) / I[1, 1], k2]])   # I W symmetric
    B = I @ W
    # tangent n_u, n_v with S_u . n_u = B11, S_v . n_u = B21, S_u . n_v = B12, S_v . n_v = B22
    T = np.stack([s_u[:2], s_v[:2]])
    n_u, n_v = (np.append(np.linalg.solve(T, B[:, k]), 0.0) for k in range(2))
    vec = lambda a: mi.Vector3f(*(mi.Float([c]) for c in a))
    s = surfaces.SurfaceSample(p=mi.Point3f(0, 0, 0), dp_du=vec(s_u), dp_dv=vec(s_v),
                               n=vec([0.0, 0.0, 1.0]), dn_du=vec(n_u), dn_dv=vec(n_v))
    k_max, k_min, d_max, d_min = (np.asarray(a).ravel() for a in surfaces.principal_curvatures(s))
    assert np.allclose([k_max[0], k_min[0]], [k1, k2], atol=1e-5)
    for d, k in ((d_max, k1), (d_min, k2)):
        ab = np.linalg.solve(T.T, d[:2])                    # d = a S_u + b S_v
        assert np.isclose(ab @ B @ ab / (ab @ I @ ab), k, atol=1e-4)
