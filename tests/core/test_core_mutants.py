"""Tests written to kill mutants of the core/ modules that survived the other tests
(issue 19, docs/testing.md, "Remaining ddm/ and core/ modules")."""
from __future__ import annotations
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.bezier import teapot_body
from mi_displace.core.surfaces import principal_curvatures


def _np(v):
    return np.stack([np.asarray(c) for c in v], 1)


# --- core/bezier.py ------------------------------------------------------------------------

def _body_points(rng, n=400):
    """Random (u, v) inside the teapot body's patches, away from patch borders (C = 4 columns,
    R = 3 rows: the derivatives jump across a border)."""
    col, row = rng.integers(0, 4, n), rng.integers(0, 3, n)
    return (col + rng.uniform(0.1, 0.9, n)) / 4, (row + rng.uniform(0.1, 0.9, n)) / 3


def test_teapot_derivatives_along_v_match_finite_differences(variant):
    """S_v and n_v (the tests above check only u) against central differences of S and n."""
    body = teapot_body()
    u, v = _body_points(np.random.default_rng(1))
    u, v = mi.Float(u), mi.Float(v)
    s, h = body.sample(u, v), 1e-3
    hi, lo = body.sample(u, v + h), body.sample(u, v - h)
    fd = (_np(hi.p) - _np(lo.p)) / (2 * h)
    scale = np.abs(fd).max()
    assert np.abs(fd - _np(s.dp_dv)).max() < 1e-3 * scale
    fdn = (_np(hi.n) - _np(lo.n)) / (2 * h)
    assert np.abs(fdn - _np(s.dn_dv)).max() < 2e-2 * max(np.abs(fdn).max(), 1.0)
    # n is the unit normal of S_u x S_v, pointing away from the z axis on the body rows
    cross = np.cross(_np(s.dp_du), _np(s.dp_dv))
    cross /= np.linalg.norm(cross, axis=1, keepdims=True)
    assert np.allclose(_np(s.n), cross, atol=1e-4) or np.allclose(_np(s.n), -cross, atol=1e-4)


def test_teapot_extent_is_the_longest_isoparametric_curve(variant):
    """extent() = (longest u-line, longest v-line) in object units, measured as polylines."""
    body = teapot_body()
    n, k = 96, 1024
    t = (np.arange(n) + 0.5) / n
    a = np.linspace(0, 1, k + 1)

    def lengths(u, v):
        p = _np(body.sample(mi.Float(u.ravel()), mi.Float(v.ravel())).p).reshape(*u.shape, 3)
        return np.linalg.norm(np.diff(p, axis=1), axis=2).sum(1)

    around = lengths(*np.meshgrid(a, t)[::1])                   # each row: u from 0 to 1
    down = lengths(*np.meshgrid(t, a, indexing="ij"))           # each row: v from 0 to 1
    eu, ev = body.extent()
    assert eu == pytest.approx(around.max(), rel=2e-3)
    assert ev == pytest.approx(down.max(), rel=2e-3)


def test_teapot_curvature_bounds_are_the_extremes_on_a_finer_grid(variant):
    """curvature_bounds() (sampled on a grid) against the principal curvatures on a grid
    three times finer, of other points: within 25 % (the extremes are spikes at the rim lip, which the coarse grid
    only approaches)."""
    body = teapot_body()
    n = 288
    t = (np.arange(n) + 0.25) / n
    u, v = np.meshgrid(t, t)
    k_max, k_min, _, _ = principal_curvatures(body.sample(mi.Float(u.ravel()), mi.Float(v.ravel())))
    lo, hi = body.curvature_bounds()
    assert lo == pytest.approx(float(np.min(k_min)), rel=0.25)
    assert hi == pytest.approx(float(np.max(k_max)), rel=0.25)
    assert body.name == "teapot"


# --- core/thickness.py ---------------------------------------------------------------------

from mi_displace.core import surfaces, tessellate  # noqa: E402
from mi_displace.core.thickness import crossing_check  # noqa: E402


def _constant(value):
    return lambda uv: (dr.full(mi.Float, value, dr.width(uv)), dr.zeros(mi.Vector2f, dr.width(uv)))


