"""Model restoration (§5): subdivide the low-poly, displace the new vertices from the map.

1. **Subdivision** (Fig. 10) — ``levels`` rounds of 1 -> 4 midpoint subdivision, i.e. every
   triangle split into 4^levels on a barycentric grid (:func:`mi_displace.core.tessellate.subdivision_topology`
   with 2^levels edge splits), or, with ``split = N``, the uniform 1 -> N^2 pattern directly
   (N = 3 is the ternary 1 -> 9 split, a pattern no power of two reaches).
2. **Alias buffers** — twins (vertices at the same position with different UVs, from UV seams)
   share one alias id (:func:`meshdata.weld_ids`, a hash on the exact float32 position instead
   of the paper's octree search); the subdivision keys new edge vertices by the alias ids of
   the edge's ends, so twins created by subdivision inherit aliases too.  The displacement
   vector of every alias class is the mean over its members ("synchronize duplicate vertices
   displacement amounts"), so twins move identically: no cracks.
3. **Displacement** — P = p + d * dir, d bilinearly sampled from the map at the vertex's UV
   (Dr.Jit texture, clamp), dir the interpolated normal, or for direction formats
   normalize(x t + y b + z n) from the stored tangent-space direction.
4. **Holes** — vertices sampling "void" in the bake's validity mask (no high-poly within
   reach) are counted.  On an *open* low-poly (boundary edges) a void region is a hole of the
   original: faces with at least two of three void vertices are dropped.  A *closed* low-poly
   never loses a face: its void vertices keep the map's value there, which the bake's edge
   padding filled from the nearest measured texel (within the padding radius; beyond it the
   displacement is 0, i.e. the low-poly position), so the restored mesh stays closed.
5. **Normals** — area-weighted normals of the displaced faces summed over alias classes.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake import formats
from mi_displace.bake.meshdata import MeshData, edge_counts, load_mesh, save_obj, weld_ids
from mi_displace.bake.mikktspace import mikktspace, vertex_tangents
from mi_displace.core.tessellate import (MAX_VERTICES, face_weighted_normals, gather,
                                         scatter_add, subdivision_topology)

MAX_SPLIT = 64
VOID_CORNERS = 2  # a face is dropped when most (2 of 3) of its corners are void


@dataclass
class Restored:
    """A restored mesh (NumPy): positions (V,3) f32, faces (F,3) u32, normals (V,3), uvs (V,2)."""

    positions: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    seconds: float
    report: dict   # closed, boundary/non-manifold edges, void vertices, dropped faces, holes rule
    state: "DisplaceState" = None   # what re-displaces the mesh from an edited map (Dr.Jit, AD)

    def save(self, path: str | os.PathLike) -> None:
        """Write as OBJ or PLY (by suffix)."""
        path = str(path)
        if path.lower().endswith(".ply"):
            import trimesh

            trimesh.Trimesh(self.positions, self.faces, vertex_normals=self.normals,
                            process=False).export(path)
        elif path.lower().endswith(".obj"):
            save_obj(path, self.positions, self.faces, self.uvs, self.normals)
        else:
            raise ValueError(f"out: restored mesh must be .ply or .obj, got {path!r}")


@dataclass
class DisplaceState:
    """Step 3 as a function of the map: the subdivided low-poly (Dr.Jit, N vertices, G alias
    classes) and what turns a displacement tensor (H, W, 1) [object units] into positions,
    differentiably (the ``restored`` shape's map texels are optimisable through it).

    ``fixed`` (G,) marks alias classes whose offset is not read from the map (void vertices of
    a closed low-poly, filled from their neighbours: ``fixed_offset``, constant).
    """

    p: mi.Point3f                 # (N,) undisplaced subdivided positions
    direction: mi.Vector3f        # (N,) unit displacement directions
    lookup: mi.Point2f            # (N,) texture lookup (u, 1 - v)
    groups: mi.UInt32             # (N,) alias class
    count: mi.Float               # (G,) members per class
    n_groups: int
    fixed: mi.Bool = False
    fixed_offset: mi.Vector3f = None
    faces: mi.Vector3u = None
    normals: mi.Vector3f = None   # (N,) interpolated low-poly normals (normal fallback)

    def offsets(self, displacement: mi.TensorXf) -> mi.Vector3f:
        """(G,) mean displacement vector of each alias class, bilinear from the map."""
        tex = mi.Texture2f(displacement, filter_mode=dr.FilterMode.Linear,
                           wrap_mode=dr.WrapMode.Clamp, use_accel=False)
        d = tex.eval(self.lookup)[0]
        total = dr.zeros(mi.Vector3f, self.n_groups)   # alias buffer: one displacement per class
        scatter_add(total, d * self.direction, self.groups)
        return total / self.count

    def displace(self, displacement: mi.TensorXf) -> tuple[mi.Point3f, mi.Vector3f]:
        """Positions (N,) and area-weighted normals (N,) of the mesh displaced by the map."""
        off = dr.select(self.fixed, self.fixed_offset, self.offsets(displacement)) \
            if self.fixed_offset is not None else self.offsets(displacement)
        p = self.p + gather(mi.Vector3f, off, self.groups)
        return p, face_weighted_normals(p, self.faces, self.groups, self.n_groups, self.normals)


def edge_splits(levels: int | None, split: int | None) -> int:
    """Edge splits per triangle from ``levels`` (1 -> 4 rounds) or ``split`` (1 -> N^2)."""
    if split is not None:
        if isinstance(split, bool) or int(split) != split or not 1 <= split <= MAX_SPLIT:
            raise ValueError(f"split: must be an integer in [1, {MAX_SPLIT}], got {split!r}")
        return int(split)
    levels = 2 if levels is None else levels
    if isinstance(levels, bool) or int(levels) != levels or not 0 <= levels <= 6:
        raise ValueError(f"levels: must be an integer in [0, 6], got {levels!r}")
    return 2 ** int(levels)


def _texture(array: np.ndarray) -> mi.Texture2f:
    a = np.ascontiguousarray(array if array.ndim == 3 else array[:, :, None], np.float32)
    return mi.Texture2f(mi.TensorXf(a), filter_mode=dr.FilterMode.Linear,
                        wrap_mode=dr.WrapMode.Clamp)


def restore(low, displacement_map, levels: int | None = 2, split: int | None = None,
            keep_holes: bool = True) -> Restored:
    """Restore the detailed mesh from a low-poly and a baked map.

    Args:
        low: low-poly with UVs (path or :class:`MeshData`), the ``low.obj`` the baker wrote.
        displacement_map: path of a map with its sidecar, or the dict of
            :func:`formats.read_map` (``displacement`` (H, W) [object units], optional
            ``direction_tangent`` (H, W, 3)).
        levels, split: subdivision (see :func:`edge_splits`).
        keep_holes: on an open low-poly, drop faces with two or three vertices over texels
            where the bake found no high-poly (the map's validity mask ``valid.png``): holes
            of the original stay open.  A closed low-poly never loses a face (step 4 above).
    """
    L = edge_splits(levels, split)
    low = low if isinstance(low, MeshData) else load_mesh(low, "low-poly")
    if low.uvs is None:
        raise ValueError("low: the low-poly has no UVs; restore from the low.obj the baker wrote")
    decoded = displacement_map if isinstance(displacement_map, dict) else formats.read_map(displacement_map)
    disp = decoded.get("displacement")
    if disp is None:
        raise ValueError("map: holds no displacement (a pure normal map cannot restore geometry)")
    meta, dirs = decoded.get("meta"), decoded.get("direction_tangent")
    if meta is not None:  # a map file: its sidecar says how the bake measured
        if meta.get("low_faces") not in (None, len(low.faces)):
            raise ValueError(f"low: the map was baked over a low-poly with {meta['low_faces']:,} "
                             f"faces, this one has {len(low.faces):,}; pass the low.obj the "
                             "baker wrote beside the map")
        if meta.get("cage") and dirs is None:
            raise ValueError(f"map: baked along a cage ({meta['cage']}) but format "
                             f"{meta['format']!r} stores no direction; restore from dir24_d8, "
                             "dir16_d16 or float")
        if not meta.get("cage"):
            dirs = None   # measured along the normal: the stored direction is z, up to quantisation
    elif dirs is not None and np.allclose(dirs[..., 2], 1.0):
        dirs = None
    if not np.all(np.isfinite(disp)):
        raise ValueError("map: displacement has NaN/Inf texels")
    faces_out = len(low.faces) * L * L
    if faces_out > 2 * MAX_VERTICES:
        raise ValueError(f"levels: {faces_out:,} triangles exceed the limit of {2 * MAX_VERTICES:,}")
    start = time.perf_counter()
    normals = low.normals()
    weld = weld_ids(low.positions)
    src, bary, group, new_faces = subdivision_topology(low.faces, weld, L)
    idx = [mi.UInt32(src[:, k]) for k in range(3)]
    wts = [mi.Float(bary[:, k]) for k in range(3)]

    def interp(cls, data):
        arr = cls(*[mi.Float(np.ascontiguousarray(data[:, k], np.float32)) for k in range(data.shape[1])])
        return sum((gather(cls, arr, idx[k]) * wts[k] for k in (1, 2)), gather(cls, arr, idx[0]) * wts[0])

    p = mi.Point3f(interp(mi.Vector3f, low.positions))
    n_raw = interp(mi.Vector3f, normals)
    n = dr.normalize(n_raw)
    uv = mi.Point2f(interp(mi.Vector2f, low.uvs))
    lookup = mi.Point2f(uv.x, 1.0 - uv.y)          # image row 0 holds v = 1
    direction = n
    if dirs is not None:
        t_v, s_v = vertex_tangents(low.faces, *mikktspace(low.positions, low.faces, normals, low.uvs),
                                   len(low.positions))
        t = interp(mi.Vector3f, t_v)
        b = dr.sign(interp(mi.Vector2f, np.stack([s_v, s_v], 1)).x) * dr.cross(n_raw, t)
        x = _texture(dirs).eval(lookup)
        direction = dr.normalize(x[0] * t + x[1] * b + x[2] * n_raw)
    groups = mi.UInt32(group)
    n_groups = int(group.max()) + 1
    count = dr.zeros(mi.Float, n_groups)
    dr.scatter_add(count, 1.0, groups)
    state = DisplaceState(p, direction, lookup, groups, count, n_groups)
    offset = np.stack([np.asarray(c) for c in state.offsets(
        mi.TensorXf(np.ascontiguousarray(disp[:, :, None], np.float32)))], 1)     # (G, 3)
    edges = edge_counts(low.faces, weld)
    report = {"closed": edges["boundary_edges"] == 0, **edges, "void_vertices": 0,
              "dropped_faces": 0, "holes": "no validity mask"}
    if decoded.get("valid") is not None:
        # alias classes over texels where the bake found no high-poly
        vsum = dr.zeros(mi.Float, n_groups)
        dr.scatter_add(vsum, _texture(decoded["valid"]).eval(lookup)[0], groups)
        void_g = np.asarray(vsum) / np.asarray(count) < 0.5
        void = void_g[group]
        report["void_vertices"] = int(void.sum())
        if report["closed"] or not keep_holes:
            offset = _fill_from_neighbours(offset, void_g, group[new_faces])
            state.fixed = mi.Bool(void_g)
            state.fixed_offset = mi.Vector3f(*[mi.Float(np.ascontiguousarray(offset[:, k], np.float32))
                                               for k in range(3)])
            report["holes"] = ("kept and filled: void vertices take the harmonic interpolation of "
                               "their measured neighbours' displacement (none: the low-poly position)")
        else:   # open low-poly: drop faces made mostly of void vertices (holes of the original)
            keep = void[new_faces].sum(1) < VOID_CORNERS
            report["dropped_faces"] = int((~keep).sum())
            report["holes"] = "dropped: faces with 2 or 3 void vertices (open low-poly)"
            new_faces = new_faces[keep]
            if len(new_faces) == 0:
                raise ValueError("map: its validity mask marks every texel as void (nothing to restore)")
    state.faces = mi.Vector3u(*[mi.UInt32(new_faces[:, k]) for k in range(3)])
    state.normals = n
    p, nrm = state.displace(mi.TensorXf(np.ascontiguousarray(disp[:, :, None], np.float32)))
    dr.eval(p, nrm, uv)
    out = Restored(np.stack([np.asarray(c) for c in p], 1), new_faces,
                   np.stack([np.asarray(c) for c in nrm], 1), np.stack([np.asarray(c) for c in uv], 1),
                   time.perf_counter() - start, report, state)
    if not (np.all(np.isfinite(out.positions)) and np.all(np.isfinite(out.normals))):
        raise ValueError("restore: the restored mesh has NaN/Inf vertices (check the map)")
    return out


def _fill_from_neighbours(offset: np.ndarray, void: np.ndarray, group_faces: np.ndarray) -> np.ndarray:
    """Displacement vectors (G, 3) of the ``void`` alias classes replaced by the harmonic
    interpolation of the measured ones around them (the graph Laplacian of the restored mesh's
    edges solved over the void classes, SciPy sparse; a void region with no measured class
    around it stays at the low-poly position)."""
    if not void.any():
        return offset
    from scipy.sparse import coo_matrix, diags
    from scipy.sparse.linalg import spsolve

    G = len(offset)
    a, b = group_faces.ravel(), np.roll(group_faces, -1, axis=1).ravel()
    adj = coo_matrix((np.ones(2 * len(a)), (np.r_[a, b], np.r_[b, a])), shape=(G, G)).tocsr()
    adj.data[:] = 1.0                                    # an edge shared by two faces counts once
    lap = diags(np.asarray(adj.sum(1)).ravel()) - adj
    v, k = np.flatnonzero(void), np.flatnonzero(~void)
    # a tiny pull towards 0 keeps void regions without measured neighbours solvable (they stay 0)
    system = (lap[v][:, v] + 1e-9 * diags(np.ones(len(v)))).tocsc()
    rhs = -(lap[v][:, k] @ offset[k])
    out = offset.copy()
    out[v] = np.asarray(spsolve(system, rhs)).reshape(len(v), 3)
    return out


def low_for_map(map_path: str | os.PathLike) -> str:
    """The low-poly file a map's sidecar names (resolved beside the map)."""
    meta = formats.read_metadata(map_path)
    if "low" not in meta:
        raise ValueError(f"map {str(map_path)!r}: its metadata names no low-poly; pass --low")
    return os.path.join(os.path.dirname(meta["_path"]), meta["low"])
