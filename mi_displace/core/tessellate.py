"""True displacement: P(u, v) = S(u, v) + scale * (h(u, v) - midlevel) * n(u, v), tessellated.

Two kinds of base:

* parametric (:mod:`mi_displace.core.surfaces`): a (nu + 1) x (nv + 1) vertex grid over
  [0, 1]^2 with analytic shading normals
  N = P_u x P_v,  P_u = S_u + scale ((h - m) n_u + h_u n)  (likewise for v);
* polygonal (a triangle mesh with UVs): every triangle split into level^2 triangles on a
  barycentric grid, vertices shared across edges, displaced along the interpolated *welded*
  direction (one per position: the angle-weighted normal of the welded surface,
  :func:`welded_normals`) by one height per position (the mean of the sides' lookups at a
  UV seam), so every copy of a position moves by the same vector and the surface stays
  closed across UV seams and hard edges; shading normals are those of the displaced smooth
  surface over the mesh's own vertex normals n,
  N = P_u x P_v with P_u = T_u + scale ((h - m) n_u + h_u n), where T_u is the interpolated
  tangent dS/du projected onto the plane of n (so zero height shades like the smooth base).

Everything per vertex / face is Dr.Jit; the returned buffers go straight into a mi.Mesh.
Closed bases stay watertight: seam vertices are evaluated at the wrapped parameter and the
sphere's pole rows collapse to one displaced point (height averaged over the pole ring).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.surfaces import BaseSurface

MAX_VERTICES = 2**31 // 16  # keeps 3 x 4-byte indices per vertex addressable


def gather(cls, source, index):
    """dr.gather of a vector type (mi.Point3f, mi.Vector2f, ...) component by component."""
    return cls(*(dr.gather(type(c), c, index) for c in source))


def scatter_add(target, value, index) -> None:
    """dr.scatter_add into a vector type, component by component."""
    for t, v in zip(target, value):
        dr.scatter_add(t, v, index)


@dataclass
class Tessellation:
    """Mesh buffers of a displaced surface (Dr.Jit arrays).

    Attributes:
        positions: mi.Point3f, V vertices [object units]
        normals: mi.Vector3f, V unit shading normals
        texcoords: mi.Point2f, V (u, v)
        faces: mi.Vector3u, F triangles (counter-clockwise seen from outside)
        base_positions, base_normals: the undisplaced point S and unit normal n of each
            vertex (mi.Point3f / mi.Vector3f, V), or None where not kept
        displacement: mi.Float, V signed displacement scale (h - m) along n [object units],
            or None (zero height)
    """

    positions: mi.Point3f
    normals: mi.Vector3f
    texcoords: mi.Point2f
    faces: mi.Vector3u
    base_positions: mi.Point3f | None = None
    base_normals: mi.Vector3f | None = None
    displacement: mi.Float | None = None

    @property
    def vertex_count(self) -> int:
        return dr.width(self.positions)

    @property
    def face_count(self) -> int:
        return dr.width(self.faces)


def grid_resolution(base: BaseSurface, resolution: int | None = None,
                    edge_length: float | None = None) -> tuple[int, int]:
    """Grid size (nu, nv) from a u-resolution or a target edge length [object units].

    With ``resolution`` the v count keeps the base's aspect ratio (extent_v / extent_u).
    """
    ext_u, ext_v = base.extent()
    if edge_length is not None:
        if not edge_length > 0 or not math.isfinite(edge_length):
            raise ValueError(f"displaced: 'edge_length' must be a positive number, got {edge_length}")
        nu, nv = math.ceil(ext_u / edge_length), math.ceil(ext_v / edge_length)
    else:
        resolution = 64 if resolution is None else resolution
        if int(resolution) != resolution or resolution < 1:
            raise ValueError(f"displaced: 'resolution' must be a positive integer, got {resolution}")
        nu = int(resolution)
        nv = math.ceil(nu * ext_v / ext_u)
    nu = max(nu, 3 if base.periodic_u else 1)
    nv = max(nv, 2 if base.poles else (3 if base.periodic_v else 1))
    if (nu + 1) * (nv + 1) > MAX_VERTICES:
        raise ValueError(
            f"displaced: a {nu} x {nv} grid ({(nu + 1) * (nv + 1):,} vertices) exceeds the "
            f"limit of {MAX_VERTICES:,} vertices; lower 'resolution' or raise 'edge_length'"
        )
    return nu, nv


def grid_faces(nu: int, nv: int, poles: bool, flip: bool) -> mi.Vector3u:
    """Triangles of a (nu + 1) x (nv + 1) row-major vertex grid, two per quad.

    With ``poles`` the triangle of each quad in the first and last row that would be
    degenerate (two corners on the collapsed pole) is left out.  ``flip`` reverses the
    winding so that face normals agree with the base's outward normal.
    """
    f = dr.arange(mi.UInt32, 2 * nu * nv)
    if poles:
        keep = dr.full(mi.Bool, True, dr.width(f))
        row = (f // 2) // nu
        odd = (f & 1) == 1
        keep &= ~((row == 0) & ~odd) & ~((row == nv - 1) & odd)
        f = dr.gather(mi.UInt32, f, dr.compress(keep))
    q, odd = f // 2, (f & 1) == 1
    a = (q // nu) * (nu + 1) + q % nu
    b, c, d = a + 1, a + nu + 2, a + nu + 1
    # even: (a, b, c)  odd: (a, c, d); in grid order this winds as S_u x S_v
    i1 = dr.select(odd, c, b)
    i2 = dr.select(odd, d, c)
    return mi.Vector3u(a, i2, i1) if flip else mi.Vector3u(a, i1, i2)


def displace_parametric(base: BaseSurface, height, scale: float, midlevel: float,
                        nu: int, nv: int) -> Tessellation:
    """Tessellate and displace a parametric base.

    Args:
        base: the base surface.
        height: callable(uv: mi.Point2f) -> (h: mi.Float, grad: mi.Vector2f), h unitless,
            grad per unit uv; ``None`` for zero displacement (the base itself).
        scale: displacement per unit height [object units].
        midlevel: height that maps to zero displacement.
        nu, nv: grid cells along u and v.
    """
    i = dr.arange(mi.UInt32, (nu + 1) * (nv + 1))
    iu, iv = i % (nu + 1), i // (nu + 1)
    u_tex, v_tex = mi.Float(iu) / nu, mi.Float(iv) / nv
    # Evaluate at the wrapped parameter so seam twins are bit-identical.
    u = mi.Float(iu % nu) / nu if base.periodic_u else u_tex
    v = mi.Float(iv % nv) / nv if base.periodic_v else v_tex

    def poles(h, grad):
        return (_pole_average(h, iv, nu, nv),
                dr.select((iv == 0) | (iv == nv), 0.0, grad)) if base.poles else (h, grad)

    s, p, p_u, p_v, disp = displaced_partials(base, height, scale, midlevel, u, v, poles)
    if base.poles:  # collapse each pole row onto one point
        first = dr.select(iv == 0, 0, dr.select(iv == nv, nv * (nu + 1), i))
        p = gather(mi.Point3f, p, first)
    flip = _winding_is_inward(base)
    return Tessellation(positions=p, normals=partials_normal(s, p_u, p_v),
                        texcoords=mi.Point2f(u_tex, v_tex),
                        faces=grid_faces(nu, nv, base.poles, flip), base_positions=mi.Point3f(s.p),
                        base_normals=mi.Vector3f(s.n), displacement=disp)


def displaced_partials(base: BaseSurface, height, scale: float, midlevel: float,
                       u: mi.Float, v: mi.Float, adjust=None):
    """P = S + scale (h - m) n and its partials P_u, P_v at (u, v) (Dr.Jit, per point).

    P_u = S_u + scale ((h - m) n_u + h_u n) (likewise v).  ``adjust(h - m, grad)`` may
    replace the height and gradient first (pole rows, seam twins).

    Returns:
        (s, p, p_u, p_v, disp): the base's :class:`SurfaceSample`, mi.Point3f, two
        mi.Vector3f and the signed displacement mi.Float (``None`` without a height).
    """
    s = base.sample(u, v)
    p, n = mi.Point3f(s.p), mi.Vector3f(s.n)
    p_u, p_v, disp = s.dp_du, s.dp_dv, None
    if height is not None:
        h, grad = height(mi.Point2f(u, v))
        h = h - midlevel
        if adjust is not None:
            h, grad = adjust(h, grad)
        disp = scale * h
        p = p + disp * n
        p_u = p_u + scale * (h * s.dn_du + grad.x * n)
        p_v = p_v + scale * (h * s.dn_dv + grad.y * n)
    return s, p, p_u, p_v, disp


def partials_normal(s, p_u: mi.Vector3f, p_v: mi.Vector3f) -> mi.Vector3f:
    """Unit normal P_u x P_v oriented like the base's n; n itself where it degenerates."""
    n = mi.Vector3f(s.n)
    normal = dr.cross(p_u, p_v)
    orientation = dr.sign(dr.dot(dr.cross(s.dp_du, s.dp_dv), n))
    normal *= orientation
    degenerate = dr.squared_norm(normal) <= 1e-12 * dr.squared_norm(p_u) * dr.squared_norm(p_v)
    return dr.normalize(dr.select(degenerate, n, normal))


