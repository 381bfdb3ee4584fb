"""``<shape type="restored">``: a low-poly restored with a baked displacement map (paper 003 §5).

(:data:`SPEC` declares its parameters.)

The mesh is built by :func:`mi_displace.bake.restore.restore` (Dr.Jit subdivision and
displacement, alias-welded seams, recomputed normals) and uploaded into this ``mi.Mesh``.
``levels="auto"`` derives the levels from the map resolution and the projected size through
the sensors (:mod:`mi_displace.bake.levels`): the referenced ones, else the scene's, given by
``fit_to_sensors(sensors)`` (:func:`mi_displace.fit_to_sensors` calls it; so do the mi-displace loaders);
until then from the map alone.  ``build_stats`` (a dict) holds levels, why, faces,
vertices, bytes and seconds.

``displacement`` (the map's texels, a (H, W, 1) tensor [object units]) is exposed through
``mi.traverse`` as differentiable: an edit re-displaces the mesh (never stale), and with a
gradient enabled the vertex positions and normals carry it (refine a bake against images).
"""
from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake import formats
from mi_displace.bake.levels import auto_levels
from mi_displace.bake.meshdata import load_mesh
from mi_displace.bake.restore import MAX_SPLIT, edge_splits, low_for_map, restore
from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.plugins._guard import constructor, take_sensors

SPEC = PluginSpec(
    "restored", "shape",
    "A low-poly restored with a baked displacement map (paper 003 §5): subdivided (1 -> 4 "
    "rounds, or a uniform 1 -> N² split), displaced along the interpolated normal by the "
    "map, seams welded across UV-chart aliases and normals recomputed.  `levels=\"auto\"` "
    "derives the rounds from the map resolution and the projected size through the sensors "
    "(those referenced with `<ref id=\"...\"/>`, else the scene's, given by "
    "`mi_displace.fit_to_sensors`).  `traverse` exposes `displacement` (the map's texels, a "
    "(H, W, 1) tensor in object units; editable, differentiable: an edit re-displaces the mesh).",
    (
        Param("map", "string", REQUIRED, "a baked map with its .json sidecar"),
        Param("low", "string", None, "the low-poly (default: the one the map's sidecar names)"),
        Param("levels", "int", 2, "subdivision rounds (1 -> 4 triangles each)", low=0, high=6, auto=True),
        Param("split", "int", None, "instead of `levels`: a uniform 1 -> N² split", low=1, high=MAX_SPLIT),
        Param("dicing_rate", "float", 1.0, "`levels=auto`: pixels per micro-edge", unit="px",
              low=0, open_low=True),
        Param("keep_holes", "bool", True, "open low-polys: drop the faces over void texels"),
    ),
    example="""<shape type="restored">
    <string name="map" value="parts/bake_bunny/d16.png"/>
    <integer name="levels" value="1"/>
    <bsdf type="diffuse"/>
</shape>""",
    nested="one `bsdf`; sensors (`<ref id=\"camera\"/>`) for `levels=auto`",
    stats="levels, split, rule (and the inputs of an auto rule), vertices, faces, bytes, "
          "restore_s, build_s and the restore report",
    limits="The map's sidecar must describe the low-poly (same UVs); `levels=auto` before "
           "`fit_to_sensors` sizes from the map alone.",
)


