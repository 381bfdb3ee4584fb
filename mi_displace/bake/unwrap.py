"""Inputs the paper assumes but users lack (§1.3, §3.1): UVs and a low-poly model.

* :func:`unwrap` — the low-poly has no texture mapping: xatlas charts and packs it (an
  unambiguous, non-overlapping atlas, the paper's mapping (2) of Fig. 6).  Seam vertices are
  duplicated (twins share a position; restoration welds them through alias ids).
* :func:`make_low_poly` — no low-poly at all: smooth the high-poly first ("a few passes of a
  surface smoothing algorithm before reducing the number of polygons", §1.3; Taubin
  lambda/mu smoothing, which does not shrink), then reduce it with fast-simplification
  (quadric edge collapse) to ``target_faces``.
"""
from __future__ import annotations

import numpy as np

from mi_displace.bake.meshdata import MeshData, check_mesh, defect_summary, face_defects


def unwrap(mesh: MeshData, padding: int = 2, resolution: int = 1024) -> MeshData:
    """Chart and pack UVs with xatlas.

    Args:
        mesh: the low-poly (its own UVs, if any, are replaced).
        padding: texels between charts in the atlas (xatlas PackOptions.padding).
        resolution: atlas resolution xatlas packs for [texels].

    Returns:
        A new MeshData with duplicated seam vertices and ``uvs`` in [0, 1]^2.
    """
    import xatlas

    atlas = xatlas.Atlas()
    atlas.add_mesh(mesh.positions.astype(np.float32), mesh.faces.astype(np.uint32))
    pack = xatlas.PackOptions()
    pack.padding = int(padding)
    pack.resolution = int(resolution)
    pack.bilinear = True
    atlas.generate(pack_options=pack)
    vmapping, indices, uvs = atlas[0]
    out = MeshData(mesh.positions[vmapping], indices.astype(np.int64), uvs.astype(np.float32),
                   name=mesh.name, notes=mesh.notes + [
                       f"unwrapped with xatlas ({atlas.chart_count} charts, padding {padding} "
                       f"texels at {resolution}^2)"])
    return check_mesh(out, "unwrapped low-poly")


def make_low_poly(high: MeshData, target_faces: int = 5000, smoothing_iterations: int = 10) -> MeshData:
    """A low-poly model from the high-poly: Taubin smoothing, then quadric simplification.

    Args:
        high: the original mesh.
        target_faces: wanted triangle count (>= 4, < the high-poly's count).
        smoothing_iterations: Taubin passes before reduction (0 = none).
    """
    import fast_simplification
    import trimesh

    if int(target_faces) != target_faces or target_faces < 4:
        raise ValueError(f"target_faces: must be an integer >= 4, got {target_faces!r}")
    if target_faces >= len(high.faces):
        raise ValueError(f"target_faces: {target_faces} is not below the high-poly's "
                         f"{len(high.faces)} triangles")
    if int(smoothing_iterations) != smoothing_iterations or smoothing_iterations < 0:
        raise ValueError(f"smoothing_iterations: must be an integer >= 0, got {smoothing_iterations!r}")
    tm = trimesh.Trimesh(high.positions.astype(np.float64), high.faces, process=True)
    if smoothing_iterations:
        trimesh.smoothing.filter_taubin(tm, lamb=0.5, nu=0.53, iterations=int(smoothing_iterations))
    reduction = 1.0 - target_faces / len(tm.faces)
    points, faces = fast_simplification.simplify(tm.vertices, tm.faces, target_reduction=reduction)
    notes = [f"made from the high-poly: {smoothing_iterations} Taubin smoothing passes, "
             f"fast-simplification to {len(faces)} triangles"]
    # a decimation can leave faces no 2-manifold has: drop them (and the vertices only they use)
    defects = face_defects(points.astype(np.float32), faces)
    if any(len(f) for f in defects.values()):
        faces = np.delete(faces, np.concatenate(list(defects.values())), axis=0)
        notes.append(f"removed {defect_summary(defects)}")
    keep = np.unique(faces)
    remap = np.full(len(points), -1)
    remap[keep] = np.arange(len(keep))
    low = MeshData(points[keep].astype(np.float32), remap[faces].astype(np.int64), None,
                   name=f"{high.name}_low", notes=notes)
    return check_mesh(low, "simplified low-poly")