def _pole_average(h: mi.Float, iv: mi.UInt32, nu: int, nv: int) -> mi.Float:
    """Replace h on the two pole rows by its mean over the row (one value per pole)."""
    ring = dr.arange(mi.UInt32, nu)
    north = dr.mean(dr.gather(mi.Float, h, ring))
    south = dr.mean(dr.gather(mi.Float, h, ring + nv * (nu + 1)))
    return dr.select(iv == 0, north, dr.select(iv == nv, south, h))


def _winding_is_inward(base: BaseSurface) -> bool:
    """True if S_u x S_v points against n (then faces are wound the other way)."""
    s = base.sample(mi.Float(0.3), mi.Float(0.4))
    return dr.dot(dr.cross(s.dp_du, s.dp_dv), s.n)[0] < 0


# ---------------------------------------------------------------------------------------
# Polygonal bases


def subdivision_topology(faces: np.ndarray, weld: np.ndarray, level: int):
    """Shared vertices of a uniform 1 -> level^2 split of every triangle (NumPy, one-off).

    Grid point (i, j), i + j <= level, of face (a, b, c) has barycentrics
    (level - i - j, i, j) / level.  Points on an edge are keyed by the edge's end
    vertices, so neighbouring faces share them; UV-seam twins (different vertex ids, same
    ``weld`` id) stay separate vertices (their UVs differ) but are written with the same
    canonical (lower weld id first) interpolation, hence identical positions.

    Args:
        faces: (F, 3) int vertex indices of the base mesh.
        weld: (V,) int position class of each base vertex.
        level: edge splits (>= 1).

    Returns:
        src: (N, 3) uint32 base vertices and ``bary``: (N, 3) float32 weights of each new
        vertex; ``group``: (N,) uint32 weld class of each new vertex; ``new_faces``:
        (F * level^2, 3) uint32.
    """
    L, F, V = level, len(faces), int(faces.max()) + 1
    ii, jj = np.meshgrid(np.arange(L + 1), np.arange(L + 1), indexing="ij")
    sel = ii + jj <= L
    w = np.stack([L - ii[sel] - jj[sel], ii[sel], jj[sel]], 1)          # (P, 3) ints
    P = len(w)
    src = np.repeat(faces[:, None, :], P, 1).astype(np.int64)          # (F, P, 3)
    wts = np.broadcast_to(w, (F, P, 3)).copy()
    nonzero = w > 0
    kind = nonzero.sum(1)                                               # 1 corner, 2 edge, 3 interior
    vkey = (np.arange(F)[:, None] * P + np.arange(P)[None, :]) * 3 + 2  # interior
    gkey = vkey.copy()
    for p in np.flatnonzero(kind == 1):
        c = int(np.argmax(w[p]))
        v = faces[:, c].astype(np.int64)
        src[:, p] = v[:, None]
        wts[:, p] = (L, 0, 0)
        vkey[:, p], gkey[:, p] = v * 3, weld[v] * 3
    for p in np.flatnonzero(kind == 2):
        a, b = np.flatnonzero(nonzero[p])
        va, vb = faces[:, a].astype(np.int64), faces[:, b].astype(np.int64)
        swap = weld[va] > weld[vb]                                      # canonical order
        lo, hi = np.where(swap, vb, va), np.where(swap, va, vb)
        t = np.where(swap, w[p, b], w[p, a])                            # weight of lo
        src[:, p] = np.stack([lo, hi, lo], 1)
        wts[:, p] = np.stack([t, L - t, np.zeros_like(t)], 1)
        vkey[:, p] = ((np.minimum(va, vb) * V + np.maximum(va, vb)) * (L + 1)
                      + np.where(va < vb, w[p, a], w[p, b])) * 3 + 1
        gkey[:, p] = ((weld[lo] * V + weld[hi]) * (L + 1) + t) * 3 + 1
    _, first, inverse = np.unique(vkey.ravel(), return_index=True, return_inverse=True)
    _, group = np.unique(gkey.ravel()[first], return_inverse=True)
    # Small triangles: up (i,j),(i+1,j),(i,j+1); down (i+1,j),(i+1,j+1),(i,j+1).
    local = -np.ones((L + 1, L + 1), dtype=np.int64)
    local[ii[sel], jj[sel]] = np.arange(P)
    i, j = ii[sel], jj[sel]
    up = (i + j) < L
    down = (i + j) < L - 1
    tri = np.concatenate([
        np.stack([local[i[up], j[up]], local[i[up] + 1, j[up]], local[i[up], j[up] + 1]], 1),
        np.stack([local[i[down] + 1, j[down]], local[i[down] + 1, j[down] + 1],
                  local[i[down], j[down] + 1]], 1)])
    new_faces = inverse.reshape(F, P)[:, tri].reshape(-1, 3)
    return (src.reshape(-1, 3)[first].astype(np.uint32),
            (wts.reshape(-1, 3)[first] / L).astype(np.float32),
            group.astype(np.uint32), new_faces.astype(np.uint32))


