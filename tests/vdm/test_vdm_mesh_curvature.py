"""Per-vertex curvature tensors on meshes against analytic principal curvatures."""
import math

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core import surfaces, tessellate
from mi_displace.vdm import mesh_curvature as mc


def _grid(base, nu, nv):
    t = tessellate.displace_parametric(base, None, 0.0, 0.0, nu, nv)
    from mi_displace.plugins.vdm_mesh import _columns

    return tuple(_columns(v) for v in (t.positions, t.normals, t.texcoords, t.faces))


def test_torus_principal_curvatures(variant):
    base = surfaces.make_base("torus", major_radius=1.0, minor_radius=0.4)
    pos, nrm, uv, faces = _grid(base, 96, 40)
    K, cmax, cmin = mc.curvature_tensors(pos, nrm, faces)
    s = base.sample(mi.Float(uv[:, 0]), mi.Float(uv[:, 1]))
    kmax, kmin, dmax, _ = surfaces.principal_curvatures(s)
    np.testing.assert_allclose(cmax, np.asarray(kmax), atol=0.03)
    np.testing.assert_allclose(cmin, np.asarray(kmin), atol=0.03)
    # the tensor gives the normal curvature along the analytic principal direction
    d = np.stack([np.asarray(c) for c in dmax], 1)
    along = np.einsum("vi,vij,vj->v", d, K, d)
    np.testing.assert_allclose(along, np.asarray(kmax), atol=0.03)


def test_sphere_and_plane(variant):
    pos, nrm, uv, faces = _grid(surfaces.make_base("sphere", radius=2.0), 64, 32)
    _, cmax, cmin = mc.curvature_tensors(pos, nrm, faces)
    inner = (uv[:, 1] > 0.1) & (uv[:, 1] < 0.9)
    np.testing.assert_allclose(cmax[inner], 0.5, atol=0.01)
    np.testing.assert_allclose(cmin[inner], 0.5, atol=0.01)
    pos, nrm, uv, faces = _grid(surfaces.make_base("plane"), 8, 8)
    K, cmax, cmin = mc.curvature_tensors(pos, nrm, faces)
    assert np.all(K == 0) and np.all(cmax == 0)
    tile, spread = mc.tile_scale(pos, uv, faces, (4.0, 4.0))
    np.testing.assert_allclose(tile, 0.5, rtol=1e-6)      # a 2 x 2 plane, 4 x 4 tiles
    assert spread < 1e-6


# --- mutants that survived the tests above (scripts/mutation.sh, docs/testing.md) ---------

