"""``<shape type="displaced">``: a base surface displaced along its normal by a height texture.

.. code-block:: xml

    <shape type="displaced">
        <string name="base" value="sphere"/>      <!-- plane | sphere | cylinder | torus | mesh -->
        <float name="radius" value="1"/>           <!-- sphere, cylinder -->
        <texture type="ripples" name="height"/>    <!-- any texture; h in texture units -->
        <float name="scale" value="0.1"/>          <!-- object units per unit height -->
        <float name="midlevel" value="0"/>         <!-- height with zero displacement -->
        <integer name="resolution" value="256"/>   <!-- cells along u (or edge_length) -->
        <bsdf type="diffuse"/>
    </shape>

Mesh bases: ``base="mesh"`` with ``filename`` (PLY/OBJ with UVs) and ``subdivision`` (edge
splits per triangle) or ``edge_length``.  Meshes without UVs are refused (unwrap them
first, e.g. with ``mi_displace.bake.unwrap.unwrap`` (xatlas)).  ``scale`` and ``midlevel`` are editable through
``mi.traverse`` (re-displacement keeps the topology).
"""
from __future__ import annotations

import math
import time
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces, tessellate
from mi_displace.core.mesh_io import load_uv_mesh
from mi_displace.core.texture_height import check_texture_finite, height_function
from mi_displace.core.thickness import crossing_check, crossing_warning

BASE_PARAMS = {
    "plane": (),
    "sphere": ("radius",),
    "cylinder": ("radius", "length"),
    "torus": ("major_radius", "minor_radius"),
}


def _mesh_level(mesh_data, props, edge_length) -> int:
    """Edge splits per base triangle: ``subdivision`` or from ``edge_length``."""
    if edge_length is not None:
        if not edge_length > 0:
            raise ValueError(f"displaced: 'edge_length' must be > 0, got {edge_length}")
        pos, faces = mesh_data[0], mesh_data[3]
        mean_edge = float(np.mean(np.linalg.norm(pos[faces] - pos[np.roll(faces, 1, 1)], axis=2)))
        level = max(1, math.ceil(mean_edge / edge_length))
    else:
        level = props.get("subdivision", 1)
        if int(level) != level or level < 1:
            raise ValueError(f"displaced: 'subdivision' must be a positive integer, got {level}")
    faces = len(mesh_data[3]) * int(level) ** 2
    if faces > 2 * tessellate.MAX_VERTICES:
        raise ValueError(f"displaced: subdivision level {level} gives {faces:,} triangles, more "
                         f"than the limit of {2 * tessellate.MAX_VERTICES:,}; lower "
                         "'subdivision' or raise 'edge_length'")
    return int(level)


def _build(base, mesh_data, grid, height_texture, scale, midlevel) -> tessellate.Tessellation:
    """Tessellate a parametric (``grid`` = (nu, nv)) or mesh (``grid`` = level) base."""
    if base is not None:
        nu, nv = grid
        height = None if height_texture is None else height_function(
            height_texture, 0.5 / max(nu, nv))
        return tessellate.displace_parametric(base, height, scale, midlevel, nu, nv)
    height = None if height_texture is None else height_function(height_texture, 1e-3 / grid)
    return tessellate.displace_mesh(*mesh_data, height, scale, midlevel, grid)


class Displaced(mi.Mesh):
    """True displacement: a tessellated mesh P = S + scale (h - midlevel) n."""

    def __init__(self, props: mi.Properties):
        base_name = props.get("base", "mesh" if "filename" in props else "sphere")
        height = props.get("height", None)
        if height is not None and not isinstance(height, mi.Texture):
            raise ValueError("displaced: 'height' must be a nested texture")
        scale = float(props.get("scale", 0.1))
        midlevel = float(props.get("midlevel", 0.0))
        for key, val in (("scale", scale), ("midlevel", midlevel)):
            if not math.isfinite(val):
                raise ValueError(f"displaced: '{key}' must be finite, got {val}")
        resolution = props.get("resolution", None)
        edge_length = props.get("edge_length", None)
        # load_dict/XML hand over a double-precision transform; the mesh is float32
        to_world = mi.ScalarTransform4f(mi.ScalarMatrix4f(np.array(
            props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float32)))
        if height is not None:
            check_texture_finite(height)

        if base_name == "mesh":
            if "filename" not in props:
                raise ValueError("displaced: base 'mesh' needs a 'filename' (PLY/OBJ with UVs)")
            mesh_data = load_uv_mesh(props.get("filename"))
            base, grid = None, _mesh_level(mesh_data, props, edge_length)
        else:
            base = surfaces.make_base(
                base_name, **{k: float(props.get(k)) for k in BASE_PARAMS.get(base_name, ())
                              if k in props})
            mesh_data, grid = None, tessellate.grid_resolution(base, resolution, edge_length)
        start = time.perf_counter()
        t = _build(base, mesh_data, grid, height, scale, midlevel)
        super().__init__(props.id() or "displaced", t.vertex_count, t.face_count, props,
                         True, True)
        self.base, self.mesh_data, self.grid = base, mesh_data, grid
        self.height_texture, self.to_world = height, to_world
        self.scale, self.midlevel = mi.Float(scale), mi.Float(midlevel)
        self._upload(t, start)

    def _upload(self, t: tessellate.Tessellation, start: float) -> None:
        """Write the tessellation into the mesh buffers (object -> world) and check it."""
        to_world = mi.Transform4f(self.to_world)
        positions = to_world @ t.positions
        normals = dr.normalize(to_world @ mi.Normal3f(t.normals))
        params = mi.traverse(self)
        params["vertex_positions"] = dr.ravel(positions)
        params["vertex_normals"] = dr.ravel(normals)
        params["vertex_texcoords"] = dr.ravel(t.texcoords)
        params["faces"] = dr.ravel(t.faces)
        params.update()
        finite = dr.all(dr.isfinite(params["vertex_positions"])) & dr.all(
            dr.isfinite(params["vertex_normals"]))
        if not finite[0]:
            raise ValueError(f"displaced: tessellation of {self.id()!r} produced NaN/Inf "
                             "(check the height texture and 'scale')")
        v, f = t.vertex_count, t.face_count
        tessellate_s = time.perf_counter() - start
        check = (crossing_check(t, thickness=self.base.thickness()) if self.base is not None
                 else crossing_check(t, base_mesh=(self.mesh_data[0], self.mesh_data[3])))
        message = crossing_warning(f"displaced {self.id()!r}", check)
        if message:
            warnings.warn(message, stacklevel=2)
        self.build_stats = {"tessellate_s": tessellate_s, "vertices": v, "faces": f,
                            "bytes": v * 8 * 4 + f * 3 * 4,
                            "crossing_vertices": check["crossing_vertices"],
                            "warnings": [message] if message else []}

    def traverse(self, cb):
        super().traverse(cb)
        cb.put("scale", self.scale, mi.ParamFlags.NonDifferentiable)
        cb.put("midlevel", self.midlevel, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=[]):
        if "scale" in keys or "midlevel" in keys:
            start = time.perf_counter()
            self._upload(_build(self.base, self.mesh_data, self.grid, self.height_texture,
                                self.scale[0], self.midlevel[0]), start)
        else:
            super().parameters_changed(keys)

    def to_string(self):
        s = self.build_stats
        return (f"Displaced[base={self.base.name if self.base else 'mesh'}, "
                f"vertices={s.get('vertices')}, faces={s.get('faces')}]")


def register():
    mi.register_shape("displaced", lambda props: Displaced(props))