def vertex_frames(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray,
                  faces: np.ndarray):
    """Per-vertex tangents dS/du, dS/dv and normal derivatives dn/du, dn/dv (NumPy, one-off).

    Each triangle's constant Jacobians (from its positions, vertex normals and UVs) are
    averaged over the triangles around a vertex, weighted by area; the normal derivatives
    are projected onto the vertex's tangent plane (derivatives of the *unit* normal).
    Triangles with a degenerate UV map contribute nothing.

    Returns:
        (s_u, s_v, n_u, n_v): four (V, 3) float32 arrays [object units per unit uv; per unit uv].
    """
    p = np.asarray(positions, np.float64)
    nrm = np.asarray(normals, np.float64)
    uv = np.asarray(uvs, np.float64)
    f = np.asarray(faces, np.int64)
    e1, e2 = p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]
    m1, m2 = nrm[f[:, 1]] - nrm[f[:, 0]], nrm[f[:, 2]] - nrm[f[:, 0]]
    d1, d2 = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    # [X_u X_v] = [X_1 X_2] [d1 d2]^-1 for X = S (edges e) and the interpolated normal (m)
    ju = lambda a, b: (a * d2[:, 1:2] - b * d1[:, 1:2]) * inv
    jv = lambda a, b: (b * d1[:, 0:1] - a * d2[:, 0:1]) * inv
    area = (0.5 * np.linalg.norm(np.cross(e1, e2), axis=1) * ok)[:, None]
    out = []
    for per_face in (ju(e1, e2), jv(e1, e2), ju(m1, m2), jv(m1, m2)):
        acc = np.zeros_like(p)
        for k in range(3):
            np.add.at(acc, f[:, k], per_face * area)
        out.append(acc)
    weight = np.zeros(len(p))
    for k in range(3):
        np.add.at(weight, f[:, k], area[:, 0])
    weight = np.where(weight > 0, weight, 1.0)[:, None]
    s_u, s_v, n_u, n_v = (a / weight for a in out)
    unit = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    n_u -= np.sum(n_u * unit, 1, keepdims=True) * unit
    n_v -= np.sum(n_v * unit, 1, keepdims=True) * unit
    return tuple(np.ascontiguousarray(a, np.float32) for a in (s_u, s_v, n_u, n_v))


