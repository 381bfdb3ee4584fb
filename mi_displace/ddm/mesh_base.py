"""Polygonal base surfaces for DDM (HDDM §4.1): a triangle mesh with a one-to-one UV layout.

The mesh is laid flat in its UV layout as a second ``mi.Mesh`` (x, y = u, v; z = 0) and
located by one ray per query point along -z: the hit gives the triangle and its
barycentrics for any number of points at once (Mitsuba as a rasteriser in UV space).
:class:`MeshBase` then behaves like the analytic bases of :mod:`mi_displace.core.surfaces`:
``sample(u, v)`` gives the piecewise-linear position S, the interpolated unit normal n and
their exact per-triangle derivatives, so ``exact`` mode and ``jacobian`` normals work on it.

Points outside the layout (invalid) are clamped to the nearest valid location, as the
paper does: the nearest covered texel of a ``clamp_resolution``² validity map, found by the
§4.1 diffusion (:func:`mi_displace.ddm.base_maps.diffuse_fill`).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.surfaces import BaseSurface, SurfaceSample
from mi_displace.core.tessellate import gather


def _per_triangle_gradient(values: np.ndarray, uvs: np.ndarray, faces: np.ndarray):
    """d(value)/du and d(value)/dv of the linear interpolant on each triangle, (F, C) each.

    Triangles with a degenerate UV image get zero gradients.
    """
    f = faces.astype(np.int64)
    d1, d2 = values[f[:, 1]] - values[f[:, 0]], values[f[:, 2]] - values[f[:, 0]]
    e1, e2 = uvs[f[:, 1]] - uvs[f[:, 0]], uvs[f[:, 2]] - uvs[f[:, 0]]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    # [d1 d2] = [g_u g_v] [e1 e2]  =>  [g_u g_v] = [d1 d2] [e1 e2]^-1
    g_u = (d1 * e2[:, 1:2] - d2 * e1[:, 1:2]) * inv
    g_v = (d2 * e1[:, 0:1] - d1 * e2[:, 0:1]) * inv
    return g_u.astype(np.float32), g_v.astype(np.float32)


def _vec(a: np.ndarray):
    return mi.Vector3f(*(mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)))


class MeshBase(BaseSurface):
    """A triangle mesh with UVs as a DDM base (object units; uv in [0, 1]^2).

    Args:
        positions, normals: (V, 3) float; uvs: (V, 2) float; faces: (F, 3) int.
        clamp_resolution: texels per side of the validity map used to clamp queries that
            fall outside the UV layout to the nearest valid location.
    """

    name = "mesh"

    def __init__(self, positions, normals, uvs, faces, clamp_resolution: int = 512):
        pos = np.asarray(positions, np.float64)
        nrm = np.asarray(normals, np.float64)
        uv = np.asarray(uvs, np.float64)
        f = np.asarray(faces, np.int64)
        self.faces_np, self.uvs_np, self.positions_np = f, uv, pos
        self.face_count = len(f)
        layout = mi.Mesh("ddm_uv_layout", len(uv), len(f), mi.Properties(), False, False)
        params = mi.traverse(layout)
        params["vertex_positions"] = dr.ravel(mi.Point3f(
            mi.Float(uv[:, 0].astype(np.float32)), mi.Float(uv[:, 1].astype(np.float32)), 0))
        params["faces"] = mi.UInt32(f.astype(np.uint32).ravel())
        params.update()
        self._scene = mi.load_dict({"type": "scene", "layout": layout})
        self._faces = mi.Vector3u(*(mi.UInt32(f[:, k].astype(np.uint32)) for k in range(3)))
        self._p, self._n = _vec(pos), _vec(nrm)
        pu, pv = _per_triangle_gradient(pos, uv, f)
        nu, nv = _per_triangle_gradient(nrm, uv, f)
        self._dp = (_vec(pu), _vec(pv))
        self._dn = (_vec(nu), _vec(nv))
        # curvature bound: normal turn per unit length over every edge
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        length = np.linalg.norm(pos[e[:, 0]] - pos[e[:, 1]], axis=1)
        turn = np.linalg.norm(nrm[e[:, 0]] - nrm[e[:, 1]], axis=1)
        self.edge_kappa = turn[length > 0] / length[length > 0]   # [1 / object units]
        self._kappa = float(np.max(self.edge_kappa))
        ext = pos.max(0) - pos.min(0)
        self._extent = (float(np.linalg.norm(ext)), float(np.linalg.norm(ext)))
        self.clamp_resolution = int(clamp_resolution)
        self._clamp_uv = None

    def locate(self, u: mi.Float, v: mi.Float):
        """Triangle and barycentrics under each (u, v): ``(valid, prim, b1, b2)``."""
        n = dr.width(u)
        ray = mi.Ray3f(mi.Point3f(u, v, 1.0), dr.zeros(mi.Vector3f, n) + mi.Vector3f(0, 0, -1))
        pi = self._scene.ray_intersect_preliminary(ray, coherent=False)
        # every field in one kernel: evaluated one by one, each would trace the rays again
        dr.eval(pi.valid, pi.prim_index, pi.prim_uv)
        valid = pi.is_valid()
        prim = dr.select(valid, pi.prim_index, 0)
        return valid, prim, pi.prim_uv.x, pi.prim_uv.y

    def interpolate(self, prim, b1, b2):
        """Position and (unnormalised) interpolated normal at barycentrics on ``prim``."""
        i0, i1, i2 = (dr.gather(mi.UInt32, self._faces[k], prim) for k in range(3))
        b0 = 1 - b1 - b2
        p = gather(mi.Vector3f, self._p, i0) * b0 + gather(mi.Vector3f, self._p, i1) * b1 \
            + gather(mi.Vector3f, self._p, i2) * b2
        nn = gather(mi.Vector3f, self._n, i0) * b0 + gather(mi.Vector3f, self._n, i1) * b1 \
            + gather(mi.Vector3f, self._n, i2) * b2
        return p, nn

    def clamp_map(self):
        """(R, R, 2) float32 uv of the nearest valid sample for every texel of the clamp map."""
        if self._clamp_uv is None:
            from mi_displace.ddm.base_maps import diffuse_fill, texel_coordinates

            r = self.clamp_resolution
            u, v = texel_coordinates(r, r, False, False)
            valid, _, _, _ = self.locate(u, v)
            ok = np.asarray(valid).reshape(r, r)
            if not ok.any():
                raise ValueError("ddm: the base mesh's UV layout covers no part of [0, 1]^2")
            src, _ = diffuse_fill(ok, False, False)
            uu, vv = np.asarray(u).reshape(r, r), np.asarray(v).reshape(r, r)
            self._clamp_uv = (mi.Float(uu.ravel()[src.ravel()]), mi.Float(vv.ravel()[src.ravel()]))
        return self._clamp_uv

    def sample(self, u, v):
        u, v = mi.Float(u), mi.Float(v)
        valid, prim, b1, b2 = self.locate(u, v)
        if not dr.all(valid):  # clamp to the nearest valid location (§4.1)
            cu, cv = self.clamp_map()
            r = self.clamp_resolution
            iu = mi.UInt32(dr.clip(dr.round(u * (r - 1)), 0, r - 1))
            iv = mi.UInt32(dr.clip(dr.round(v * (r - 1)), 0, r - 1))
            k = iv * r + iu
            u = dr.select(valid, u, dr.gather(mi.Float, cu, k))
            v = dr.select(valid, v, dr.gather(mi.Float, cv, k))
            valid2, prim2, c1, c2 = self.locate(u, v)
            prim = dr.select(valid, prim, prim2)
            b1, b2 = dr.select(valid, b1, c1), dr.select(valid, b2, c2)
        return self._sample_at(prim, b1, b2)

    def _sample_at(self, prim, b1, b2) -> SurfaceSample:
        p, nn = self.interpolate(prim, b1, b2)
        length = dr.maximum(dr.norm(nn), 1e-20)
        n = nn / length
        dn_u, dn_v = (gather(mi.Vector3f, d, prim) for d in self._dn)
        n_u = (dn_u - n * dr.dot(n, dn_u)) / length
        n_v = (dn_v - n * dr.dot(n, dn_v)) / length
        return SurfaceSample(p=mi.Point3f(p), dp_du=gather(mi.Vector3f, self._dp[0], prim),
                             dp_dv=gather(mi.Vector3f, self._dp[1], prim), n=n,
                             dn_du=n_u, dn_dv=n_v)

    def extent(self):
        return self._extent

    def curvature_bounds(self):
        return -self._kappa, self._kappa
