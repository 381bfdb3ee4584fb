"""Bicubic Bezier patch surfaces: the Utah teapot body as a parametric base.

The Newell teapot text format (``data/teapot/newell_teapot.txt``): line 1 the patch count,
then one line per patch with 16 comma-separated 1-based control-point indices (4 x 4,
row-major: the 4 entries of a row run *around* the teapot, rows run from the rim down),
then the point count and one ``x, y, z`` line per point (Z up).

:class:`BezierBody` joins a grid of patches (``columns`` around x ``rows`` down) into one
base S(u, v) over [0, 1]^2 with exact S, S_u, S_v and normal derivatives (from the second
derivatives), so HDDM's ``exact`` mode and the ``jacobian`` normals work on it like on the
analytic bases.  The teapot body is patches 1-12 (rim, upper body, lower body; 4 around).
"""
from __future__ import annotations

import os
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.resources import data_path
from mi_displace.core.surfaces import BaseSurface, SurfaceSample, principal_curvatures

DEFAULT_TEAPOT = data_path("teapot", "newell_teapot.txt")
TEAPOT_BODY = ((0, 1, 2, 3), (4, 5, 6, 7), (8, 9, 10, 11))  # rows of 0-based patch ids


def load_patches(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a Newell-format patch file.

    Returns:
        ``(patches, points)``: (P, 16) int64 0-based control-point indices and (N, 3)
        float64 control points [object units].

    Raises:
        FileNotFoundError: no such file.  ValueError: malformed content (names the file).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Bezier patch file {str(path)!r} does not exist")
    lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip()]
    try:
        n_patch = int(lines[0])
        patches = np.array([[int(x) for x in ln.split(",")] for ln in lines[1:1 + n_patch]])
        n_pts = int(lines[1 + n_patch])
        points = np.array([[float(x) for x in ln.split(",")]
                           for ln in lines[2 + n_patch:2 + n_patch + n_pts]])
    except (ValueError, IndexError) as e:
        raise ValueError(f"Bezier patch file {str(path)!r} is malformed: {e}") from None
    if patches.shape != (n_patch, 16) or points.shape != (n_pts, 3):
        raise ValueError(f"Bezier patch file {str(path)!r}: expected {n_patch} x 16 indices and "
                         f"{n_pts} x 3 points, got {patches.shape} and {points.shape}")
    if patches.min() < 1 or patches.max() > n_pts:
        raise ValueError(f"Bezier patch file {str(path)!r}: indices outside 1..{n_pts}")
    return patches - 1, points


def _bernstein(t):
    """Cubic Bernstein basis, first and second derivatives at t (lists of 4 Dr.Jit Floats)."""
    s = 1 - t
    b = [s * s * s, 3 * t * s * s, 3 * t * t * s, t * t * t]
    db = [-3 * s * s, 3 * s * s - 6 * t * s, 6 * t * s - 3 * t * t, 3 * t * t]
    ddb = [6 * s, -12 * s + 6 * t, 6 * s - 12 * t, 6 * t]
    return b, db, ddb