def smooth_displaced_normals(n, s_u, s_v, n_u, n_v, disp, grad, scale: float):
    """Normal of the displaced smooth surface in the interpolated frame (Dr.Jit, per vertex).

    N = P_u x P_v with P_u = T_u + disp n_u + scale h_u n, T_u = s_u - (s_u . n) n (likewise
    for v), oriented along n; where it degenerates, n.

    Args:
        n: unit interpolated normal; s_u, s_v, n_u, n_v: interpolated frame (mi.Vector3f);
        disp: scale (h - m) (mi.Float) or None; grad: dh/duv (mi.Vector2f) or None.
    """
    t_u = s_u - dr.dot(s_u, n) * n
    t_v = s_v - dr.dot(s_v, n) * n
    frame = dr.dot(dr.cross(t_u, t_v), n)  # 0 where the frame is degenerate (dr.sign(0) is 1)
    orientation = dr.select(frame < 0, -1.0, 1.0)
    p_u, p_v = t_u, t_v
    if disp is not None:
        p_u = p_u + disp * (n_u - dr.dot(n_u, n) * n) + scale * grad.x * n
        p_v = p_v + disp * (n_v - dr.dot(n_v, n) * n) + scale * grad.y * n
    normal = dr.cross(p_u, p_v) * orientation
    degenerate = (dr.squared_norm(normal) <= 1e-12 * dr.squared_norm(p_u) * dr.squared_norm(p_v)) | (
        frame == 0)
    return dr.normalize(dr.select(degenerate, n, normal))


