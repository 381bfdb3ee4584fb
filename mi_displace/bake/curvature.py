"""Mean curvature of the high-poly (per vertex, NumPy preprocessing) and the cavity map.

Discrete mean curvature by the cotangent formula of Meyer, Desbrun, Schröder and Barr,
"Discrete Differential-Geometry Operators for Triangulated 2-Manifolds" (2003), eq. 8 with the
mixed Voronoi area of their Fig. 4::

    K(x_i) = 1 / (2 A_mixed) * sum_j (cot alpha_ij + cot beta_ij) (x_i - x_j),
    H(x_i) = K(x_i) . n_i / 2

signed against the area-weighted vertex normal n_i: H > 0 where the surface is convex
(a sphere of radius r: H = 1/r; a cylinder: 1/(2r)), H < 0 in creases and pits.  Units:
1 / object units.  Boundary vertices get the formula's value, which is not a curvature (one
side of their fan is missing): the maps are meaningful away from the high-poly's holes.

The baker interpolates H at the point where each texel's ray hit the high-poly.  The cavity
map is the normalised negative part: ``cavity = clip(-H / H_ref, 0, 1)``, ``H_ref`` the
``curvature_range`` setting or, by default, the 99th percentile of |H| over the measured
texels (recorded in the sidecar); the 16-bit curvature PNG stores
``0.5 + 0.5 clip(H / H_ref, -1, 1)`` (0.5 = flat).
"""
from __future__ import annotations

import numpy as np

#: percentile of |H| over the measured texels that maps to full contrast by default
RANGE_PERCENTILE = 99.0


def mean_curvature(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V,) float32 signed mean curvature H [1 / object units] of a triangle mesh
    (positions (V, 3), faces (F, 3); welded: seam twins must already share one vertex)."""
    p = np.asarray(positions, np.float64)
    f = np.asarray(faces, np.int64)
    V = len(p)
    corners = [p[f[:, k]] for k in range(3)]
    # edge opposite corner k: from corner k+1 to corner k+2
    e = [corners[(k + 2) % 3] - corners[(k + 1) % 3] for k in range(3)]
    normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    double_area = np.linalg.norm(normal, axis=1)
    safe = np.maximum(double_area, 1e-300)
    # cot of the angle at corner k: dot / |cross| of its two edges
    cot = []
    for k in range(3):
        a, b = -e[(k + 2) % 3], e[(k + 1) % 3]    # corner k -> k+1 and corner k -> k+2
        cot.append((a * b).sum(1) / safe)
    cot = np.stack(cot, 1)                                                   # (F, 3)
    K = np.zeros((V, 3))
    for k in range(3):
        i, j, m = f[:, k], f[:, (k + 1) % 3], f[:, (k + 2) % 3]
        # edge (i, j) is opposite corner m, edge (i, m) opposite corner j
        np.add.at(K, i, cot[:, (k + 2) % 3, None] * (p[i] - p[j]) + cot[:, (k + 1) % 3, None] * (p[i] - p[m]))
    # mixed Voronoi area (Meyer et al. Fig. 4)
    sq = np.stack([(e[k] ** 2).sum(1) for k in range(3)], 1)                   # |edge opposite k|^2
    area = double_area / 2
    obtuse = cot < 0
    any_obtuse = obtuse.any(1)
    A = np.zeros(V)
    for k in range(3):
        voronoi = (sq[:, (k + 1) % 3] * cot[:, (k + 1) % 3] + sq[:, (k + 2) % 3] * cot[:, (k + 2) % 3]) / 8
        mixed = np.where(any_obtuse, np.where(obtuse[:, k], area / 2, area / 4), voronoi)
        np.add.at(A, f[:, k], mixed)
    vn = np.zeros((V, 3))
    for k in range(3):
        np.add.at(vn, f[:, k], normal)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    H = (K * vn).sum(1) / (4 * np.maximum(A, 1e-300))
    return np.where(A > 0, H, 0.0).astype(np.float32)


def curvature_range(H: np.ndarray, measured: np.ndarray, given: float | None) -> float:
    """H_ref [1 / object units]: ``given``, else the RANGE_PERCENTILE of |H| at the measured
    texels ((H, W) bool), never 0."""
    if given is not None:
        return float(given)
    values = np.abs(H[measured]) if np.any(measured) else np.abs(H)
    ref = float(np.percentile(values, RANGE_PERCENTILE)) if values.size else 0.0
    return ref if ref > 0 else 1.0


def cavity(H: np.ndarray, ref: float) -> np.ndarray:
    """(H, W) float32 cavity in [0, 1]: the negative part of H over ``ref``."""
    return np.clip(-H / ref, 0.0, 1.0).astype(np.float32)


def encode_signed(H: np.ndarray, ref: float) -> np.ndarray:
    """(H, W) float32 in [0, 1]: 0.5 + 0.5 clip(H / ref, -1, 1) (the curvature PNG)."""
    return (0.5 + 0.5 * np.clip(H / ref, -1.0, 1.0)).astype(np.float32)
