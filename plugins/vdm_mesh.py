"""``<shape type="vdm_mesh">``: a coarse base mesh that carries its curvature for VDM
(:data:`SPEC` declares its parameters).

It is the undisplaced base (the reference surface of the paper) as an ordinary triangle
mesh, plus per-vertex curvature tensors estimated *on this mesh* (the same estimator for
parametric and file bases; :mod:`mi_displace.vdm.mesh_curvature`), in the mesh's own
(object) space, stored as face attributes (``face_vdm_q*``: the second fundamental form in tile
coordinates as a linear function of uv; ``face_vdm_uv``: the faces' own uv Jacobian),
from which the ``vdm`` BSDF gets c_V and the world size of a tile per pixel — so instancing or a
``to_world`` scale changes nothing in tile units, and ``depth`` follows ``to_world`` as
``displaced``'s ``scale`` does.  On construction it hands the measured curvatures and tile size to its
``vdm`` BSDF, which builds its table over exactly that curvature range.

Design note: the curvature could be attached to any Mitsuba mesh with ``add_attribute``,
but the BSDF must learn the curvature range before the first kernel is traced, and a BSDF
cannot see its shape; a shape that owns the estimate and calls ``bsdf.attach`` solves both.
"""
from __future__ import annotations

import time
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces, tessellate
from mi_displace.core.mesh_io import load_uv_mesh
from mi_displace.core.properties import PluginSpec
from mi_displace.vdm import EXAMPLE_XML, mesh_curvature
from mi_displace.plugins._guard import constructor
from mi_displace.vdm.steps import FACE_FORMS

SPEC = PluginSpec(
    "vdm_mesh", "shape",
    "The undisplaced base of view-dependent displacement mapping (the paper's reference "
    "surface) as a coarse triangle mesh, with per-vertex curvature tensors estimated on this "
    "mesh (the same estimator for parametric and file bases).  On construction it hands the "
    "measured curvature range and tile size to its `vdm` BSDF, which builds its table for "
    "exactly that range.",
    (surfaces.base_param("sphere"), *surfaces.BASE_DIMENSIONS,
     surfaces.resolution_param(64, "grid cells along u (coarse: the BSDF adds the detail)"),
     surfaces.EDGE_LENGTH, surfaces.BASE_FILENAME),
    example=EXAMPLE_XML,
    nested="one `bsdf` (a `vdm`, `horizon` or `relief` BSDF receives the curvature range and "
           "tile size; any other renders the plain base)",
    stats="vertices, faces, curvature_min, curvature_max, build_s, and the attached BSDF's "
          "numeric stats",
    limits="The curvature is estimated per vertex on the mesh itself: a mesh whose faces share "
           "no vertex positions has none (warns); open meshes warn (front faces only).",
)


def _columns(v) -> np.ndarray:
    """(N, k) NumPy array of a Dr.Jit vector (scalar-literal components broadcast)."""
    n = dr.width(v)
    return np.stack([np.broadcast_to(np.asarray(c), (n,)) for c in v], 1)


def base_geometry(values: dict):
    """(positions, normals, uvs, faces) NumPy arrays of the undisplaced base (object space),
    from the read :data:`SPEC` ``values``."""
    name = surfaces.base_name("vdm_mesh", values, "sphere")
    if name == "mesh":
        return load_uv_mesh(values["filename"], "vdm_mesh")
    base = surfaces.make_base(name, **surfaces.base_params("vdm_mesh", name, values))
    nu, nv = tessellate.grid_resolution(base, values["resolution"], values["edge_length"])
    t = tessellate.displace_parametric(base, None, 0.0, 0.0, nu, nv)
    return (_columns(t.positions), _columns(t.normals), _columns(t.texcoords), _columns(t.faces))


class VDMMesh(mi.Mesh):
    """The coarse reference surface with per-vertex curvature tensors (attributes)."""

    def __init__(self, props: mi.Properties, values: dict):
        start = time.perf_counter()
        obj_pos, obj_nrm, uvs, faces = base_geometry(values)
        m = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float64)
        pos = obj_pos @ m[:3, :3].T + m[:3, 3]
        nrm = obj_nrm @ np.linalg.inv(m[:3, :3])
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm))):
            raise ValueError("vdm_mesh: the base has NaN/Inf positions or normals")
        super().__init__(props.id() or "vdm_mesh", len(pos), len(faces), props, True, True)
        params = mi.traverse(self)
        params["vertex_positions"] = mi.Float(pos.astype(np.float32).ravel())
        params["vertex_normals"] = mi.Float(nrm.astype(np.float32).ravel())
        params["vertex_texcoords"] = mi.Float(np.asarray(uvs, np.float32).ravel())
        params["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
        params.update()
        # curvature and tile size in the mesh's own (object) space, like `displaced`'s
        # scale: tile units do not change with to_world or an instance's transform
        K, c_max, c_min = mesh_curvature.curvature_tensors(obj_pos, obj_nrm, faces)
        self.curvature_warning = None
        if not (np.any(c_max != 0) or np.any(c_min != 0)) and mesh_curvature.is_curved(pos, faces):
            self.curvature_warning = (
                f"vdm_mesh {props.id() or ''!r}: the curvature estimate is zero everywhere on "
                "a curved mesh (no two faces share a vertex position?): VDM silhouettes and "
                "curvature will be missing; weld the mesh")
            warnings.warn(self.curvature_warning)
            mi.Log(mi.LogLevel.Warn, self.curvature_warning)
        self.open_warning = None
        if values["filename"] is not None and (edges := mesh_curvature.open_edge_count(obj_pos, faces)):
            self.open_warning = (
                f"vdm_mesh {props.id() or ''!r}: the mesh is open ({edges} boundary edges): "
                "vdm, horizon and relief shade front faces only, so a surface seen from behind "
                "(an open vase's inner wall) renders black; close the mesh, or give the inner "
                "side a shape of its own with a plain BSDF")
            warnings.warn(self.open_warning)
            mi.Log(mi.LogLevel.Warn, self.open_warning)
        self.c_max, self.c_min = c_max, c_min
        self.build_stats = {"vertices": len(pos), "faces": len(faces),
                            "curvature_min": float(c_min.min()), "curvature_max": float(c_max.max())}
        bsdf = self.bsdf()
        if hasattr(bsdf, "attach"):
            tiling = getattr(bsdf, "tiling", (1.0, 1.0))
            tile, spread = mesh_curvature.tile_scale(obj_pos, uvs, faces, tiling)
            forms = mesh_curvature.tile_forms(obj_pos, uvs, faces, K, tiling, tile)
            for key, name in FACE_FORMS.items():
                self.add_attribute(name, 3, mi.Float(forms[key].ravel()))
            bsdf.attach({"tile_size": tile, "tile_spread": spread, "c_max": c_max,
                         "c_min": c_min, "name": self.id(), "positions": pos, "faces": faces,
                         "scale": abs(float(np.linalg.det(m[:3, :3]))) ** (1 / 3)})
            self.build_stats.update({k: v for k, v in bsdf.stats.items()
                                     if isinstance(v, (int, float, bool))})
        self.build_stats["build_s"] = time.perf_counter() - start

    def to_string(self):
        return f"VDMMesh[vertices={self.vertex_count()}, faces={self.face_count()}]"


def register():
    mi.register_shape("vdm_mesh", constructor(SPEC, VDMMesh))
