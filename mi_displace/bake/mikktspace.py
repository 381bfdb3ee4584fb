"""MikkTSpace tangents (Mikkelsen 2008), ported from the reference ``mikktspace.c`` to NumPy.

The tangent frame Blender, Unity, Unreal and glTF rebuild when they read a tangent-space
normal map.  A map is only right in those tools if the baker used the *same* per-corner
tangents, so this is a port of ``genTangSpaceDefault`` (angular threshold 180°), step by
step, in float32 like the C code:

1. corners are welded when position, normal and UV are all bit-equal
   (``GenerateSharedVerticesIndexList``); triangles with two equal corner positions are
   degenerate and set aside (``DegenPrologue``);
2. per triangle (``InitTriInfo``): ``vOs`` = dP/ds and ``vOt`` = dP/dt from the UV gradients
   (eq. 18, 19), normalised and multiplied by the sign of the UV area; a triangle is
   *orientation preserving* when its signed UV area is > 0; one with zero UV area or zero
   gradient is *group-with-anything* (GWA);
3. neighbours across welded edges (``BuildNeighborsFast``: edges sorted by (min, max, face),
   paired greedily with the first unpaired reversed edge);
4. groups (``Build4RuleGroups``): at each welded vertex, the triangles reachable from one
   another across edges through that vertex *with the same orientation flag*: mirrored UVs
   and chart borders split the fan;
5. per corner (``GenerateTSpaces`` / ``EvalTspace``): the subgroup of the group's triangles
   whose tangents projected onto the vertex's normal plane are not antiparallel to its own,
   and the tangent = normalize(sum over the subgroup of angle * projected vOs), the angle being
   the corner angle between the edges projected onto the normal plane; sign = +1 if the group
   is orientation preserving, else -1;
6. corners of degenerate triangles copy the space of the first good corner at the same welded
   vertex (``DegenEpilogue``); corners no group reached keep MikkTSpace's default
   (tangent +x, sign -1).

Shader convention (MikkTSpace's): per pixel ``b = sign * cross(n, t)`` from the interpolated,
*unnormalised* vertex normal n and tangent t, and ``N = normalize(x t + y b + z n)``.

Per-element work is NumPy over all corners at once (graph components with SciPy); the only
Python loops run over non-manifold edges (three or more faces on one welded edge) and over
the rounds in which GWA triangles adopt an orientation, both rare.  One deviation: the C code
lets a GWA triangle adopt the orientation of whichever group its depth-first walk reaches it
from first (its only order dependency); here it adopts that of the lowest-numbered adjacent
group (the group whose seed corner comes first, the walk's usual first visitor).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

FLT_MIN = np.float32(np.finfo(np.float32).tiny)
# fThresCos of genTangSpaceDefault: (float) cos((180.0f * (float) M_PI) / 180.0f)
THRESHOLD_COS = np.float32(np.cos(np.float64(np.float32(np.pi))))


def _not_zero(x):
    return np.abs(x) > FLT_MIN


def _normalize_nonzero(v: np.ndarray) -> np.ndarray:
    """Normalise rows of v (float32) whose components are not all (near) zero (VNotZero)."""
    nz = _not_zero(v).any(-1, keepdims=True)
    length = np.sqrt(np.einsum("...k,...k->...", v, v, dtype=np.float32))[..., None]
    return np.where(nz, v / np.where(nz, length, 1), v).astype(np.float32)


def _project(v: np.ndarray, n: np.ndarray) -> np.ndarray:
    """v - (n . v) n, normalised if not zero (float32)."""
    d = np.einsum("...k,...k->...", n, v, dtype=np.float32)[..., None]
    return _normalize_nonzero((v - d * n).astype(np.float32))


def _neighbours(w: np.ndarray) -> np.ndarray:
    """(T, 3) neighbour triangle across edge (i, i+1) of each triangle, -1 where none
    (BuildNeighborsFast's greedy pairing)."""
    T = len(w)
    i0, i1 = w, np.roll(w, -1, axis=1)                        # edge i = (corner i, corner i+1)
    lo, hi = np.minimum(i0, i1).ravel(), np.maximum(i0, i1).ravel()
    face = np.repeat(np.arange(T), 3)
    order = np.lexsort((face, hi, lo))                        # by (min, max, face)
    lo, hi, e = lo[order], hi[order], order                   # e = f * 3 + edge number
    nb = -np.ones(3 * T, np.int64)
    start = np.flatnonzero(np.r_[True, (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])])
    size = np.diff(np.r_[start, len(lo)])
    a0 = i0.ravel()
    # the common case: two faces on an edge, in opposite directions
    two = start[size == 2]
    ea, eb = e[two], e[two + 1]
    opposite = a0[ea] != a0[eb]
    nb[ea[opposite]], nb[eb[opposite]] = eb[opposite] // 3, ea[opposite] // 3
    for s, k in zip(start[size > 2], size[size > 2]):         # non-manifold edges (rare)
        run = e[s:s + k]
        for x in range(k):
            if nb[run[x]] >= 0:
                continue
            for y in range(x + 1, k):
                if nb[run[y]] < 0 and a0[run[y]] != a0[run[x]]:
                    nb[run[x]], nb[run[y]] = run[y] // 3, run[x] // 3
                    break
    return nb.reshape(T, 3)


