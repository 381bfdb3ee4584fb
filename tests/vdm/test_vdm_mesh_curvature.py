"""Per-vertex curvature tensors on meshes against analytic principal curvatures."""
import mitsuba as mi
import numpy as np

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