def displace_mesh(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray,
                  faces: np.ndarray, height, scale: float, midlevel: float,
                  level: int) -> Tessellation:
    """Subdivide a triangle mesh with UVs and displace it along its welded normals.

    Every copy of a position (UV seams, hard edges) moves by one vector: the welded
    direction (:func:`welded_normals`) times the mean of the copies' heights.  Shading
    normals are those of the displaced *smooth* surface (:func:`smooth_displaced_normals`
    over the interpolated frame of :func:`vertex_frames`), averaged over seam twins; at zero
    height they are the interpolated base normals, as a smooth-shaded base mesh has.

    Args:
        positions: (V, 3) float vertex positions [object units].
        normals: (V, 3) float unit vertex normals.
        uvs: (V, 2) float texture coordinates.
        faces: (F, 3) int triangles.
        height: callable(uv) -> (h, grad) or None; scale, midlevel: as
            :func:`displace_parametric`.
        level: subdivision level (each edge split into ``level`` segments).
    """
    src, bary, group, new_faces = subdivision_topology(faces, weld_classes(positions), level)
    return displace_mesh_vertices(positions, normals, uvs, faces, src, bary, group, new_faces,
                                  height, scale, midlevel)


def weld_classes(positions: np.ndarray) -> np.ndarray:
    """(V,) int position class of each vertex (equal float32 positions share one)."""
    _, weld = np.unique(np.asarray(positions, np.float32), axis=0, return_inverse=True)
    return weld.ravel()


