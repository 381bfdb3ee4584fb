"""Triangle meshes of the baker: loading, welding, smooth normals and the tangent frame.

A :class:`MeshData` holds NumPy arrays (one-off preprocessing; per-texel work is Dr.Jit):
``positions`` (V, 3) float32 [object units], ``faces`` (F, 3) int64, ``uvs`` (V, 2) float32
or ``None``.  UVs follow the OBJ / Blender / glTF-after-flip convention: *v points up*, so
image row 0 (the top of a PNG) holds v = 1 (texel (col c, row r) has its centre at
u = (c + 0.5) / W, v = 1 - (r + 0.5) / H).

Normals are always recomputed here from the welded geometry (area-weighted face normals
summed over every vertex at the same position), so UV-seam twins
(same position, different UV) get the same normal in the baker and in restoration (§5:
"alias information is used to restore smooth model normals").

Tangents are exact MikkTSpace (:mod:`mi_displace.bake.mikktspace`), per face corner.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf")


@dataclass
class MeshData:
    """A triangle mesh (NumPy).  Shapes: positions (V,3) f32, faces (F,3) i64, uvs (V,2) f32."""

    positions: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None = None
    name: str = "mesh"
    notes: list = field(default_factory=list)

    @property
    def diagonal(self) -> float:
        """Bounding-box diagonal [object units]."""
        return float(np.linalg.norm(self.positions.max(0) - self.positions.min(0)))

    def normals(self) -> np.ndarray:
        """(V, 3) float32 unit vertex normals from the welded geometry."""
        return vertex_normals(self.positions, self.faces)

    def to_trimesh(self):
        import trimesh

        return trimesh.Trimesh(self.positions.astype(np.float64), self.faces, process=False)


def check_mesh(mesh: MeshData, what: str) -> MeshData:
    """Validate shapes, indices and finiteness; raise ValueError naming ``what``."""
    p, f = np.asarray(mesh.positions), np.asarray(mesh.faces)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3:
        raise ValueError(f"{what}: positions must have shape (V >= 3, 3), got {p.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise ValueError(f"{what}: faces must have shape (F > 0, 3), got {f.shape}")
    if f.min() < 0 or f.max() >= len(p):
        raise ValueError(f"{what}: face indices must lie in [0, {len(p)})")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{what}: {int((~np.isfinite(p)).sum())} NaN/Inf vertex coordinates")
    if mesh.uvs is not None:
        uv = np.asarray(mesh.uvs)
        if uv.shape != (len(p), 2) or not np.all(np.isfinite(uv)):
            raise ValueError(f"{what}: UVs must be finite with shape ({len(p)}, 2), got {uv.shape}")
    area = np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1)
    if not area.sum() > 0:
        raise ValueError(f"{what}: the mesh has zero surface area")
    mesh.positions = p.astype(np.float32)
    mesh.faces = f.astype(np.int64)
    return mesh


def load_mesh(path: str | os.PathLike, what: str = "mesh") -> MeshData:
    """Read a triangle mesh (OBJ, PLY, OFF, STL, glTF) with trimesh, keeping UVs if present.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: unknown suffix, unreadable file, no triangles, NaN vertices.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} file {str(path)!r} does not exist")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(f"{what} file {str(path)!r}: suffix must be one of {', '.join(MESH_SUFFIXES)}")
    try:
        tm = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds on garbage input
        raise ValueError(f"{what} file {str(path)!r} could not be read as a mesh: {e}") from None
    if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
        raise ValueError(f"{what} file {str(path)!r} holds no triangles")
    uv = getattr(tm.visual, "uv", None)
    uvs = None if uv is None or len(uv) != len(tm.vertices) else np.asarray(uv, np.float32)
    return check_mesh(MeshData(np.asarray(tm.vertices, np.float32), np.asarray(tm.faces, np.int64),
                               uvs, name=path.stem), f"{what} file {str(path)!r}")


def _lines(fmt: str, rows: np.ndarray) -> str:
    """``fmt`` applied to every row of ``rows`` (N, k) in one C-level formatting call."""
    return (fmt * len(rows)) % tuple(rows.ravel().tolist())