class Restored(mi.Mesh):
    """Low-poly + map -> subdivided, displaced triangle mesh (object units of the low-poly)."""

    def __init__(self, props: mi.Properties, values: dict):
        self.sensors = take_sensors(props)   # the sensors referenced for levels="auto"
        resolver = mi.file_resolver()   # paths relative to the scene file
        self.map_path = str(resolver.resolve(values["map"]))
        low = str(resolver.resolve(values["low"])) if values["low"] is not None else low_for_map(self.map_path)
        levels = values["levels"]
        self.auto = levels == "auto"
        self.split = values["split"]
        self.dicing_rate = values["dicing_rate"]
        self.keep_holes = values["keep_holes"]
        self.low = load_mesh(low, "low-poly")
        self.map_shape = (int(formats.read_metadata(self.map_path)["height"]),
                          int(formats.read_metadata(self.map_path)["width"]))
        self.to_world = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float64)
        if self.auto:
            self.levels, self.why = auto_levels(self.low, self.map_shape, self.sensors,
                                                self.to_world, self.dicing_rate)
        else:
            self.levels, self.why = levels, {"rule": "given"}
        edge_splits(self.levels, self.split)        # ValueError naming levels/split, before any kernel
        start = time.perf_counter()
        decoded = formats.read_map(self.map_path)
        out = restore(self.low, decoded, levels=self.levels, split=self.split,
                      keep_holes=self.keep_holes)
        super().__init__(props.id() or "restored", len(out.positions), len(out.faces), props, True, True)
        # the map's texels [object units], differentiable: edits re-displace the mesh
        self.displacement = mi.TensorXf(np.ascontiguousarray(decoded["displacement"][:, :, None], np.float32))
        self._upload(out, start)

    def traverse(self, cb):
        super().traverse(cb)
        cb.put("displacement", self.displacement, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=[]):
        if "displacement" not in keys:
            super().parameters_changed(keys)
            return
        if self.displacement.shape != (*self.map_shape, 1):
            raise ValueError(f"restored: 'displacement' must keep the map's shape "
                             f"{(*self.map_shape, 1)}, got {self.displacement.shape}")
        if not dr.all(dr.isfinite(dr.detach(self.displacement.array)))[0]:
            raise ValueError("restored: 'displacement' has NaN/Inf texels")
        p, n = self.state.displace(self.displacement)      # keeps the AD graph of the texels
        to_world = mi.Transform4f(mi.ScalarTransform4f(mi.ScalarMatrix4f(self.to_world.astype(np.float32))))
        params = mi.traverse(self)
        params["vertex_positions"] = dr.ravel(to_world @ p)
        params["vertex_normals"] = dr.ravel(dr.normalize(to_world @ mi.Normal3f(n)))
        params.update()

    def _upload(self, out, start: float) -> None:
        to_world = mi.Transform4f(mi.ScalarTransform4f(mi.ScalarMatrix4f(self.to_world.astype(np.float32))))
        p = to_world @ mi.Point3f(*[mi.Float(np.ascontiguousarray(out.positions[:, k])) for k in range(3)])
        n = dr.normalize(to_world @ mi.Normal3f(*[mi.Float(np.ascontiguousarray(out.normals[:, k]))
                                                  for k in range(3)]))
        params = mi.traverse(self)
        params["vertex_positions"] = dr.ravel(p)
        params["vertex_normals"] = dr.ravel(n)
        params["vertex_texcoords"] = mi.Float(np.ascontiguousarray(out.uvs.ravel()))
        params["faces"] = mi.UInt32(np.ascontiguousarray(out.faces.ravel()))
        params.update()
        self.state = out.state
        V, F = len(out.positions), len(out.faces)
        self.build_stats = {"levels": self.levels, "split": self.split, **self.why,
                            "vertices": V, "faces": F, "bytes": V * 8 * 4 + F * 3 * 4,
                            "restore_s": out.seconds, "build_s": time.perf_counter() - start,
                            **out.report}

    def fit_to_sensors(self, sensors) -> bool:
        """``levels="auto"``: re-derive the levels for ``sensors`` (the scene's, unless the
        shape references its own) and rebuild if they changed; True if rebuilt."""
        if not self.auto or self.split is not None:
            return False
        levels, why = auto_levels(self.low, self.map_shape, self.sensors or list(sensors),
                                  self.to_world, self.dicing_rate)
        self.why = why
        if levels == self.levels:
            self.build_stats.update(why)
            return False
        self.levels = levels
        start = time.perf_counter()
        self._upload(restore(self.low, formats.read_map(self.map_path), levels=levels,
                             keep_holes=self.keep_holes), start)
        return True

    def to_string(self):
        return (f"Restored[levels={self.levels}, vertices={self.build_stats['vertices']}, "
                f"faces={self.build_stats['faces']}]")


def register():
    mi.register_shape("restored", constructor(SPEC, Restored))