def welded_normals(positions: np.ndarray, normals: np.ndarray, faces: np.ndarray,
                   weld: np.ndarray | None = None) -> np.ndarray:
    """One displacement direction per position class: the angle-weighted normal of the
    welded surface (Thürmer and Wüthrich 1998), identical for every copy (NumPy, one-off).

    Each face adds its unit normal times its corner angle to the class of each corner.  A
    face whose normal points against the sum of its corners' vertex normals counts flipped,
    so the directions face the way the mesh's own normals do whatever the winding.  A class
    whose sum vanishes (isolated vertices, a sheet folded onto itself) takes the mean of its
    vertex normals, else +z.

    Args:
        positions: (V, 3) float vertex positions [object units].
        normals: (V, 3) float vertex normals (orientation and fallback only).
        faces: (F, 3) int triangles.
        weld: (V,) int position class (:func:`weld_classes` when ``None``).

    Returns:
        (V, 3) float32 unit directions, equal within a class.
    """
    p = np.asarray(positions, np.float64)
    nrm = np.asarray(normals, np.float64)
    f = np.asarray(faces, np.int64)
    weld = weld_classes(positions) if weld is None else np.asarray(weld, np.int64)
    fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    fn *= np.where(np.einsum("ij,ij->i", fn, nrm[f].sum(1)) < 0, -1.0, 1.0)[:, None]
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    acc = np.zeros((int(weld.max()) + 1, 3))
    fallback = np.zeros_like(acc)
    np.add.at(fallback, weld, nrm)
    for k in range(3):
        a = p[f[:, (k + 1) % 3]] - p[f[:, k]]
        b = p[f[:, (k + 2) % 3]] - p[f[:, k]]
        angle = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))
        np.add.at(acc, weld[f[:, k]], fn * angle[:, None])
    for candidate in (fallback, np.broadcast_to([0.0, 0.0, 1.0], acc.shape)):
        length = np.linalg.norm(acc, axis=1, keepdims=True)
        acc = np.where(length > 1e-12, acc, candidate)
    return (acc / np.linalg.norm(acc, axis=1, keepdims=True))[weld].astype(np.float32)


def split_positions(normals: np.ndarray, weld: np.ndarray) -> int:
    """Number of position classes whose copies carry different vertex normals (UV seams
    with per-side normals, hard edges): where per-vertex directions would crack."""
    key = np.concatenate([np.asarray(weld, np.int64)[:, None],
                          (np.asarray(normals, np.float32) + np.float32(0)).view(np.int32)], 1)
    pairs = np.unique(key, axis=0)[:, 0]
    return int((np.bincount(pairs) > 1).sum())


