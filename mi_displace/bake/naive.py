"""The naive per-texel baker (§2's ray-casting utilities), as a same-process baseline.

The same algorithm as :mod:`baker` on the same rays — texel centres (or aa x aa sub-samples)
rasterised by casting vertical rays at the stacked UV layout, then two distance rays along
+-n from the interpolated low-poly point with the same hit rule — but traced with trimesh's
Embree binding (``embreex``), one NumPy batch per stage.  It bakes the displacement map only
(the part every format needs) and serves as the timing baseline and as a second
implementation for the tests.
"""
from __future__ import annotations

import numpy as np

from mi_displace.bake.meshdata import MeshData


def _first_hits(intersector, origins, dirs):
    """(triangle, distance) of each ray's first hit; triangle -1 where none."""
    tri, ray, loc = intersector.intersects_id(origins, dirs, multiple_hits=False, return_locations=True)
    out_t = np.full(len(origins), -1, np.int64)
    out_d = np.full(len(origins), np.inf)
    out_t[ray] = tri
    out_d[ray] = np.linalg.norm(loc - origins[ray], axis=1)
    return out_t, out_d


def naive_bake(high: MeshData, low: MeshData, res: int, max_distance: float, delta: float,
               aa: int = 1) -> np.ndarray:
    """(res, res) float32 displacement map [object units]; texels without a hit hold NaN."""
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector
    from trimesh.triangles import points_to_barycentric

    F = len(low.faces)
    uvtri = low.uvs[low.faces].astype(np.float64)
    z = ((np.arange(F) + 1.0) / (F + 1.0))[:, None, None].repeat(3, 1)
    flat = trimesh.Trimesh(np.concatenate([uvtri, z], 2).reshape(-1, 3),
                           np.arange(3 * F).reshape(F, 3), process=False)
    texel = np.arange(res * res)
    sub = np.arange(aa * aa)
    col = (texel % res)[:, None] + ((sub % aa)[None, :] + 0.5) / aa
    row = (texel // res)[:, None] + ((sub // aa)[None, :] + 0.5) / aa
    origins = np.stack([col.ravel() / res, 1.0 - row.ravel() / res, np.full(col.size, 2.0)], 1)
    dirs = np.broadcast_to([0.0, 0.0, -1.0], origins.shape)
    prim, _ = _first_hits(RayMeshIntersector(flat), origins, dirs)
    hit = prim >= 0
    prim_h = prim[hit]
    bary = points_to_barycentric(flat.triangles[prim_h], origins[hit] * [1, 1, 0]
                                 + flat.triangles[prim_h][:, 0] * [0, 0, 1])
    f = low.faces[prim_h]
    nv = low.normals().astype(np.float64)
    p = np.einsum("nk,nkj->nj", bary, low.positions.astype(np.float64)[f])
    n = np.einsum("nk,nkj->nj", bary, nv[f])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    hm = high.to_trimesh()
    inter = RayMeshIntersector(hm)
    ta, da = _first_hits(inter, p - delta * n, n)
    tb, db = _first_hits(inter, p + delta * n, -n)
    fn = hm.face_normals
    va, vb = (ta >= 0) & (da <= max_distance + delta), (tb >= 0) & (db <= max_distance + delta)
    fa = va & (np.einsum("ij,ij->i", fn[np.maximum(ta, 0)], n) > 0)
    fb = vb & (np.einsum("ij,ij->i", fn[np.maximum(tb, 0)], n) > 0)
    sa, sb = da - delta, -(db - delta)
    pick_a = fa & (~fb | (np.abs(sa) <= np.abs(sb)))
    found = fa | fb
    d = np.where(pick_a, sa, sb)
    value = np.full(len(origins), np.nan)
    value[np.flatnonzero(hit)[found]] = d[found]
    value = value.reshape(res * res, aa * aa)
    count = np.isfinite(value).sum(1)
    total = np.where(np.isfinite(value), value, 0.0).sum(1)
    out = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return out.reshape(res, res).astype(np.float32)
