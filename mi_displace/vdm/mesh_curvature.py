"""Per-vertex curvature tensors of a triangle mesh (for c_V, paper §3.2).

Estimator (Rusinkiewicz 2004, "Estimating curvatures and their derivatives on triangle
meshes"): per face, the shape operator II in the face plane is the least-squares fit of
``II e = dn`` over its three edges e (dn: difference of the vertex normals along e); each
vertex averages the faces around it weighted by area, after projecting onto its own
tangent plane.  Vertices at the same position (UV-seam twins, per-corner normals) are
welded: one normal (the mean of their normals) and one tensor per position.

The tensor is stored in world coordinates as a symmetric 3x3 matrix
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


def pack(K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(diag, off) float32 (V, 3) each: (Kxx, Kyy, Kzz) and (Kxy, Kxz, Kyz)."""
    diag = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 2, 2]], 1)
    off = np.stack([K[:, 0, 1], K[:, 0, 2], K[:, 1, 2]], 1)
    return diag.astype(np.float32), off.astype(np.float32)


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