def displace_mesh_vertices(positions, normals, uvs, faces, src: np.ndarray, bary: np.ndarray,
                           group: np.ndarray, new_faces: np.ndarray, height, scale: float,
                           midlevel: float, frames: tuple | None = None,
                           directions: np.ndarray | None = None) -> Tessellation:
    """Displace the vertices of any refinement of a base mesh (:func:`displace_mesh`'s kernel).

    Args:
        positions, normals, uvs, faces: the base mesh (as :func:`displace_mesh`).
        src: (N, 3) base vertex ids and ``bary``: (N, 3) weights of each new vertex.
        group: (N,) position class: vertices of one class get one displacement and one
            normal (UV-seam twins stay on one point).
        new_faces: (F', 3) triangles over the new vertices.
        height, scale, midlevel: as :func:`displace_parametric`.
        frames: :func:`vertex_frames` of the base mesh, when already computed (a
            re-displacement of the same base); computed here when ``None``.
        directions: (V, 3) unit displacement direction of each base vertex;
            :func:`welded_normals` (one per position: watertight) when ``None``.
    """
    idx = [mi.UInt32(np.ascontiguousarray(src[:, k], np.uint32)) for k in range(3)]
    wts = [mi.Float(np.ascontiguousarray(bary[:, k], np.float32)) for k in range(3)]

    def interp(data):
        cls = mi.Vector3f if data.shape[1] == 3 else mi.Vector2f
        arr = cls(*[mi.Float(np.ascontiguousarray(data[:, k], np.float32))
                    for k in range(data.shape[1])])
        return sum((gather(cls, arr, idx[k]) * wts[k] for k in range(1, 3)),
                   gather(cls, arr, idx[0]) * wts[0])

    base_p = mi.Point3f(interp(positions))
    uv = mi.Point2f(interp(uvs))
    s_u, s_v, n_u, n_v = (interp(a) for a in (vertex_frames(positions, normals, uvs, faces)
                                                 if frames is None else frames))
    frame = dr.cross(s_u, s_v)

    def unit(n_raw):
        # between normals that cancel (a crease whose sides share vertices) fall back to the
        # tangent frame's normal, else +z: never a NaN
        return dr.normalize(dr.select(dr.squared_norm(n_raw) > 1e-12, n_raw, dr.select(
            dr.squared_norm(frame) > 0, frame, mi.Vector3f(0, 0, 1))))

    n = unit(interp(normals))                       # shading frame: the mesh's own normals
    if directions is None:
        directions = welded_normals(positions, normals, faces)
    # edge points interpolate their edge's two welded ends in canonical order (the topology's
    # src / bary), so every copy of a position gets the same direction bit for bit
    direction = unit(interp(directions))
    groups = mi.UInt32(np.ascontiguousarray(group, np.uint32))
    n_groups = int(group.max()) + 1
    p, disp, grad = base_p, None, None
    if height is not None:
        h, grad = height(uv)
        # one height per position class: the mean of the sides' lookups (UV seams)
        disp = group_mean(scale * (h - midlevel), groups, n_groups)
        p = base_p + disp * direction
    normal = smooth_displaced_normals(n, s_u, s_v, n_u, n_v, disp, grad, scale)
    # seam twins whose normals cancel (a fold of the offset surface) keep n: never a NaN
    mean = group_mean(normal, groups, n_groups)
    normal = dr.normalize(dr.select(dr.squared_norm(mean) > 1e-12, mean, n))
    f = mi.Vector3u(*[mi.UInt32(np.ascontiguousarray(new_faces[:, k], np.uint32))
                      for k in range(3)])
    return Tessellation(positions=p, normals=normal, texcoords=uv, faces=f,
                        base_positions=base_p, base_normals=direction, displacement=disp)


def group_mean(value, groups: mi.UInt32, n_groups: int):
    """Mean of ``value`` (mi.Float or a 3-vector) over the vertices of each group, per vertex."""
    count = dr.zeros(mi.Float, n_groups)
    dr.scatter_add(count, 1.0, groups)
    count = dr.gather(mi.Float, count, groups)
    if isinstance(value, mi.Float):
        total = dr.zeros(mi.Float, n_groups)
        dr.scatter_add(total, value, groups)
        return dr.gather(mi.Float, total, groups) / count
    total = dr.zeros(mi.Vector3f, n_groups)
    scatter_add(total, value, groups)
    return gather(mi.Vector3f, total, groups) / count


def face_weighted_normals(p: mi.Point3f, faces: mi.Vector3u, groups: mi.UInt32,
                          n_groups: int, fallback: mi.Vector3f) -> mi.Vector3f:
    """Area-weighted vertex normals summed over position classes ``groups``.

    Vertices whose faces all have zero area keep ``fallback``.
    """
    p0, p1, p2 = (gather(mi.Point3f, p, faces[k]) for k in range(3))
    fn = dr.cross(p1 - p0, p2 - p0)
    acc = dr.zeros(mi.Vector3f, n_groups)
    for k in range(3):
        scatter_add(acc, fn, dr.gather(mi.UInt32, groups, faces[k]))
    nrm = gather(mi.Vector3f, acc, groups)
    return dr.normalize(dr.select(dr.squared_norm(nrm) > 0, nrm, fallback))