def _affine_sheet(n=5):
    """A sheared, rotated planar grid p = p0 + A (u, v): constant uv Jacobian A (3, 2)."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="xy")
    uv = np.stack([u.ravel(), v.ravel()], 1)
    A = np.array([[2.0, 0.5], [0.3, 1.5], [1.0, -0.7]])
    pos = uv @ A.T + [0.2, -1.0, 3.0]
    i = np.arange(n - 1)
    a = (i[None, :] + n * i[:, None]).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return pos, uv, faces, A


def test_tile_forms_on_an_affine_sheet():
    pos, uv, faces, A = _affine_sheet()
    rng = np.random.default_rng(0)
    S = rng.normal(size=(3, 3))
    K = np.broadcast_to(S + S.T, (len(pos), 3, 3))          # any symmetric tensor
    tiling, tile = (2.0, 4.0), 0.7
    forms = mc.tile_forms(pos, uv, faces, K, tiling, tile)
    J = A / np.array(tiling)[None, :]                        # world per tile unit
    II = J.T @ K[0] @ J * tile
    np.testing.assert_allclose(forms["q"], np.broadcast_to([II[0, 0], II[0, 1], II[1, 1]],
                                                           (len(faces), 3)), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(forms["q_du"], 0, atol=1e-5)
    np.testing.assert_allclose(forms["q_dv"], 0, atol=1e-5)
    np.testing.assert_allclose(forms["uv"][:, :2], uv[faces].mean(1), atol=1e-7)
    np.testing.assert_allclose(forms["uv"][:, 2], np.linalg.norm(np.cross(A[:, 0], A[:, 1])),
                               rtol=1e-6)
    assert all(v.dtype == np.float32 and v.shape == (len(faces), 3) for v in forms.values())


def test_tile_forms_interpolate_the_vertex_values_linearly():
    pos, uv, faces, A = _affine_sheet()
    # K varying from vertex to vertex: Q(uv) on each face is the linear interpolant of its
    # corners' Q = J^T K J tile_size
    rng = np.random.default_rng(1)
    S = rng.normal(size=(len(pos), 3, 3))
    K = S + np.transpose(S, (0, 2, 1))
    tiling, tile = (1.0, 3.0), 2.0
    forms = mc.tile_forms(pos, uv, faces, K, tiling, tile)
    J = A / np.array(tiling)[None, :]
    II = np.einsum("ai,vab,bj->vij", J, K, J) * tile
    Q = np.stack([II[:, 0, 0], II[:, 0, 1], II[:, 1, 1]], 1)
    for k in range(3):
        d = uv[faces[:, k]] - forms["uv"][:, :2]
        at_corner = forms["q"] + forms["q_du"] * d[:, :1] + forms["q_dv"] * d[:, 1:]
        np.testing.assert_allclose(at_corner, Q[faces[:, k]], rtol=1e-4, atol=1e-4)


def test_tile_forms_skip_faces_without_uv_area():
    pos, uv, faces, A = _affine_sheet(3)
    K = np.broadcast_to(np.diag([1.0, 2.0, 0.0]), (len(pos), 3, 3))
    # an extra vertex and a face whose uvs are collinear (no uv area): it gets no weight,
    # so every vertex keeps the sheet's Jacobian
    pos2 = np.vstack([pos, pos[-1] + [0.0, 0.0, 5.0]])
    uv2 = np.vstack([uv, [[0.5, 0.5]]])
    K2 = np.concatenate([K, K[:1]])
    faces2 = np.vstack([faces, [[0, 4, len(pos)]]])          # uv (0,0), (0.5,0.5), (0.5,0.5)
    forms = mc.tile_forms(pos2, uv2, faces2, K2, (1.0, 1.0), 1.0)
    ref = mc.tile_forms(pos, uv, faces, K, (1.0, 1.0), 1.0)
    np.testing.assert_allclose(forms["q"][:len(faces)], ref["q"], rtol=1e-6)
    np.testing.assert_array_equal(forms["q_du"][-1], 0)
    np.testing.assert_array_equal(forms["uv"][-1, 2], 0)


def test_tile_scale_is_the_area_weighted_mean_and_spread():
    # two separate triangles: world area 1 on tile area 1 (s = 1), world area 3 on 3/4 (s = 2)
    pos = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 1], [3, 0, 1], [0, 2, 1]], float)
    uv = np.array([[0, 0], [2, 0], [0, 1], [0, 0], [1.5, 0], [0, 1]], float) / 2   # tiles: x 2
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    tile, spread = mc.tile_scale(pos, uv, faces, (2.0, 2.0))
    mean = 0.25 * 1 + 0.75 * 2
    np.testing.assert_allclose(tile, mean, rtol=1e-12)
    np.testing.assert_allclose(spread, math.sqrt(0.25 * (1 - mean) ** 2 + 0.75 * (2 - mean) ** 2) / mean,
                               rtol=1e-12)
    # tiling scales tile units: twice the periods, half the tile size
    np.testing.assert_allclose(mc.tile_scale(pos, uv, faces, (4.0, 4.0))[0], mean / 2, rtol=1e-12)
    np.testing.assert_allclose(mc.tile_scale(pos, uv, faces, (4.0, 2.0))[0], mean / math.sqrt(2),
                               rtol=1e-12)
    with pytest.raises(ValueError, match="^vdm: the mesh's UVs have no area; cannot derive the "
                                         "tile size$"):
        mc.tile_scale(pos, np.zeros_like(uv), faces, (1.0, 1.0))


def test_is_curved():
    pos, uv, faces, A = _affine_sheet()
    assert not mc.is_curved(pos, faces)                      # planar, any orientation
    assert not mc.is_curved(pos, faces[::-1, ::-1])          # flipped normals: still +-n
    assert not mc.is_curved(pos, faces[:1])                  # one face
    fold = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    assert mc.is_curved(fold, np.array([[0, 1, 2], [0, 3, 1]]))   # two faces at 90 deg
    bent = pos + np.array([0.0, 0.0, 1.0]) * (uv[:, :1] ** 2)
    assert mc.is_curved(bent, faces)
    # the tolerance bounds the second eigenvalue of the normals' scatter matrix
    fn = np.cross(bent[faces[:, 1]] - bent[faces[:, 0]], bent[faces[:, 2]] - bent[faces[:, 0]])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    second = np.linalg.eigvalsh(fn.T @ fn / len(fn))[1]
    assert mc.is_curved(bent, faces, 0.9 * second) and not mc.is_curved(bent, faces, 1.1 * second)


def test_per_corner_normals_are_welded():
    """Splitting every vertex per face (flat-shaded files) gives the shared-vertex tensors."""
    base = surfaces.make_base("torus", major_radius=1.0, minor_radius=0.4)
    pos, nrm, uv, faces = _grid(base, 24, 12)
    K, cmax, cmin = mc.curvature_tensors(pos, nrm, faces)
    split = faces.ravel()
    rng = np.random.default_rng(2)
    tilted = nrm[split] + 0.05 * rng.normal(size=(len(split), 3))   # corners disagree
    Ks, cmax_s, cmin_s = mc.curvature_tensors(pos[split], tilted, np.arange(len(split)).reshape(-1, 3))
    # the welded normal is the mean of the corners' at one position (seam twins included):
    # compare with that normal given to the shared-vertex mesh
    _, where = np.unique(pos.astype(np.float32), axis=0, return_inverse=True)
    where = where.ravel()
    acc = np.zeros((where.max() + 1, 3))
    np.add.at(acc, where[split], tilted / np.linalg.norm(tilted, axis=1, keepdims=True))
    welded = acc[where] / np.linalg.norm(acc[where], axis=1, keepdims=True)
    Kw, cmax_w, cmin_w = mc.curvature_tensors(pos, welded, faces)
    np.testing.assert_allclose(cmax_s, cmax_w[split], atol=1e-9)
    np.testing.assert_allclose(cmin_s, cmin_w[split], atol=1e-9)
    np.testing.assert_allclose(Ks, Kw[split], atol=1e-9)


def test_cylinder_with_helical_edges():
    """Edges at 45 deg to the principal directions (every face's shape operator has an
    off-diagonal term): along the axis c = 0, around it c = 1/r."""
    r, n = 0.5, 17
    s, t = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="xy")
    phi, z = 0.8 * (s + t).ravel(), 0.8 * (s - t).ravel()
    pos = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    nrm = np.stack([np.cos(phi), np.sin(phi), 0 * phi], 1)
    i = np.arange(n - 1)
    a = (i[None, :] + n * i[:, None]).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    K, cmax, cmin = mc.curvature_tensors(pos, nrm, faces)
    inner = ((s > 0) & (s < 1) & (t > 0) & (t < 1)).ravel()
    axis = np.array([0.0, 0.0, 1.0])
    around = np.stack([-np.sin(phi), np.cos(phi), 0 * phi], 1)
    np.testing.assert_allclose(np.einsum("i,vij,j->v", axis, K, axis)[inner], 0, atol=0.02 / r)
    np.testing.assert_allclose(np.einsum("vi,vij,vj->v", around, K, around)[inner], 1 / r,
                               rtol=0.02)
    np.testing.assert_allclose(cmax[inner], 1 / r, rtol=0.02)
    np.testing.assert_allclose(cmin[inner], 0, atol=0.02 / r)