def test_crossing_check_without_displacement_or_vertices(variant):
    """No displacement (zero height) and an empty tessellation: nothing crosses, exactly."""
    flat = tessellate.Tessellation(mi.Point3f([0, 1, 0], [0, 0, 1], [0, 0, 0]),
                                   mi.Vector3f([0, 0, 0], [0, 0, 0], [1, 1, 1]),
                                   mi.Point2f([0, 1, 0], [0, 0, 1]), mi.Vector3u([0], [1], [2]))
    assert crossing_check(flat, thickness=0.1) == {
        "crossing_vertices": 0, "vertices": 3, "max_depth_ratio": 0.0}
    empty = tessellate.Tessellation(mi.Point3f(), mi.Vector3f(), mi.Point2f(), mi.Vector3u(),
                                    displacement=mi.Float())
    assert crossing_check(empty, thickness=0.1) == {
        "crossing_vertices": 0, "vertices": 0, "max_depth_ratio": 0.0}


def test_displacement_of_exactly_the_thickness_reaches_but_does_not_cross(variant):
    """A parametric base of thickness 0.25 (torus tube radius 0.125): an inward displacement
    of exactly 0.25 (d = 0.25 (0 - 1), exact in float32) touches the other side; a crossing
    is a displacement *deeper* than the thickness (ratio > 1)."""
    torus = surfaces.Torus(1.0, 0.125)
    assert torus.thickness() == 0.25
    t = tessellate.displace_parametric(torus, _constant(0.0), 0.25, 1.0, 16, 8)
    assert np.all(np.asarray(t.displacement) == -0.25)
    assert crossing_check(t, thickness=0.25)["crossing_vertices"] == 0
    t = tessellate.displace_parametric(torus, _constant(0.0), 0.2501, 1.0, 16, 8)
    check = crossing_check(t, thickness=0.25)
    assert check["crossing_vertices"] == t.vertex_count
    assert check["max_depth_ratio"] == pytest.approx(0.2501 / 0.25, rel=1e-6)


# --- core/tessellate.py --------------------------------------------------------------------

def test_group_mean_of_scalars_and_vectors(variant):
    groups = mi.UInt32([0, 1, 0, 2, 1, 0])
    x = mi.Float([1.0, 2.0, 3.0, 10.0, 6.0, 8.0])
    assert np.allclose(np.asarray(tessellate.group_mean(x, groups, 3)), [4, 4, 4, 10, 4, 4])
    v = mi.Vector3f(x, 2 * x, dr.zeros(mi.Float, 6) - 1)
    mean = _np(tessellate.group_mean(v, groups, 3))
    assert np.allclose(mean, np.c_[[4, 4, 4, 10, 4, 4], [8, 8, 8, 20, 8, 8], -np.ones(6)])


