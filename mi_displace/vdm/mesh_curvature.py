"""Per-vertex curvature tensors of a triangle mesh (for c_V, paper §3.2).

Estimator (Rusinkiewicz 2004, "Estimating curvatures and their derivatives on triangle
meshes"): per face, the shape operator II in the face plane is the least-squares fit of
``II e = dn`` over its three edges e (dn: difference of the vertex normals along e); each
vertex averages the faces around it weighted by area, after projecting onto its own
tangent plane.  Vertices at the same position (UV-seam twins, per-corner normals) are
welded: one normal (the mean of their normals) and one tensor per position.

The tensor is returned in the coordinates of the input as a symmetric 3x3 matrix
``K = c_max C_max C_max^T + c_min C_min C_min^T`` (tangent to the vertex normal), so that
the curvature along any direction V is ``V_t^T K V_t / |V_t|^2`` with ``V_t`` the
tangential part of V — the paper's c_V formula — and K interpolates across a triangle
without the sign ambiguity of principal directions.  Sign: c > 0 where the surface bends
away from its normal (a sphere with outward normals has c = +1/r).
"""
from __future__ import annotations

import numpy as np


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (N, 3) orthogonal to unit normals n (N, 3)."""
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(n, t1)


def curvature_tensors(positions: np.ndarray, normals: np.ndarray, faces: np.ndarray):
    """Per-vertex curvature tensors and principal curvatures.

    Args:
        positions: (V, 3) [world units]; normals: (V, 3) unit vertex normals; faces: (F, 3).

    Returns:
        (K, c_max, c_min): K (V, 3, 3) float64 [1 / world units]; c_max >= c_min (V,).
    """
    p = np.asarray(positions, np.float64)
    n = np.asarray(normals, np.float64)
    f = np.asarray(faces, np.int64)
    _, weld = np.unique(p.astype(np.float32), axis=0, return_inverse=True)
    weld = weld.ravel()
    n_groups = int(weld.max()) + 1
    # one normal per position: files with per-corner normals (one `vn` per face corner,
    # e.g. flat-shaded exports) split every vertex, and their corners' normals are the
    # face's, so dn = 0 on every edge; the mean of the corner normals at each welded
    # position is the smooth normal the estimate needs (unchanged where they agree)
    acc_n = np.zeros((n_groups, 3))
    np.add.at(acc_n, weld, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30))
    n = acc_n[weld]
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    # face frame
    e = [p[f[:, (k + 2) % 3]] - p[f[:, (k + 1) % 3]] for k in range(3)]   # edge opposite k
    dn = [n[f[:, (k + 2) % 3]] - n[f[:, (k + 1) % 3]] for k in range(3)]
    fn = np.cross(e[0], e[1])
    area2 = np.linalg.norm(fn, axis=1)
    good = area2 > 1e-30
    fn = fn / np.maximum(area2, 1e-30)[:, None]
    u = e[0] / np.maximum(np.linalg.norm(e[0], axis=1), 1e-30)[:, None]
    v = np.cross(fn, u)
    # least squares for [a b; b c]: rows (eu, ev, 0)(a,b,c) = dn.u and (0, eu, ev) = dn.v
    M = np.zeros((len(f), 3, 3))
    r = np.zeros((len(f), 3))
    for k in range(3):  # three edges per face
        eu, ev = np.sum(e[k] * u, 1), np.sum(e[k] * v, 1)
        du, dv = np.sum(dn[k] * u, 1), np.sum(dn[k] * v, 1)
        rows = [(np.stack([eu, ev, 0 * eu], 1), du), (np.stack([0 * eu, eu, ev], 1), dv)]
        for a, b in rows:
            M += a[:, :, None] * a[:, None, :]
            r += a * b[:, None]
    M[~good] = np.eye(3)
    abc = np.linalg.solve(M, r[..., None])[..., 0]
    abc[~good] = 0.0
    a, b, c = abc.T
    Kf = (a[:, None, None] * u[:, :, None] * u[:, None, :]
          + b[:, None, None] * (u[:, :, None] * v[:, None, :] + v[:, :, None] * u[:, None, :])
          + c[:, None, None] * v[:, :, None] * v[:, None, :])
    w = 0.5 * area2
    acc = np.zeros((n_groups, 3, 3))
    wsum = np.zeros(n_groups)
    for k in range(3):  # scatter each face's tensor to its three corners
        g = weld[f[:, k]]
        np.add.at(acc, g, Kf * w[:, None, None])
        np.add.at(wsum, g, w)
    K = acc[weld] / np.maximum(wsum[weld], 1e-30)[:, None, None]
    # project onto each vertex's tangent plane: K <- P K P, P = I - n n^T
    P = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    K = P @ K @ P
    K = 0.5 * (K + np.transpose(K, (0, 2, 1)))
    t1, t2 = _tangent_basis(n)
    k11 = np.einsum("vi,vij,vj->v", t1, K, t1)
    k12 = np.einsum("vi,vij,vj->v", t1, K, t2)
    k22 = np.einsum("vi,vij,vj->v", t2, K, t2)
    mean, half = 0.5 * (k11 + k22), np.sqrt(0.25 * (k11 - k22) ** 2 + k12 ** 2)
    return K, mean + half, mean - half


def tile_scale(positions: np.ndarray, uvs: np.ndarray, faces: np.ndarray, tiling) -> tuple[float, float]:
    """World size of one texture tile: area-weighted mean of sqrt(A_world / A_tile) over the
    faces, and its relative spread (area-weighted standard deviation / mean).

    Faces with zero UV area are skipped.
    """
    p = np.asarray(positions, np.float64)
    t = np.asarray(uvs, np.float64) * np.asarray(tiling, np.float64)[None, :]
    f = np.asarray(faces, np.int64)
    aw = 0.5 * np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1)
    d1, d2 = t[f[:, 1]] - t[f[:, 0]], t[f[:, 2]] - t[f[:, 0]]
    at = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    ok = (at > 1e-20) & (aw > 0)
    if not ok.any():
        raise ValueError("vdm: the mesh's UVs have no area; cannot derive the tile size")
    s = np.sqrt(aw[ok] / at[ok])
    w = aw[ok] / aw[ok].sum()
    mean = float(np.sum(w * s))
    spread = float(np.sqrt(np.sum(w * (s - mean) ** 2)) / mean)
    return mean, spread


def open_edge_count(positions: np.ndarray, faces: np.ndarray) -> int:
    """Edges used by one face only once vertices are welded by position (0: closed).

    Args:
        positions: (V, 3) vertex positions; copies at UV seams count as one vertex.
        faces: (F, 3) vertex indices.
    """
    _, weld = np.unique(np.asarray(positions, np.float32), axis=0, return_inverse=True)
    f = weld.reshape(-1)[np.asarray(faces)]
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]          # degenerate faces add no edge
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int(np.count_nonzero(counts == 1))


def is_curved(positions: np.ndarray, faces: np.ndarray, tolerance: float = 1e-6) -> bool:
    """True when the faces' normals are not all parallel (the mesh bends somewhere).

    The second eigenvalue of the scatter matrix of unit face normals is 0 exactly for a
    planar mesh (all normals +-n); ``tolerance`` bounds it otherwise.
    """
    p = np.asarray(positions, np.float64)
    f = np.asarray(faces, np.int64)
    fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    norm = np.linalg.norm(fn, axis=1)
    fn = fn[norm > 0] / norm[norm > 0, None]
    if len(fn) < 2:
        return False
    return bool(np.linalg.eigvalsh(fn.T @ fn / len(fn))[1] > tolerance)


def tile_forms(positions: np.ndarray, uvs: np.ndarray, faces: np.ndarray, K: np.ndarray,
               tiling, tile_size: float) -> dict[str, np.ndarray]:
    """Transform-invariant curvature attributes for rendering (instances, to_world).

    Per face the uv Jacobian J = [dp/du, dp/dv] (exact for a linear triangle); per vertex
    the area-weighted mean of its faces' J (by vertex index: UV-seam twins keep their own
    chart), and ``Q = J_T^T K J_T tile_size`` (Q11, Q12, Q22): the second fundamental form
    in tile coordinates (T = uv * tiling).  With the world Gram matrix G of the tile
    vectors at a pixel and s the local scale of the shape's placement, the curvature along
    a tangent with tile coordinates w is ``c = s^2 w^T Q w / (w^T G w)`` tile^-1, whatever
    rotation or uniform scale places the mesh (``mi_displace.vdm.steps.view_curvature``).

    Everything is returned per face (F, 3) float32, so that a renderer needs no
    barycentric coordinates (Mitsuba computes them from world positions, wrong inside an
    instance): ``q`` (Q at the face's uv centroid), ``q_du``, ``q_dv`` (its uv gradient:
    Q(uv) is the barycentric interpolation of the vertex values) and ``uv`` = (centroid u,
    centroid v, |dp/du x dp/dv|, the reference of s = sqrt(world area / this)).

    Args:
        positions (V, 3), uvs (V, 2), faces (F, 3): the mesh in the space K was measured in.
        K: (V, 3, 3) curvature tensors of :func:`curvature_tensors`.
        tiling: (u, v) texture periods per unit uv; tile_size: one tile in those units.
    """
    p = np.asarray(positions, np.float64)
    t = np.asarray(uvs, np.float64)
    f = np.asarray(faces, np.int64)
    e1, e2 = p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]
    d1, d2 = t[f[:, 1]] - t[f[:, 0]], t[f[:, 2]] - t[f[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    ok = np.abs(det) > 1e-20
    inv = 1.0 / np.where(ok, det, 1.0)
    dp_du = ((d2[:, 1] * inv)[:, None] * e1 - (d1[:, 1] * inv)[:, None] * e2) * ok[:, None]
    dp_dv = ((-d2[:, 0] * inv)[:, None] * e1 + (d1[:, 0] * inv)[:, None] * e2) * ok[:, None]
    area = np.linalg.norm(np.cross(dp_du, dp_dv), axis=1)
    w = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1) * ok
    J = np.zeros((len(p), 3, 2))
    wsum = np.zeros(len(p))
    Jf = np.stack([dp_du / float(tiling[0]), dp_dv / float(tiling[1])], 2) * w[:, None, None]
    for k in range(3):  # scatter each face's Jacobian to its three corners
        np.add.at(J, f[:, k], Jf)
        np.add.at(wsum, f[:, k], w)
    J /= np.maximum(wsum, 1e-30)[:, None, None]
    II = np.einsum("vai,vab,vbj->vij", J, K, J) * float(tile_size)
    Q = np.stack([II[:, 0, 0], 0.5 * (II[:, 0, 1] + II[:, 1, 0]), II[:, 1, 1]], 1)
    # per face, Q as a linear function of uv (what barycentric interpolation of the vertex
    # values gives): at the uv centroid and its uv gradient
    dq1, dq2 = Q[f[:, 1]] - Q[f[:, 0]], Q[f[:, 2]] - Q[f[:, 0]]
    q_du = ((d2[:, 1] * inv)[:, None] * dq1 - (d1[:, 1] * inv)[:, None] * dq2) * ok[:, None]
    q_dv = ((-d2[:, 0] * inv)[:, None] * dq1 + (d1[:, 0] * inv)[:, None] * dq2) * ok[:, None]
    uv_c = t[f].mean(1)
    forms = {"q": Q[f].mean(1), "q_du": q_du, "q_dv": q_dv,
             "uv": np.concatenate([uv_c, area[:, None]], 1)}
    return {k: v.astype(np.float32) for k, v in forms.items()}
