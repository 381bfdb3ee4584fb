"""Polygonal base surfaces for DDM (HDDM §4.1): a triangle mesh with a one-to-one UV layout.

The mesh is laid flat in its UV layout as a second ``mi.Mesh`` (x, y = u, v; z = 0) and
located by one ray per query point along -z: the hit gives the triangle and its
barycentrics for any number of points at once (Mitsuba as a rasteriser in UV space).
:class:`MeshBase` then behaves like the analytic bases of :mod:`mi_displace.core.surfaces`:
``sample(u, v)`` gives the piecewise-linear position S, the interpolated unit normal n and
their exact per-triangle derivatives, so ``exact`` mode and ``jacobian`` normals work on it.

UV charts: the layout mesh lies at height z = chart index (charts are the connected pieces
of the welded UV layout, :func:`mi_displace.ddm.charts.uv_charts`), so a ray segment of
length 1 from z = c + 1/2 finds a point *in chart c only* (:meth:`MeshBase.locate` with
``chart``).

Points outside the layout (invalid) are clamped to the nearest valid location, as the
paper does (§4.1), but exactly: the closest point of the layout's boundary edges in UV
(a Dr.Jit loop over the edges of the point's chart, :meth:`MeshBase.clamp`), whose
triangle and barycentrics follow from the edge.  :meth:`MeshBase.sample_chart` clamps
to the point's own chart, so a tile's vertices never jump to a neighbouring chart.
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
    """

    name = "mesh"

    def __init__(self, positions, normals, uvs, faces):
        pos = np.asarray(positions, np.float64)
        nrm = np.asarray(normals, np.float64)
        uv = np.asarray(uvs, np.float64)
        f = np.asarray(faces, np.int64)
        self.faces_np, self.uvs_np, self.positions_np = f, uv, pos
        self.face_count = len(f)
        from mi_displace.ddm.charts import chart_boundaries, uv_charts

        self.face_chart, self.chart_count, welded = uv_charts(pos, uv, f)
        # boundary edges of every chart, grouped by chart: face, its two corners (0..2)
        face, c0, c1, first = chart_boundaries(welded, self.face_chart, self.chart_count)
        self._edge_first = mi.UInt32(first.astype(np.uint32))   # (C + 1,) range per chart
        self._edge_face = mi.UInt32(face.astype(np.uint32))
        self._edge_corners = (mi.UInt32(c0.astype(np.uint32)), mi.UInt32(c1.astype(np.uint32)))
        ends = [uv[f[face, c]] for c in (c0, c1)]
        self._edge_uv = tuple(mi.Point2f(mi.Float(e[:, 0].astype(np.float32)),
                                         mi.Float(e[:, 1].astype(np.float32))) for e in ends)
        self.boundary_edges = len(face)
        vertex_chart = np.zeros(len(uv), np.int64)
        vertex_chart[f.ravel()] = np.repeat(self.face_chart, 3)
        #: (C, 4) u_min, v_min, u_max, v_max of each chart's UV image
        self.chart_bounds = np.array([[*uv[f[self.face_chart == c]].reshape(-1, 2).min(0),
                                       *uv[f[self.face_chart == c]].reshape(-1, 2).max(0)]
                                      for c in range(self.chart_count)])
        layout = mi.Mesh("ddm_uv_layout", len(uv), len(f), mi.Properties(), False, False)
        params = mi.traverse(layout)
        params["vertex_positions"] = dr.ravel(mi.Point3f(
            mi.Float(uv[:, 0].astype(np.float32)), mi.Float(uv[:, 1].astype(np.float32)),
            mi.Float(vertex_chart.astype(np.float32))))
        params["faces"] = mi.UInt32(f.astype(np.uint32).ravel())
        params.update()
        self._scene = mi.load_dict({"type": "scene", "layout": layout})
        self._faces = mi.Vector3u(*(mi.UInt32(f[:, k].astype(np.uint32)) for k in range(3)))
        self._uv = mi.Point2f(mi.Float(uv[:, 0].astype(np.float32)), mi.Float(uv[:, 1].astype(np.float32)))
        self._p, self._n = _vec(pos), _vec(nrm)
        pu, pv = _per_triangle_gradient(pos, uv, f)
        nu, nv = _per_triangle_gradient(nrm, uv, f)
        self._dp = (_vec(pu), _vec(pv))
        self.gradients_np = (pu.astype(np.float64), pv.astype(np.float64))  # (F, 3) S_u, S_v
        self._dn = (_vec(nu), _vec(nv))
        # curvature bound: normal turn per unit length over every edge
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        length = np.linalg.norm(pos[e[:, 0]] - pos[e[:, 1]], axis=1)
        turn = np.linalg.norm(nrm[e[:, 0]] - nrm[e[:, 1]], axis=1)
        self.edge_kappa = turn[length > 0] / length[length > 0]   # [1 / object units]
        self._kappa = float(np.max(self.edge_kappa))
        ext = pos.max(0) - pos.min(0)
        self._extent = (float(np.linalg.norm(ext)), float(np.linalg.norm(ext)))

    def locate(self, u: mi.Float, v: mi.Float, chart: mi.UInt32 | None = None):
        """Triangle and barycentrics under each (u, v): ``(valid, prim, b1, b2)``; with
        ``chart`` (per point) only that chart's triangles count."""
        n = dr.width(u)
        top = self.chart_count + 0.5 if chart is None else mi.Float(chart) + 0.5
        ray = mi.Ray3f(mi.Point3f(u, v, top), dr.zeros(mi.Vector3f, n) + mi.Vector3f(0, 0, -1))
        if chart is not None:
            ray.maxt = 1.0          # the slab of chart c only: z in [c - 1/2, c + 1/2]
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

    def clamp(self, u, v, chart: mi.UInt32 | None = None):
        """The closest point of the UV layout's boundary (of ``chart``'s boundary per point,
        or of every chart) to each (u, v): ``(prim, b1, b2)`` on the edge's triangle.

        A Dr.Jit loop over the boundary edges of the point's chart (§4.1: clamp "toward the
        nearest valid location", exactly rather than by diffusion on a grid).
        """
        n = dr.width(u)
        lo = dr.zeros(mi.UInt32, n) if chart is None else dr.gather(mi.UInt32, self._edge_first, chart)
        hi = (dr.zeros(mi.UInt32, n) + self.boundary_edges if chart is None
              else dr.gather(mi.UInt32, self._edge_first, chart + 1))
        p = mi.Point2f(dr.detach(u), dr.detach(v))      # the search itself: no gradient
        best_d = dr.full(mi.Float, dr.inf, n)
        best_e, best_t = dr.zeros(mi.UInt32, n), dr.zeros(mi.Float, n)

        def body(i, best_d, best_e, best_t):
            a, b = (dr.gather(mi.Point2f, e, i) for e in self._edge_uv)
            ab = b - a
            t = dr.clip(dr.dot(p - a, ab) / dr.maximum(dr.squared_norm(ab), 1e-30), 0.0, 1.0)
            d = dr.squared_norm(a + ab * t - p)
            closer = d < best_d
            return (i + 1, dr.select(closer, d, best_d), dr.select(closer, i, best_e),
                    dr.select(closer, t, best_t))

        _, _, best_e, best_t = dr.while_loop((lo, best_d, best_e, best_t),
                                             lambda i, *_: i < hi, body)
        if dr.grad_enabled(u) or dr.grad_enabled(v):   # the edge's parameter, differentiable
            a, b = (dr.gather(mi.Point2f, e, best_e) for e in self._edge_uv)
            ab = b - a
            best_t = dr.clip(dr.dot(mi.Point2f(u, v) - a, ab) / dr.maximum(dr.squared_norm(ab), 1e-30),
                             0.0, 1.0)
        prim = dr.gather(mi.UInt32, self._edge_face, best_e)
        c0, c1 = (dr.gather(mi.UInt32, c, best_e) for c in self._edge_corners)

        def weight(k):
            return dr.select(c0 == k, 1 - best_t, 0.0) + dr.select(c1 == k, best_t, 0.0)

        return prim, weight(1), weight(2)

    def sample(self, u, v):
        return self.sample_chart(u, v, None)

    def sample_chart(self, u, v, chart: mi.UInt32 | None) -> SurfaceSample:
        """S, n and derivatives at (u, v) in UV chart ``chart`` (mi.UInt32 per point; None:
        any chart): points outside it are clamped to the chart's nearest boundary point
        (:meth:`clamp`), never to another chart."""
        u, v = mi.Float(u), mi.Float(v)
        differentiable = dr.grad_enabled(u) or dr.grad_enabled(v)
        valid, prim, b1, b2 = self.locate(dr.detach(u), dr.detach(v), chart)
        if differentiable:       # the ray's barycentrics carry no gradient: redo them in uv
            b1, b2 = self._barycentrics(prim, u, v)
        if not dr.all(valid):
            prim2, c1, c2 = self.clamp(u, v, chart)
            prim = dr.select(valid, prim, prim2)
            b1, b2 = dr.select(valid, b1, c1), dr.select(valid, b2, c2)
        return self._sample_at(prim, b1, b2)

    def _barycentrics(self, prim, u, v):
        """Barycentrics (b1, b2) of (u, v) in triangle ``prim``'s UV image (differentiable)."""
        a, b, c = (gather(mi.Point2f, self._uv, dr.gather(mi.UInt32, self._faces[k], prim))
                   for k in range(3))
        e1, e2, d = b - a, c - a, mi.Point2f(u, v) - a
        det = e1.x * e2.y - e1.y * e2.x
        inv = dr.select(dr.abs(det) > 1e-20, 1 / det, 0.0)
        return (d.x * e2.y - d.y * e2.x) * inv, (e1.x * d.y - e1.y * d.x) * inv

    def fold_samples(self) -> SurfaceSample:
        """S, n and derivatives at every face centroid (the folding check of the model)."""
        third = dr.full(mi.Float, 1 / 3, self.face_count)
        return self._sample_at(dr.arange(mi.UInt32, self.face_count), third, third)

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
