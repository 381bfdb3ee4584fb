"""Model restoration (§5): subdivide the low-poly, displace the new vertices from the map.

1. **Subdivision** (Fig. 10) — ``levels`` rounds of 1 -> 4 midpoint subdivision, i.e. every
   triangle split into 4^levels on a barycentric grid (:func:`tessellate.subdivision_topology`
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
4. **Holes** — faces with at least two of three vertices sampling "void" in the bake's validity mask
   (no high-poly within reach: a hole of the original) are dropped.
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
from mi_displace.bake.meshdata import MeshData, load_mesh, save_obj, weld_ids
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
        keep_holes: drop faces with two or three vertices over texels where the bake found no
            high-poly (the map's validity mask ``valid.png``): holes of the original stay open.
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
    d = _texture(disp).eval(lookup)[0]
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
    total = dr.zeros(mi.Vector3f, n_groups)        # alias buffer: one displacement per class
    count = dr.zeros(mi.Float, n_groups)
    scatter_add(total, d * direction, groups)
    dr.scatter_add(count, 1.0, groups)
    p = p + gather(mi.Vector3f, total, groups) / dr.gather(mi.Float, count, groups)
    if decoded.get("valid") is not None and keep_holes:
        # vertices over texels where the bake found no high-poly; drop faces made only of them
        vsum = dr.zeros(mi.Float, n_groups)
        dr.scatter_add(vsum, _texture(decoded["valid"]).eval(lookup)[0], groups)
        void = np.asarray(dr.gather(mi.Float, vsum, groups) / dr.gather(mi.Float, count, groups)) < 0.5
        new_faces = new_faces[void[new_faces].sum(1) < VOID_CORNERS]
        if len(new_faces) == 0:
            raise ValueError("map: its validity mask marks every texel as void (nothing to restore)")
    f = mi.Vector3u(*[mi.UInt32(new_faces[:, k]) for k in range(3)])
    nrm = face_weighted_normals(p, f, groups, n_groups, n)
    dr.eval(p, nrm, uv)
    out = Restored(np.stack([np.asarray(c) for c in p], 1), new_faces,
                   np.stack([np.asarray(c) for c in nrm], 1), np.stack([np.asarray(c) for c in uv], 1),
                   time.perf_counter() - start)
    if not (np.all(np.isfinite(out.positions)) and np.all(np.isfinite(out.normals))):
        raise ValueError("restore: the restored mesh has NaN/Inf vertices (check the map)")
    return out


def low_for_map(map_path: str | os.PathLike) -> str:
    """The low-poly file a map's sidecar names (resolved beside the map)."""
    meta = formats.read_metadata(map_path)
    if "low" not in meta:
        raise ValueError(f"map {str(map_path)!r}: its metadata names no low-poly; pass --low")
    return os.path.join(os.path.dirname(meta["_path"]), meta["low"])