def _groups(w: np.ndarray, nb: np.ndarray, orient: np.ndarray, gwa: np.ndarray):
    """Group id per corner (T, 3), -1 where no group reached it; orientation of each group.

    Corners (f, i) and (t, j) are linked when t is f's neighbour across one of the two edges
    through corner i, w[t, j] == w[f, i], and both triangles have the same orientation flag
    (AssignRecur).  GWA triangles join with the orientation of their lowest-numbered adjacent
    group.
    """
    T = len(w)
    corner = np.arange(3 * T).reshape(T, 3)
    rows, cols = [], []
    for t in (nb, np.roll(nb, 1, axis=1)):                    # across edges (i, i+1), (i-1, i)
        has = t >= 0
        f_idx, i_idx = np.nonzero(has)
        tt = t[f_idx, i_idx]
        j = np.argmax(w[tt] == w[f_idx, i_idx][:, None], axis=1)
        rows.append(corner[f_idx, i_idx])
        cols.append(corner[tt, j])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    orient = orient.copy()
    decided = ~gwa
    while True:
        ok = decided[rows // 3] & decided[cols // 3] & (orient[rows // 3] == orient[cols // 3])
        graph = coo_matrix((np.ones(int(ok.sum()), np.int8), (rows[ok], cols[ok])), shape=(3 * T, 3 * T))
        _, label = connected_components(graph, directed=False)
        # a component's rank: its first good (non-GWA) corner, the Build4RuleGroups seed order
        seeded = np.repeat(decided & ~gwa, 3)
        first = np.full(label.max() + 1, 3 * T, np.int64)
        np.minimum.at(first, label[seeded], np.flatnonzero(seeded))
        pending = ~decided[rows // 3] & decided[cols // 3]
        if not pending.any():
            break
        # each undecided (GWA) triangle adopts the orientation of its lowest-ranked neighbour group
        tri, nbr = rows[pending] // 3, cols[pending] // 3
        rank = first[label[cols[pending]]]
        best = np.full(T, 3 * T, np.int64)
        np.minimum.at(best, tri, rank)
        pick = rank == best[tri]
        orient[tri[pick]] = orient[nbr[pick]]
        decided[tri[pick]] = True
    in_group = np.repeat(decided, 3) & (first[label] < 3 * T)
    _, gid = np.unique(np.where(in_group, first[label], 3 * T), return_inverse=True)
    gid = gid.ravel()
    gid[~in_group] = -1
    n_groups = int(gid.max()) + 1
    g_orient = np.zeros(n_groups, bool)
    g_orient[gid[in_group]] = np.repeat(orient, 3)[in_group]
    return gid.reshape(T, 3), g_orient


def mikktspace(positions, faces, normals, uvs) -> tuple[np.ndarray, np.ndarray]:
    """MikkTSpace tangents of a triangle mesh, per face corner (see the module docstring).

    Args:
        positions: (V, 3) vertex positions [object units].
        faces: (F, 3) vertex indices.
        normals: (V, 3) unit vertex normals (the ones the renderer will interpolate).
        uvs: (V, 2) texture coordinates (v up, as OBJ and Blender).

    Returns:
        tangents (F, 3, 3) float32 unit vectors and signs (F, 3) float32 in {-1, +1}, corner k
        of face f at [f, k].
    """
    faces = np.asarray(faces, np.int64)
    F = len(faces)
    P = np.asarray(positions, np.float32)[faces] + np.float32(0)      # +0: -0.0 welds with 0.0
    N = np.asarray(normals, np.float32)[faces] + np.float32(0)
    UV = np.asarray(uvs, np.float32)[faces] + np.float32(0)
    key = np.concatenate([P, N, UV], axis=2).reshape(3 * F, 8)
    _, weld = np.unique(key.view(np.dtype((np.void, 32))).ravel(), return_inverse=True)
    weld = weld.reshape(F, 3)
    degenerate = ((P[:, 0] == P[:, 1]).all(1) | (P[:, 0] == P[:, 2]).all(1)
                  | (P[:, 1] == P[:, 2]).all(1))
    good = np.flatnonzero(~degenerate)
    w, p, n, uv = weld[good], P[good], N[good], UV[good]
    T = len(good)
    # InitTriInfo: eq. 18, 19 in float32
    t21, t31 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area2 = t21[:, 0] * t31[:, 1] - t21[:, 1] * t31[:, 0]
    vos = t31[:, 1:2] * d1 - t21[:, 1:2] * d2
    vot = -t31[:, 0:1] * d1 + t21[:, 0:1] * d2
    orient = area2 > 0
    fs = np.where(orient, np.float32(1), np.float32(-1))[:, None]
    len_s = np.sqrt(np.einsum("ij,ij->i", vos, vos, dtype=np.float32))
    len_t = np.sqrt(np.einsum("ij,ij->i", vot, vot, dtype=np.float32))
    area_ok = _not_zero(area2)
    vos = np.where((area_ok & _not_zero(len_s))[:, None], fs / np.where(len_s > 0, len_s, 1)[:, None] * vos, 0)
    vot = np.where((area_ok & _not_zero(len_t))[:, None], fs / np.where(len_t > 0, len_t, 1)[:, None] * vot, 0)
    abs_area = np.where(area_ok, np.abs(area2), 1)
    gwa = ~(area_ok & _not_zero(len_s / abs_area) & _not_zero(len_t / abs_area))
    vos, vot = vos.astype(np.float32), vot.astype(np.float32)

    nb = _neighbours(w)
    gid, g_orient = _groups(w, nb, orient, gwa)

    # EvalTspace terms of every corner (f, i): projected vOs and the projected corner angle
    prev, nxt = np.roll(p, 1, axis=1), np.roll(p, -1, axis=1)
    e1 = _project((prev - p).astype(np.float32), n)
    e2 = _project((nxt - p).astype(np.float32), n)
    cos = np.clip(np.einsum("fik,fik->fi", e1, e2, dtype=np.float32), -1, 1)
    angle = np.arccos(cos.astype(np.float64)).astype(np.float32)

    # GenerateTSpaces: pairs (corner c, member m) of the same group; c's subgroup is the
    # members whose projected vOs, vOt are not antiparallel to its own (or GWA, or c itself)
    flat_g = gid.ravel()
    members = np.flatnonzero(flat_g >= 0)
    order = members[np.argsort(flat_g[members], kind="stable")]
    g_sorted = flat_g[order]
    start = np.flatnonzero(np.r_[True, g_sorted[1:] != g_sorted[:-1]])
    size = np.diff(np.r_[start, len(order)])
    k = np.repeat(size, size)                                 # pairs of each corner: its group's size
    c_pos = np.repeat(np.arange(len(order)), k)
    run_start = np.repeat(np.cumsum(k) - k, k)
    m_pos = np.repeat(np.repeat(start, size), k) + np.arange(len(c_pos)) - run_start
    c = order[c_pos]
    m = order[m_pos]
    cf, mf = c // 3, m // 3
    nc = n.reshape(-1, 3)[c]
    vs_c, vt_c = _project(vos[cf], nc), _project(vot[cf], nc)
    vs_m, vt_m = _project(vos[mf], nc), _project(vot[mf], nc)
    cos_s = np.einsum("ij,ij->i", vs_c, vs_m, dtype=np.float32)
    cos_t = np.einsum("ij,ij->i", vt_c, vt_m, dtype=np.float32)
    member = gwa[cf] | gwa[mf] | (cf == mf) | ((cos_s > THRESHOLD_COS) & (cos_t > THRESHOLD_COS))
    use = member & ~gwa[mf]                                   # GWA triangles add nothing
    contrib = angle.ravel()[m][:, None] * vs_m
    tan = np.zeros((3 * T, 3), np.float32)
    np.add.at(tan, c[use], contrib[use])
    tan = _normalize_nonzero(tan)
    sign = np.where(g_orient[np.maximum(flat_g, 0)], np.float32(1), np.float32(-1))
    unreached = flat_g < 0
    tan[unreached] = (1, 0, 0)
    sign[unreached] = -1

    tangents = np.zeros((F, 3, 3), np.float32)
    signs = np.full((F, 3), -1, np.float32)
    tangents[..., 0] = 1
    tangents[good] = tan.reshape(T, 3, 3)
    signs[good] = sign.reshape(T, 3)
    bad = np.flatnonzero(degenerate)
    if len(bad):  # DegenEpilogue: copy from the first good corner with the same welded vertex
        flat_w = w.ravel()
        uniq, first = np.unique(flat_w, return_index=True)
        dw = weld[bad].ravel()
        pos = np.searchsorted(uniq, dw)
        found = (pos < len(uniq)) & (uniq[np.minimum(pos, len(uniq) - 1)] == dw)
        src = first[np.minimum(pos, len(uniq) - 1)]
        dt, ds = tangents[bad].reshape(-1, 3), signs[bad].ravel()
        dt[found], ds[found] = tan[src[found]], sign[src[found]]
        tangents[bad], signs[bad] = dt.reshape(-1, 3, 3), ds.reshape(-1, 3)
    return tangents, signs


def vertex_tangents(faces, tangents, signs, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex (V, 3) tangents and (V,) signs from the per-corner ones: the space of the
    first corner of each vertex (for consumers that interpolate per vertex; exact wherever a
    vertex's corners share one MikkTSpace group, i.e. away from orientation flips inside a fan)."""
    flat = np.asarray(faces, np.int64).ravel()
    _, first = np.unique(flat, return_index=True)
    t = np.tile(np.float32([1, 0, 0]), (vertex_count, 1))
    s = np.ones(vertex_count, np.float32)
    used = np.unique(flat)
    t[used] = tangents.reshape(-1, 3)[first]
    s[used] = signs.ravel()[first]
    return t, s


def decode_tangent_map(low, normal_tangent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Object-space normals from a tangent-space map, as a MikkTSpace renderer decodes it.

    Per texel centre: the low-poly triangle and barycentrics (the baker's UV layout, no
    conservative coverage), the interpolated unnormalised vertex normal n and MikkTSpace
    tangent t, b = sign (n x t), N = normalize(x t + y b + z n).

    Args:
        low: :class:`~mi_displace.bake.meshdata.MeshData` with UVs (the bake's ``low.obj``).
        normal_tangent: (H, W, 3) unit tangent-space normals (row 0 = v 1).

    Returns:
        (H, W, 3) float32 object-space normals (0 outside the charts) and the (H, W) bool
        mask of texels whose centre lies in a UV triangle.
    """
    from mi_displace.bake.meshdata import vertex_normals
    from mi_displace.bake.uv_raster import UVLayout, rasterize_rows

    H, W, _ = normal_tangent.shape
    s = rasterize_rows(UVLayout(low), W, H, 0, H, 1, conservative=False)
    texel, f = np.asarray(s.texel, np.int64), np.asarray(s.prim, np.int64)
    b1, b2 = np.asarray(s.b1), np.asarray(s.b2)
    w = np.stack([1 - b1 - b2, b1, b2], 1)[..., None]
    normals = vertex_normals(low.positions, low.faces)
    tangents, signs = mikktspace(low.positions, low.faces, normals, low.uvs)
    n = (normals[low.faces[f]] * w).sum(1)
    t = (tangents[f] * w).sum(1)
    b = np.sign((signs[f] * w[..., 0]).sum(1))[:, None] * np.cross(n, t)
    x = normal_tangent.reshape(-1, 3)[texel]
    v = x[:, :1] * t + x[:, 1:2] * b + x[:, 2:3] * n
    out = np.zeros((H * W, 3), np.float32)
    out[texel] = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-30)
    inside = np.zeros(H * W, bool)
    inside[texel] = True
    return out.reshape(H, W, 3), inside.reshape(H, W)