def test_vertex_frames_weight_the_triangles_by_area():
    """Two triangles of different area and different Jacobians around vertex 0: its S_u, S_v
    are their area-weighted mean (each triangle's [S_u S_v] solved from its edges and UV
    edges with NumPy)."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5], [-2, 0, 1.0]])
    uv = np.array([[0, 0], [1, 0], [0, 1], [-1, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    nrm = np.tile([0, 0, 1.0], (4, 1))
    s_u, s_v, _, _ = tessellate.vertex_frames(pos, nrm, uv, faces)
    total, weight = np.zeros((2, 3)), 0.0
    for f in faces:
        e = np.stack([pos[f[1]] - pos[f[0]], pos[f[2]] - pos[f[0]]], 1)       # (3, 2)
        d = np.stack([uv[f[1]] - uv[f[0]], uv[f[2]] - uv[f[0]]], 1)           # (2, 2)
        jac = e @ np.linalg.inv(d)                                            # [S_u S_v]
        area = 0.5 * np.linalg.norm(np.cross(e[:, 0], e[:, 1]))
        total += area * jac.T
        weight += area
    assert np.allclose(s_u[0], total[0] / weight, atol=1e-6)
    assert np.allclose(s_v[0], total[1] / weight, atol=1e-6)


def test_zero_vertex_normals_fall_back_to_the_tangent_frame(variant):
    """Vertex normals that vanish (here: given as zero) fall back to the normal of the
    tangent frame S_u x S_v, however small the frame (a 0.5 x 0.5 square in the x-z plane
    over the unit uv square: |S_u x S_v| = 0.25), not to +z."""
    pos = np.array([[0, 0, 0], [0.5, 0, 0], [0.5, 0, 0.5], [0, 0, 0.5]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    t = tessellate.displace_mesh(pos, np.zeros((4, 3)), uv, faces, None, 0.0, 0.0, 1)
    n = _np(t.base_normals)
    assert np.allclose(n, [0, -1, 0], atol=1e-6)      # (0.5, 0, 0) x (0, 0, 0.5) / 0.25


def test_outward_rays_use_their_own_facing(variant):
    """A vertex at the origin (n = +z) displaced +0.5: the +n ray meets a steep roof 0.3
    above at a grazing angle (cos 0.087 < GRAZING_COS: a crease, not a crossing), the -n ray
    a floor head-on.  The outward vertex is judged by its own (+n) ray: no crossing; moved
    -0.5 instead it passes through the floor 0.4 below (ratio 0.5 / 0.4)."""
    from mi_displace.core.thickness import crossing_warning

    a = np.radians(5.0)
    up = np.array([np.sin(a), 0, np.cos(a)])          # the roof rises 5 degrees off vertical
    mid = np.array([[0, 1, 0.3], [0, -1, 0.3]])       # the roof's middle line, over the origin
    roof = [*(mid - up), *(mid[::-1] + up)]
    floor = [[-1, -1, -0.4], [1, -1, -0.4], [1, 1, -0.4], [-1, 1, -0.4]]
    pos = np.array(roof + floor, np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])

    def vertex(d):
        p = mi.Point3f([0.0], [0.0], [0.0])
        return tessellate.Tessellation(p, mi.Vector3f([0], [0], [1]), mi.Point2f([0], [0]),
                                       mi.Vector3u([0], [0], [0]), p, mi.Vector3f([0], [0], [1]),
                                       mi.Float([d]))

    from mi_displace.core.thickness import cast_crossing_rays

    rays = cast_crossing_rays(vertex(0.5), (pos, faces))
    assert np.asarray(rays.gap[0])[0] == pytest.approx(0.3, abs=1e-4)      # the roof is met
    assert abs(np.asarray(rays.facing[0])[0]) == pytest.approx(np.sin(a), abs=1e-4)
    assert abs(np.asarray(rays.facing[1])[0]) == pytest.approx(1.0, abs=1e-6)   # the floor
    assert crossing_check(vertex(0.5), base_mesh=(pos, faces))["crossing_vertices"] == 0
    down = crossing_check(vertex(-0.5), base_mesh=(pos, faces))
    assert down["crossing_vertices"] == 1
    assert down["max_depth_ratio"] == pytest.approx(0.5 / 0.4, rel=1e-3)
    assert crossing_warning("displaced 'x'", down) == (
        "displaced 'x': displacement deeper than the local thickness of the base at 1 of 1 "
        "vertices (up to 1.25x the distance to the base's other side): the displaced surface "
        "passes through the base and the reference is wrong there; lower 'scale' or raise "
        "'midlevel'")


def test_crossing_rays_report_the_uv_of_what_they_hit(variant):
    """With base UVs the rays carry the texture coordinates of the hit: from the outer wall
    of a thin spherical shell (both walls with the same spherical UVs) the -n ray meets the
    inner wall at (nearly) the vertex's own (u, v)."""
    import trimesh

    from mi_displace.core.thickness import cast_crossing_rays

    ico = trimesh.creation.icosphere(3)
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1, keepdims=True)
    uv = np.stack([np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(v[:, 2], -1, 1)) / np.pi], 1)
    n = len(v)
    pos = np.concatenate([v, 0.985 * v])
    faces = np.concatenate([ico.faces, ico.faces[:, ::-1] + n])
    t = tessellate.displace_mesh(v, v, uv, ico.faces, None, 0.0, 0.0, 1)
    rays = cast_crossing_rays(t, (pos, faces, np.concatenate([uv, uv])))
    hit = _np(rays.uv[1])
    own = _np(t.texcoords)
    away = (np.abs(own[:, 0] - 0.5) < 0.4) & (np.abs(own[:, 1] - 0.5) < 0.35)   # seam, poles
    assert away.sum() > 100
    err = np.abs(hit[away] - own[away]).max(1)
    assert np.mean(err < 2e-3) > 0.95       # (a few hit a face spanning the u seam)