class BezierBody(BaseSurface):
    """A ``rows`` x ``columns`` grid of bicubic patches as one base over [0, 1]^2.

    u runs around (``columns`` patches, periodic when the last column meets the first),
    v runs down the rows.  Patch (r, c) covers u in [c / C, (c + 1) / C], v in [r / R,
    (r + 1) / R].  The normal is oriented outward (away from the z axis at mid height).
    """

    name = "teapot"
    periodic_u = True

    def __init__(self, filename: str | os.PathLike = DEFAULT_TEAPOT, grid=TEAPOT_BODY):
        patches, points = load_patches(filename)
        grid = np.asarray(grid, np.int64)
        if grid.ndim != 2 or grid.min() < 0 or grid.max() >= len(patches):
            raise ValueError(f"BezierBody: patch grid {grid.tolist()} outside 0..{len(patches) - 1}")
        self.rows, self.cols = grid.shape
        ctrl = points[patches[grid.ravel()]].astype(np.float32)   # (R*C, 16, 3)
        self._ctrl = [mi.Float(np.ascontiguousarray(ctrl[..., k].ravel())) for k in range(3)]
        first, last = points[patches[grid[:, 0]]][:, ::4], points[patches[grid[:, -1]]][:, 3::4]
        self.periodic_u = bool(np.allclose(first, last, atol=1e-6))
        self._sign = 1.0
        s = self.sample(mi.Float(0.1), mi.Float(0.5))
        outward = dr.dot(s.n, mi.Vector3f(s.p.x, s.p.y, 0))[0]
        self._sign = 1.0 if outward > 0 else -1.0
        self._extent = None

    def sample(self, u, v):
        C, R = self.cols, self.rows
        if self.periodic_u:   # wrap around the pot (tiles crossing the seam)
            u = u - dr.floor(u)
        su, sv = u * C, v * R
        col = mi.UInt32(dr.clip(mi.Int32(dr.floor(su)), 0, C - 1))
        row = mi.UInt32(dr.clip(mi.Int32(dr.floor(sv)), 0, R - 1))
        s, t = su - mi.Float(col), sv - mi.Float(row)
        bs, dbs, ddbs = _bernstein(s)
        bt, dbt, ddbt = _bernstein(t)
        base = (row * C + col) * 16
        zero = dr.zeros(mi.Vector3f, dr.width(u))
        p, p_u, p_v, p_uu, p_uv, p_vv = (mi.Vector3f(zero) for _ in range(6))
        for i in range(4):          # row of the patch (v)
            for j in range(4):      # column (u)
                idx = base + 4 * i + j
                c = mi.Vector3f(*(dr.gather(mi.Float, a, idx) for a in self._ctrl))
                p += bt[i] * bs[j] * c
                p_u += bt[i] * dbs[j] * c
                p_v += dbt[i] * bs[j] * c
                p_uu += bt[i] * ddbs[j] * c
                p_uv += dbt[i] * dbs[j] * c
                p_vv += ddbt[i] * bs[j] * c
        p_u, p_v = p_u * C, p_v * R
        p_uu, p_uv, p_vv = p_uu * (C * C), p_uv * (C * R), p_vv * (R * R)
        big_n = self._sign * dr.cross(p_u, p_v)
        dn_u = self._sign * (dr.cross(p_uu, p_v) + dr.cross(p_u, p_uv))
        dn_v = self._sign * (dr.cross(p_uv, p_v) + dr.cross(p_u, p_vv))
        inv = dr.rcp(dr.maximum(dr.norm(big_n), 1e-20))
        n = big_n * inv
        # d(N/|N|) = (dN - n (n . dN)) / |N|
        n_u = (dn_u - n * dr.dot(n, dn_u)) * inv
        n_v = (dn_v - n * dr.dot(n, dn_v)) * inv
        return SurfaceSample(p=mi.Point3f(p), dp_du=p_u, dp_dv=p_v, n=n, dn_du=n_u, dn_dv=n_v)

    def _grid_sample(self, n: int = 96):
        i = dr.arange(mi.UInt32, n * n)
        u = (mi.Float(i % n) + 0.5) / n
        v = (mi.Float(i // n) + 0.5) / n
        return self.sample(u, v), n

    def extent(self):
        if self._extent is None:
            s, n = self._grid_sample()
            du = np.asarray(dr.norm(s.dp_du)).reshape(n, n)   # rows: v, columns: u
            dv = np.asarray(dr.norm(s.dp_dv)).reshape(n, n)
            self._extent = (float(du.mean(1).max()), float(dv.mean(0).max()))
        return self._extent

    def curvature_bounds(self):
        s, _ = self._grid_sample()
        k_max, k_min, _, _ = principal_curvatures(s)
        return float(dr.min(k_min)[0]), float(dr.max(k_max)[0])


def teapot_body(filename: str | os.PathLike | None = None) -> BezierBody:
    """The Utah teapot body (rim + upper + lower body, 12 patches) as a base."""
    return BezierBody(DEFAULT_TEAPOT if filename is None else filename, TEAPOT_BODY)


