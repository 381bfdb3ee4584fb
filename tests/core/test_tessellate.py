"""True displacement: exact base at zero height, analytic displacement and normals,
watertight closed bases, shared vertices of mesh subdivision."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import trimesh
from scipy.spatial import Delaunay

from mi_displace.core import surfaces, tessellate


def ripple(uv):
    """h = 0.5 + 0.5 sin(2 pi 4 u) cos(2 pi 3 v) and its exact gradient."""
    a, b = dr.two_pi * 4 * uv.x, dr.two_pi * 3 * uv.y
    h = 0.5 + 0.5 * dr.sin(a) * dr.cos(b)
    grad = mi.Vector2f(0.5 * dr.two_pi * 4 * dr.cos(a) * dr.cos(b),
                       -0.5 * dr.two_pi * 3 * dr.sin(a) * dr.sin(b))
    return h, grad


def to_trimesh(t: tessellate.Tessellation) -> trimesh.Trimesh:
    v = np.asarray(t.positions).T
    f = np.asarray(t.faces).T
    assert np.all(np.isfinite(v)) and np.all(np.isfinite(np.asarray(t.normals)))
    return trimesh.Trimesh(v, f, process=True)


PARAMS = {"plane": {}, "sphere": {"radius": 1.0}, "cylinder": {"radius": 0.5},
          "torus": {"major_radius": 1.0, "minor_radius": 0.3}}


@pytest.mark.parametrize("name", PARAMS)
def test_zero_height_is_the_base_exactly(variant, name):
    base = surfaces.make_base(name, **PARAMS[name])
    nu, nv = tessellate.grid_resolution(base, 24)
    flat = tessellate.displace_parametric(base, None, 0.3, 0.0, nu, nv)
    zero = tessellate.displace_parametric(base, ripple, 0.0, 0.0, nu, nv)
    mid = tessellate.displace_parametric(base, lambda uv: (dr.full(mi.Float, 0.5, dr.width(uv)),
                                                           dr.zeros(mi.Vector2f, dr.width(uv))),
                                         0.3, 0.5, nu, nv)
    uv = np.asarray(flat.texcoords)
    wrapped_u = np.where(uv[0] == 1, 0, uv[0]) if base.periodic_u else uv[0]
    wrapped_v = np.where(uv[1] == 1, 0, uv[1]) if base.periodic_v else uv[1]
    s = base.sample(mi.Float(wrapped_u), mi.Float(wrapped_v))
    expected = np.asarray(s.p)
    if not base.poles:
        assert np.array_equal(np.asarray(flat.positions), expected)
    for t in (zero, mid):  # scale 0, or height == midlevel: bit-identical to no height
        assert np.array_equal(np.asarray(t.positions), np.asarray(flat.positions))
        assert np.array_equal(np.asarray(t.faces), np.asarray(flat.faces))


def test_displacement_and_analytic_normals_on_sphere(variant):
    base = surfaces.Sphere(1.0)
    nu, nv = 96, 48
    t = tessellate.displace_parametric(base, ripple, 0.05, 0.5, nu, nv)
    uv = np.asarray(t.texcoords)
    inner = (uv[1] > 0.1) & (uv[1] < 0.9) & (uv[0] < 1)
    u, v = mi.Float(uv[0][inner]), mi.Float(uv[1][inner])
    s = base.sample(u, v)
    h, _ = ripple(mi.Point2f(u, v))
    expected = np.asarray(s.p + 0.05 * (h - 0.5) * s.n)
    assert np.allclose(np.asarray(t.positions)[:, inner], expected, atol=1e-6)

    # normals against central differences of P(u, v) (independent of the chain rule)
    def P(a, b):
        sb = base.sample(a, b)
        hh, _ = ripple(mi.Point2f(a, b))
        return np.asarray(sb.p + 0.05 * (hh - 0.5) * sb.n)

    eps = 1e-3
    pu = (P(u + eps, v) - P(u - eps, v)) / (2 * eps)
    pv = (P(u, v + eps) - P(u, v - eps)) / (2 * eps)
    n_fd = np.cross(pu.T, pv.T)
    n_fd *= np.sign(np.sum(n_fd * np.asarray(s.n).T, 1))[:, None]
    n_fd /= np.linalg.norm(n_fd, axis=1)[:, None]
    angle = np.degrees(np.arccos(np.clip(np.sum(n_fd * np.asarray(t.normals)[:, inner].T, 1), -1, 1)))
    assert angle.max() < 0.5
    # the ripple really tilts the normals
    tilt = np.degrees(np.arccos(np.clip(np.sum(np.asarray(s.n).T * np.asarray(t.normals)[:, inner].T, 1), -1, 1)))
    assert tilt.max() > 10


@pytest.mark.parametrize("name,euler", [("sphere", 2), ("torus", 0)])
def test_closed_bases_stay_watertight(variant, name, euler):
    base = surfaces.make_base(name, **PARAMS[name])
    nu, nv = tessellate.grid_resolution(base, 40)
    m = to_trimesh(tessellate.displace_parametric(base, ripple, 0.1, 0.0, nu, nv))
    assert m.is_watertight and m.is_winding_consistent
    assert m.euler_number == euler
    assert m.volume > 0  # faces wound outwards


@pytest.mark.parametrize("size", [1.0, 0.1])     # (S_u x S_v) . n above and below 1
def test_faces_point_along_shading_normals(variant, size):
    base = surfaces.Torus(1.0 * size, 0.3 * size)
    t = tessellate.displace_parametric(base, ripple, 0.02 * size, 0.0, 64, 32)
    m = trimesh.Trimesh(np.asarray(t.positions).T, np.asarray(t.faces).T, process=False)
    vn = np.asarray(t.normals).T[m.faces].mean(1)
    assert np.mean(np.sum(vn * m.face_normals, 1) > 0) > 0.999


@pytest.mark.parametrize("level", [1, 2, 5])
def test_subdivision_topology_shares_vertices(level):
    ico = trimesh.creation.icosphere(1)
    src, bary, group, faces = tessellate.subdivision_topology(
        ico.faces, np.arange(len(ico.vertices)), level)
    assert faces.shape == (len(ico.faces) * level**2, 3)
    # V' = V + E (level - 1) + F (level - 1)(level - 2) / 2 for a closed mesh
    n_edges = len(ico.edges_unique)
    expected = len(ico.vertices) + n_edges * (level - 1) + len(ico.faces) * (level - 1) * (level - 2) // 2
    assert len(src) == expected
    assert np.allclose(bary.sum(1), 1)
    pos = np.einsum("nk,nkd->nd", bary, ico.vertices[src])
    m = trimesh.Trimesh(pos, faces, process=False)
    assert m.is_watertight and m.euler_number == 2


def test_mesh_displacement_welds_uv_seams(variant):
    # A cube with every face its own UV chart: 24 vertices, seams everywhere.
    box = trimesh.creation.box()
    verts = box.vertices[box.faces].reshape(-1, 3)
    faces = np.arange(len(verts)).reshape(-1, 3)
    uvs = np.tile([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]], (len(box.faces), 1))
    uvs = uvs + 0.01 * np.repeat(np.arange(len(box.faces)), 3)[:, None]  # charts differ
    normals = verts / np.linalg.norm(verts, axis=1)[:, None]
    t0 = tessellate.displace_mesh(verts, normals, uvs, faces, None, 0.1, 0.0, 1)
    assert np.array_equal(np.asarray(t0.positions).T, verts.astype(np.float32))
    t = tessellate.displace_mesh(verts, normals, uvs, faces, ripple, 0.1, 0.0, 4)
    m = to_trimesh(t)
    assert m.is_watertight and m.euler_number == 2
    assert len(np.asarray(t.faces).T) == len(faces) * 16


def test_welded_normals_are_angle_weighted_and_face_the_vertex_normals():
    """A box split into 24 corners with per-face normals, its faces wound at random: every
    corner's direction is the diagonal (three right angles, whatever the triangulation: an
    area weight would tilt it), identical for the three copies; an unused vertex takes its
    own normal."""
    box = trimesh.creation.box()
    corners = box.vertices[box.faces].reshape(-1, 3)
    normals = np.repeat(box.face_normals, 3, 0)
    faces = np.arange(len(corners)).reshape(-1, 3)
    flip = np.random.default_rng(0).random(len(faces)) < 0.5
    faces[flip] = faces[flip][:, ::-1]
    pos = np.concatenate([corners, [[5.0, 5.0, 5.0]]])
    nrm = np.concatenate([normals, [[0.0, 1.0, 0.0]]])
    d = tessellate.welded_normals(pos, nrm, faces)
    assert d.dtype == np.float32 and d.shape == pos.shape and np.all(np.isfinite(d))
    assert np.allclose(d[:-1], np.sign(corners) / np.sqrt(3), atol=1e-6)
    assert np.array_equal(d[-1], [0, 1, 0])
    assert tessellate.split_positions(nrm, tessellate.weld_classes(pos)) == 8


def test_grid_resolution_validation():
    s = surfaces.Sphere(1.0)
    for bad in (0, -3, 2.5):
        with pytest.raises(ValueError, match=rf"^displaced: 'resolution' must be a positive "
                                             rf"integer, got {bad}$"):
            tessellate.grid_resolution(s, bad)
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError, match=rf"^displaced: 'edge_length' must be a positive "
                                             rf"number, got {bad}$"):
            tessellate.grid_resolution(s, edge_length=bad)
    with pytest.raises(ValueError, match=r"^displaced: a 200000 x 100000 grid \(20,000,300,001 "
                                         r"vertices\) exceeds the limit of [0-9,]+ vertices; "
                                         r"lower 'resolution' or raise 'edge_length'$"):
        tessellate.grid_resolution(s, 200_000)
    nu, nv = tessellate.grid_resolution(s, edge_length=0.1)
    assert nu == int(np.ceil(2 * np.pi / 0.1)) and nv == int(np.ceil(np.pi / 0.1))


def cylinder_mesh(n_around: int, n_along: int, radius: float = 1.0, length: float = 2.0):
    """Open triangulated cylinder with exact vertex normals and a UV seam (twin column at u=1)."""
    u, v = np.meshgrid(np.arange(n_around + 1) / n_around, np.arange(n_along + 1) / n_along)
    u, v = u.ravel(), v.ravel()
    phi = 2 * np.pi * u
    pos = np.stack([radius * np.cos(phi), radius * np.sin(phi), length * v], 1)
    nrm = np.stack([np.cos(phi), np.sin(phi), 0 * phi], 1)
    a = (np.arange(n_along)[:, None] * (n_around + 1) + np.arange(n_around)[None, :]).ravel()
    b, c, d = a + 1, a + n_around + 2, a + n_around + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return pos, nrm, np.stack([u, v], 1), faces


def wave(uv):
    """h = 0.5 + 0.5 sin(2 pi 3 u) sin(2 pi 2 v) (periodic in u) and its gradient."""
    a, b = dr.two_pi * 3 * uv.x, dr.two_pi * 2 * uv.y
    h = 0.5 + 0.5 * dr.sin(a) * dr.sin(b)
    return h, mi.Vector2f(0.5 * dr.two_pi * 3 * dr.cos(a) * dr.sin(b),
                          0.5 * dr.two_pi * 2 * dr.sin(a) * dr.cos(b))


def test_mesh_zero_height_shades_like_the_smooth_base(variant):
    """Zero height: every shading normal is the interpolated base normal (not a facet's)."""
    pos, nrm, uvs, faces = cylinder_mesh(12, 3)
    for t in (tessellate.displace_mesh(pos, nrm, uvs, faces, None, 0.1, 0.0, 5),
              tessellate.displace_mesh(pos, nrm, uvs, faces, wave, 0.0, 0.0, 5)):
        n = np.asarray(t.normals).T
        p = np.asarray(t.positions).T
        smooth = p[:, :2] / np.linalg.norm(p[:, :2], axis=1)[:, None]  # exact: radial, z = 0
        assert np.all(np.isfinite(n))
        assert np.allclose(n[:, 2], 0, atol=1e-6)
        assert np.allclose(n[:, :2], smooth, atol=1e-5)


def test_mesh_normals_converge_to_the_displaced_smooth_surface(variant):
    """Nonzero height on a coarse-to-fine cylinder mesh: the shading normals approach the normals
    of the exact displaced cylinder P = S + s (h - m) n (central differences), quadratically."""
    scale, mid, eps = 0.05, 0.5, 1e-3
    cyl = surfaces.Cylinder(1.0, 2.0)

    def exact_normals(uv):
        def P(a, b):
            s = cyl.sample(mi.Float(a), mi.Float(b))
            h, _ = wave(mi.Point2f(mi.Float(a), mi.Float(b)))
            return np.asarray(s.p + scale * (h - mid) * s.n).T.astype(np.float64)
        pu = (P(uv[:, 0] + eps, uv[:, 1]) - P(uv[:, 0] - eps, uv[:, 1])) / (2 * eps)
        pv = (P(uv[:, 0], uv[:, 1] + eps) - P(uv[:, 0], uv[:, 1] - eps)) / (2 * eps)
        n = np.cross(pu, pv)
        return n / np.linalg.norm(n, axis=1)[:, None]

    errors = []
    for n_around in (16, 32, 64):
        pos, nrm, uvs, faces = cylinder_mesh(n_around, n_around // 4)
        t = tessellate.displace_mesh(pos, nrm, uvs, faces, wave, scale, mid, 3)
        uv = np.asarray(t.texcoords).T.astype(np.float64)
        inner = (uv[:, 1] > 0.02) & (uv[:, 1] < 0.98)
        n = np.asarray(t.normals).T[inner]
        assert np.all(np.isfinite(n))
        cos = np.clip(np.sum(n * exact_normals(uv[inner]), 1), -1, 1)
        errors.append(np.degrees(np.arccos(cos)).max())
    # a facet of the 16-gon alone would be off by up to 11 degrees
    assert errors[0] < 0.5 and errors[-1] < 0.1, errors
    assert errors[1] < errors[0] / 1.5 and errors[2] < errors[1] / 1.5, errors


def test_mesh_crease_with_cancelling_vertex_normals_stays_finite(variant):
    """Two triangles whose shared edge carries opposite vertex normals (a shell's rim that
    shares the walls' vertices): the interpolated normal is zero at the edge's midpoint."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    nrm = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 1], [0, 0, -1]], float)
    uvs = pos[:, :2]
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    t = tessellate.displace_mesh(pos, nrm, uvs, faces, ripple, 0.05, 0.5, 4)
    assert np.all(np.isfinite(np.asarray(t.positions))) and np.all(np.isfinite(np.asarray(t.normals)))


# ---------------------------------------------------------------------------------------
# Mutants that survived the tests above (scripts/mutation.sh, docs/testing.md).


def test_grid_resolution_keeps_the_aspect_and_the_closed_minimums():
    """nv = ceil(nu extent_v / extent_u); at least 3 cells around a periodic direction and
    2 between poles (fewer cannot close the surface); the default is 64 cells along u."""
    sphere, torus, plane = surfaces.Sphere(1.0), surfaces.Torus(1.0, 0.3), surfaces.Plane()
    assert tessellate.grid_resolution(sphere, 24) == (24, 12)         # extents 2 pi : pi
    assert tessellate.grid_resolution(sphere) == (64, 32)
    assert tessellate.grid_resolution(torus, 26) == (26, 6)           # ceil(26 * 0.6 / 2.6)
    assert tessellate.grid_resolution(plane, 1) == (1, 1)
    assert tessellate.grid_resolution(sphere, 1) == (3, 2)
    assert tessellate.grid_resolution(torus, 1) == (3, 3)
    assert tessellate.grid_resolution(surfaces.Cylinder(1.0, 0.1), 1) == (3, 1)
    assert tessellate.grid_resolution(plane, edge_length=0.5) == (4, 4)
    assert tessellate.grid_resolution(plane, edge_length=0.3) == (7, 7)  # ceil(2 / 0.3)
    assert tessellate.grid_resolution(sphere, edge_length=100.0) == (3, 2)
    # the vertex limit bounds (nu + 1)(nv + 1): the largest square grid under it passes
    n = int(np.floor(np.sqrt(tessellate.MAX_VERTICES))) - 1
    assert tessellate.grid_resolution(plane, n) == (n, n)
    with pytest.raises(ValueError, match=f"limit of {tessellate.MAX_VERTICES:,} vertices"):
        tessellate.grid_resolution(plane, n + 1)
    assert isinstance(tessellate.MAX_VERTICES, int)  # a count, printed as one
    # a grid of exactly MAX_VERTICES (2^27 = 2^14 x 2^13 vertices) is allowed
    cyl = surfaces.Cylinder(1.0, 2 * np.pi * 8190.5 / 16383)
    assert tessellate.grid_resolution(cyl, 2**14 - 1) == (2**14 - 1, 2**13 - 1)


def test_sphere_poles_take_the_ring_mean_height_and_the_base_normal(variant):
    """h = 0.2 + 0.5 v + 0.3 cos(2 pi u): the ring mean is 0.2 at the north pole (v = 0,
    +z) and 0.7 at the south pole; each pole row collapses onto one displaced point."""
    def h(uv):
        c, s = dr.cos(dr.two_pi * uv.x), dr.sin(dr.two_pi * uv.x)
        return 0.2 + 0.5 * uv.y + 0.3 * c, mi.Vector2f(-0.3 * dr.two_pi * s, 0.5)
    r, scale, mid, nu, nv = 1.5, 0.4, 0.1, 12, 6
    t = tessellate.displace_parametric(surfaces.Sphere(r), h, scale, mid, nu, nv)
    assert t.vertex_count == (nu + 1) * (nv + 1) == dr.width(t.normals)
    assert t.face_count == 2 * nu * nv - 2 * nu == dr.width(t.faces)
    p, n = np.asarray(t.positions).T, np.asarray(t.normals).T
    north, south = slice(0, nu + 1), slice(nv * (nu + 1), None)
    assert np.allclose(p[north], [0, 0, r + scale * (0.2 - mid)], atol=1e-6)
    assert np.allclose(p[south], [0, 0, -(r + scale * (0.7 - mid))], atol=1e-6)
    assert np.allclose(n[north], [0, 0, 1], atol=1e-6)
    assert np.allclose(n[south], [0, 0, -1], atol=1e-6)
    disp = np.asarray(t.displacement)
    assert np.allclose(disp[north], scale * (0.2 - mid), atol=1e-6)
    assert np.allclose(disp[south], scale * (0.7 - mid), atol=1e-6)
    assert np.allclose(np.asarray(t.base_positions).T[north], [0, 0, r], atol=1e-6)


def test_face_weighted_normals_against_numpy():
    """Area-weighted vertex normals (sum of the faces' edge cross products over each
    position class), against a NumPy loop over faces; a vertex whose faces have no area
    keeps its fallback."""
    mi.set_variant("llvm_ad_rgb")
    rng = np.random.default_rng(3)
    box = trimesh.creation.box()
    pos = box.vertices[box.faces].reshape(-1, 3) + 0.05 * rng.normal(size=(36, 3))
    faces = np.arange(36).reshape(-1, 3)
    groups = trimesh.grouping.group_rows(np.round(box.vertices[box.faces].reshape(-1, 3), 6),
                                         require_count=None)
    cls = np.zeros(36, np.int64)
    for k, g in enumerate(groups):
        cls[g] = k
    # one extra degenerate triangle on its own class
    pos = np.vstack([pos, [[2, 2, 2]] * 3])
    faces = np.vstack([faces, [[36, 37, 38]]])
    cls = np.concatenate([cls, [len(groups)] * 3])
    expected = np.zeros((len(groups) + 1, 3))
    for f in faces:
        fn = np.cross(pos[f[1]] - pos[f[0]], pos[f[2]] - pos[f[0]])
        for v in f:
            expected[cls[v]] += fn
    expected = expected[cls]
    norm = np.linalg.norm(expected, axis=1, keepdims=True)
    fallback = np.tile([0.0, 0.6, 0.8], (len(pos), 1))
    expected = np.where(norm > 0, expected / np.where(norm > 0, norm, 1), fallback)
    vec = lambda a, t: t(*(mi.Float(c) for c in a.T.astype(np.float32)))
    got = tessellate.face_weighted_normals(
        vec(pos, mi.Point3f), mi.Vector3u(*(mi.UInt32(c.astype(np.uint32)) for c in faces.T)),
        mi.UInt32(cls.astype(np.uint32)), len(groups) + 1, vec(fallback, mi.Vector3f))
    assert np.allclose(np.asarray(got).T, expected, atol=1e-5)


def test_vertex_frames_are_exact_for_linear_fields():
    """Positions, normals and UVs all affine on a jittered planar triangulation: every
    triangle has the same Jacobians, so each vertex gets them exactly, S_u = first column of
    (d uv / d xy)^-1 and n_u its image under the normal field's matrix, projected onto the
    tangent plane of the unit normal.  A triangle with a degenerate UV map adds nothing."""
    rng = np.random.default_rng(1)
    g = np.linspace(0, 1, 6)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    x, y = x + 0.03 * rng.normal(size=x.size), y + 0.03 * rng.normal(size=y.size)
    faces = Delaunay(np.stack([x, y], 1)).simplices
    pos = np.stack([x, 0.5 * x + y, 0.2 * x - 0.3 * y], 1)            # an affine sheet
    A = np.array([[0.8, 0.3], [-0.2, 1.1]])                           # uv = A (x, y) + b
    uvs = np.stack([x, y], 1) @ A.T + [0.1, -0.2]
    M = np.array([[0.4, -0.1], [0.2, 0.3], [0.05, -0.15]])            # m = M (x, y) + c
    nrm = np.stack([x, y], 1) @ M.T + [0.1, 0.2, 1.0]
    # a triangle of real area whose UVs are collinear (vertex 36 off the sheet, its uv
    # midway between those of vertices 0 and 1): it must not dilute their average
    pos = np.vstack([pos, [[0.3, 0.2, 1.0]]])
    nrm = np.vstack([nrm, [[0, 0, 1]]])
    uvs = np.vstack([uvs, [0.5 * (uvs[0] + uvs[1])]])
    faces = np.vstack([faces, [[0, 1, 36]]])
    s_u, s_v, n_u, n_v = tessellate.vertex_frames(pos, nrm, uvs, faces)
    Ainv = np.linalg.inv(A)                                           # d xy / d uv
    dP = np.array([[1, 0], [0.5, 1], [0.2, -0.3]]) @ Ainv             # columns: S_u, S_v
    dm = M @ Ainv
    unit = nrm[:36] / np.linalg.norm(nrm[:36], axis=1, keepdims=True)
    for got, col in ((s_u, dP[:, 0]), (s_v, dP[:, 1])):
        assert np.allclose(got[:36], col, atol=1e-5)
    for got, col in ((n_u, dm[:, 0]), (n_v, dm[:, 1])):
        expect = col - np.sum(col * unit, 1, keepdims=True) * unit
        assert np.allclose(got[:36], expect, atol=1e-5)
    for a in (s_u, s_v, n_u, n_v):                # vertex 36 has no valid triangle
        assert np.all(a[36] == 0)


def test_smooth_displaced_normals_fall_back_to_n_on_a_degenerate_frame(variant):
    # s_u parallel to s_v (a collapsed UV chart): the frame has no orientation, so the normal
    # must be n, not the cross product of the height terms (dr.sign(0) is 1, which hid this).
    n = mi.Vector3f(0, 0, 1)
    s = mi.Vector3f(1, 0, 0)
    zero = mi.Vector3f(0, 0, 0)
    normal = tessellate.smooth_displaced_normals(n, s, 2 * s, zero, zero, mi.Float(0.1),
                                                 mi.Vector2f(0.0, 0.7), 1.0)
    assert np.allclose(np.array(normal).ravel(), [0, 0, 1])
    # A proper frame still tilts the normal against the slope (the check above can fail).
    tilted = tessellate.smooth_displaced_normals(n, s, mi.Vector3f(0, 1, 0), zero, zero, mi.Float(0.1),
                                                 mi.Vector2f(0.0, 0.7), 1.0)
    assert np.allclose(np.array(tilted).ravel(), np.array([0, -0.7, 1]) / np.hypot(0.7, 1), atol=1e-6)


def test_group_mean_of_scalars_and_vectors(variant):
    groups = mi.UInt32([0, 1, 0, 2, 1, 0])
    x = mi.Float([1.0, 2.0, 3.0, 10.0, 6.0, 8.0])
    assert np.allclose(np.asarray(tessellate.group_mean(x, groups, 3)), [4, 4, 4, 10, 4, 4])
    v = mi.Vector3f(x, 2 * x, dr.zeros(mi.Float, 6) - 1)
    mean = np.asarray(tessellate.group_mean(v, groups, 3)).T
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
    n = np.asarray(t.base_normals).T
    assert np.allclose(n, [0, -1, 0], atol=1e-6)      # (0.5, 0, 0) x (0, 0, 0.5) / 0.25