def save_obj(path: str | os.PathLike, positions, faces, uvs=None, normals=None) -> Path:
    """Write an OBJ (exact float32 round trip: 9 significant digits) with optional vt / vn.

    Positions are written once each (``v``; UV-seam twins, vertices at the same position
    with different UVs and equal normals, share one) with UVs per face corner
    (``f v/vt/vn``), as OBJ allows: Blender and other importers see one connected surface
    instead of pieces cut at every seam.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    p = np.asarray(positions, np.float32)
    faces = np.asarray(faces, np.int64)
    key = p if normals is None else np.concatenate([p, np.asarray(normals, np.float32)], 1)
    _, first, shared = np.unique(key + np.float32(0), axis=0, return_index=True, return_inverse=True)
    shared = shared.ravel()
    fv, ft = shared[faces] + 1, faces + 1
    parts = [_lines("v %.9g %.9g %.9g\n", p[first])]
    if uvs is not None:
        parts.append(_lines("vt %.9g %.9g\n", np.asarray(uvs, np.float32)))
    if normals is not None:
        parts.append(_lines("vn %.6g %.6g %.6g\n", np.asarray(normals, np.float32)[first]))
    if uvs is not None and normals is not None:
        parts.append(_lines("f %d/%d/%d %d/%d/%d %d/%d/%d\n", np.stack([fv, ft, fv], 2).reshape(-1, 9)))
    elif uvs is not None:
        parts.append(_lines("f %d/%d %d/%d %d/%d\n", np.stack([fv, ft], 2).reshape(-1, 6)))
    elif normals is not None:
        parts.append(_lines("f %d//%d %d//%d %d//%d\n", np.stack([fv, fv], 2).reshape(-1, 6)))
    else:
        parts.append(_lines("f %d %d %d\n", fv))
    path.write_text("".join(parts))
    return path


def weld_ids(positions: np.ndarray) -> np.ndarray:
    """(V,) alias id of every vertex: twins at bit-identical float32 positions share one (§5)."""
    _, inverse = np.unique(np.asarray(positions, np.float32), axis=0, return_inverse=True)
    return inverse.ravel()


def edge_counts(faces: np.ndarray, weld: np.ndarray) -> dict:
    """Boundary (one face) and non-manifold (three or more faces) edges of a mesh, counted on
    welded vertices (``weld``: (V,) position class), so UV seams are not boundaries."""
    w = np.asarray(weld, np.int64)[np.asarray(faces, np.int64)]
    e = np.sort(np.stack([w, np.roll(w, -1, axis=1)], 2).reshape(-1, 2), axis=1)
    _, count = np.unique(e[:, 0] * (int(w.max()) + 1) + e[:, 1], return_counts=True)
    return {"boundary_edges": int((count == 1).sum()), "non_manifold_edges": int((count > 2).sum())}


def face_defects(positions: np.ndarray, faces: np.ndarray, area_rel: float = 1e-12) -> dict:
    """Faces that break a 2-manifold, on welded vertices (UV-seam twins are one vertex).

    Returns:
        dict of int64 face-index arrays: ``duplicate`` (the same three vertices in the same
        winding as an earlier face: all but the first), ``back_to_back`` (the same three
        vertices in both windings: every face of such a set; a flap or a double-sided
        pocket), ``zero_area`` (area <= ``area_rel`` x the bounding-box diagonal squared).
    """
    p = np.asarray(positions, np.float64)
    w = weld_ids(positions)[np.asarray(faces, np.int64)]
    first = np.argmin(w, axis=1)
    rolled = np.take_along_axis(w, (first[:, None] + np.arange(3)) % 3, axis=1)
    winding = rolled[:, 1] < rolled[:, 2]          # the cyclic order from the smallest vertex
    _, group, count = np.unique(np.sort(w, axis=1), axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    both = np.zeros(len(count), bool)
    wound = np.zeros((len(count), 2), bool)
    wound[group, winding.astype(np.int64)] = True
    both = wound.all(1)
    order = np.lexsort((np.arange(len(w)), group))
    repeat = np.zeros(len(w), bool)
    repeat[order[1:]] = group[order[1:]] == group[order[:-1]]
    area = np.linalg.norm(np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]]), axis=1) / 2
    diagonal2 = float(np.sum((p.max(0) - p.min(0)) ** 2))
    return {"duplicate": np.flatnonzero(repeat & ~both[group]),
            "back_to_back": np.flatnonzero(both[group]),
            "zero_area": np.flatnonzero(area <= area_rel * diagonal2)}


def defect_summary(defects: dict, limit: int = 10) -> str:
    """``defects`` of :func:`face_defects` as one phrase naming the first ``limit`` faces of
    each kind ('' when there are none)."""
    parts = []
    for kind, faces in defects.items():
        if len(faces):
            named = ", ".join(str(f) for f in faces[:limit]) + (", ..." if len(faces) > limit else "")
            parts.append(f"{len(faces)} {kind.replace('_', '-')} (faces {named})")
    return "; ".join(parts)


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) float32 area-weighted vertex normals, summed over welded twins (alias buffer)."""
    p = np.asarray(positions, np.float64)
    fn = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    weld = weld_ids(positions)
    acc = np.zeros((weld.max() + 1, 3))
    for k in range(3):
        np.add.at(acc, weld[faces[:, k]], fn)
    n = acc[weld]
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.maximum(length, 1e-300), [0.0, 0.0, 1.0]).astype(np.float32)


def uv_triangle_stats(uvs: np.ndarray, faces: np.ndarray) -> dict:
    """Counts of degenerate (zero UV area) and flipped (negative UV area) triangles."""
    a = uvs[faces[:, 1]] - uvs[faces[:, 0]]
    b = uvs[faces[:, 2]] - uvs[faces[:, 0]]
    area = 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    return {"uv_degenerate_triangles": int((np.abs(area) < 1e-14).sum()),
            "uv_flipped_triangles": int((area < -1e-14).sum()),
            "uv_outside_unit_square": int(((uvs < 0) | (uvs > 1)).any(1).sum()),
            "uv_area_sum": float(np.abs(area).sum())}
