"""``<shape type="ddm">``: a base surface tiled with copies of detail tiles through
T(u, v, w) = S(u, v) + n(u, v) w (DDM, eq. 1) or its geometry-image form (HDDM, eq. 2).

(:data:`SPEC` declares its parameters; ``docs/ddm.md`` describes them in depth.)  ``time``,
``height`` and ``tile_positions`` are editable and differentiable through ``mi.traverse``:
changing them re-maps the vertices (positions, normals) in place, keeping faces, geometry
images and tiles.
"""
from __future__ import annotations

import dataclasses
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces
from mi_displace.core.properties import Param, PluginSpec
from mi_displace.ddm import base_maps, charts, mapping, normals
from mi_displace.ddm.animation import Animation
from mi_displace.ddm.layout import LAYOUTS
from mi_displace.ddm.model import BASE_PARAMS, DDMConfig, DDMModel
from mi_displace.plugins._guard import constructor, take_sensors

_CONFIG, _ANIMATION = DDMConfig(), Animation()
_ANIMATION_DOCS = {
    "velocity_u": ("tile translation along u", "tile widths/time"),
    "velocity_v": ("tile translation along v", "tile heights/time"),
    "rotation_rate": ("tile rotation about its centre", "rad/time"),
    "w_amplitude": ("relative w scaling amplitude", ""),
    "w_frequency": ("frequency of the w scaling", "1/time"),
    "alpha0": ("metamorphosis alpha at t = 0 (eq. 3)", ""),
    "alpha_rate": ("metamorphosis alpha per time unit (eq. 3)", "1/time"),
}

SPEC = PluginSpec(
    "ddm", "shape",
    "Deformation-displacement mapping (DDM): a base surface tiled with copies of "
    "detail tiles through T(u, v, w) = S(u, v) + n(u, v) w (eq. 1), or its geometry-image form "
    "(HDDM, eq. 2) with `mode=maps`.  `traverse` also exposes `tile_positions` (the tiles' "
    "vertices; editable, differentiable): an edit of it, `time` or `height` re-maps the "
    "vertices in place, keeping faces, geometry images and tiles.",
    (
        surfaces.base_param(_CONFIG.base, (*BASE_PARAMS, "mesh")), *surfaces.BASE_DIMENSIONS,
        dataclasses.replace(surfaces.BASE_FILENAME, doc="base `mesh`: a PLY/OBJ with UVs; base "
                            "`teapot`: its Bezier patch file (default: the Utah teapot body)"),
        Param("tile", "string", _CONFIG.tile, "thorn | flower | chain | hair | hexagon | "
              "stone[:SEED] | a tile file (.obj/.ply), or a comma list of them"),
        Param("tile_target", "string", None, "metamorphosis partner of `tile` (eq. 3)"),
        Param("layout", "string", _CONFIG.layout, "tile placement", choices=LAYOUTS),
        Param("tiles_u", "int", _CONFIG.tiles_u, "tiles along u", low=1),
        Param("tiles_v", "int", _CONFIG.tiles_v, "tiles along v", low=1),
        Param("gap_u", "float", _CONFIG.gap_u, "gap between tiles along u", unit="cells",
              low=0, high=1, open_high=True),
        Param("gap_v", "float", _CONFIG.gap_v, "gap between tiles along v", unit="cells",
              low=0, high=1, open_high=True),
        Param("w_offset", "float", _CONFIG.w_offset, "offset of the tiles along the normal", unit="object"),
        Param("u0", "float", _CONFIG.u0, "layout origin in u", unit="uv"),
        Param("v0", "float", _CONFIG.v0, "layout origin in v", unit="uv"),
        Param("seed", "int", _CONFIG.seed, "seed of the random layout", low=0),
        Param("height", "float", _CONFIG.height, "w scale: object units per unit tile z",
              unit="object", editable=True, differentiable=True),
        Param("mode", "string", _CONFIG.mode, "exact mapping (`reference`) or geometry images "
              "(`approximation`)", choices=(*mapping.MODES, *mapping.MODE_ALIASES)),
        Param("map_resolution", "int", _CONFIG.map_resolution, "`maps`: geometry-image texels "
              "per side (auto: the smallest meeting `tolerance`, or `dicing_rate` with sensors)",
              low=base_maps.MIN_MAP_RESOLUTION, high=base_maps.MAX_MAP_RESOLUTION, auto=True),
        Param("tolerance", "float", _CONFIG.tolerance, "auto without a sensor: largest mapped-point "
              "error", unit="base diagonals", low=0, open_low=True),
        Param("dicing_rate", "float", _CONFIG.dicing_rate, "auto with sensors: pixels per texel",
              unit="px", low=0, open_low=True),
        Param("chart_border", "string", _CONFIG.chart_border, "mesh bases: tiles across UV-chart "
              "borders are clamped or dropped", choices=charts.CHART_BORDERS),
        Param("normals", "string", _CONFIG.normals, "how mapped normals are found",
              choices=normals.METHODS),
        Param("epsilon", "float", _CONFIG.epsilon, "finite-difference step of the normals",
              unit="tile", low=0, high=0.5, open_low=True, open_high=True),
        Param("time", "float", _CONFIG.time, "animation time", unit="time", editable=True,
              differentiable=True),
        *(Param(k, "float", getattr(_ANIMATION, k), doc, unit=unit)
          for k, (doc, unit) in _ANIMATION_DOCS.items()),
    ),
    example="""<shape type="ddm">
    <string name="base" value="sphere"/>
    <string name="tile" value="thorn"/>
    <integer name="tiles_u" value="8"/>
    <integer name="tiles_v" value="4"/>
    <integer name="map_resolution" value="32"/>
    <bsdf type="diffuse"/>
</shape>""",
    nested="one `bsdf`; sensors (`<ref id=\"camera\"/>`) for `map_resolution=auto`",
    stats="mode, tiles_placed, tiles_pruned, vertices, hddm_bytes, tile_bytes, maps_bytes, "
          "mesh_bytes, map_resolution (and its rule, auto trials), map_s, bytes, "
          "clamped_vertices; mesh bases: tiles_straddling, tiles_dropped",
    limits="Tiles are mapped, not clipped: a tile across a UV-chart border of a mesh base is "
           "clamped or dropped (`chart_border`); T folds where |w| exceeds the base's radius of "
           "curvature (warns).",
)

_CONFIG_KEYS = {f.name for f in dataclasses.fields(DDMConfig)} - {"base_params", "animation", "base"}


def config_from_values(values: dict) -> DDMConfig:
    """A :class:`DDMConfig` from the read :data:`SPEC` ``values``."""
    base = surfaces.base_name("ddm", values, _CONFIG.base, file_bases=("mesh", "teapot"))
    return DDMConfig(base=base, base_params=surfaces.base_params("ddm", base, values, BASE_PARAMS),
                     animation=Animation(**{k: values[k] for k in _ANIMATION_DOCS}),
                     **{k: values[k] for k in _CONFIG_KEYS})


class DDM(mi.Mesh):
    """Tiles mapped over a base; a mi.Mesh whose vertices a Dr.Jit kernel writes."""

    def __init__(self, props: mi.Properties, values: dict):
        self.sensors = take_sensors(props)   # referenced for map_resolution="auto"
        self.to_world = mi.ScalarTransform4f(mi.ScalarMatrix4f(np.array(
            props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float32)))
        self.model = DDMModel(config_from_values(values), sensors=self.sensors, to_world=self.to_world)
        m = self.model
        super().__init__(props.id() or "ddm", m.vertex_count, m.face_count, props, True, True)
        self.time = mi.Float(m.cfg.time)
        self.height = mi.Float(m.cfg.height)
        self._faces_version = None
        self._remap()
        stats = m.stats()
        if stats.get("tiles_straddling"):   # mesh bases: tiles across UV-chart borders
            mi.Log(mi.LogLevel.Info,
                   f"ddm {self.id()!r}: {stats['tiles_straddling']} tiles straddle a UV-chart "
                   f"border ({stats['tiles_dropped']} dropped, chart_border={m.cfg.chart_border})")
        mi.Log(mi.LogLevel.Info,
               f"ddm {self.id()!r}: {stats['tiles_placed']} tiles ({stats['tiles_pruned']} pruned), "
               f"{stats['vertices']:,} vertices; HDDM stores {stats['hddm_bytes']:,} bytes "
               f"(tiles {stats['tile_bytes']:,} + maps {stats['maps_bytes']:,}) against "
               f"{stats['mesh_bytes']:,} for the explicit mesh")

    def _remap(self) -> None:
        """Map the tiles at the current time / height and write the vertex buffers."""
        start = time.perf_counter()
        positions, normals, uv = self.model.map(self.time, self.height)
        to_world = mi.Transform4f(self.to_world)
        params = mi.traverse(self)
        if self._faces_version != self.model.faces_version:  # the w scale changed sign
            params["faces"] = dr.ravel(self.model.faces)
            self._faces_version = self.model.faces_version
        params["vertex_positions"] = dr.ravel(to_world @ positions)
        params["vertex_normals"] = dr.ravel(dr.normalize(to_world @ mi.Normal3f(normals)))
        params["vertex_texcoords"] = dr.ravel(uv)
        params.update()
        ok = dr.all(dr.isfinite(params["vertex_positions"])) & dr.all(
            dr.isfinite(params["vertex_normals"]))
        if not ok[0]:
            raise ValueError(f"ddm: mapping of {self.id()!r} produced NaN/Inf (check 'height', "
                             "'w_offset' and the tile)")
        self.build_stats = {**self.model.stats(), "map_s": time.perf_counter() - start,
                            "bytes": self.model.memory_report()["mesh_bytes"]}
        self.build_stats["clamped_vertices"] = self.model.clamped_count(uv)

    def fit_to_sensors(self, sensors) -> bool:
        """``map_resolution="auto"``: re-derive R from this shape's screen footprint in
        ``sensors`` (the scene's, unless the shape references its own;
        :meth:`DDMModel.fit_to_sensors`) and re-map.  Called by
        :func:`mi_displace.fit_to_sensors`, which then rebuilds the scene's acceleration
        structure; returns True when the maps changed."""
        if not self.model.fit_to_sensors(self.sensors or list(sensors), self.to_world):
            self.build_stats.update(self.model.stats())
            return False
        self._remap()
        return True

    def traverse(self, cb):
        super().traverse(cb)
        cb.put("time", self.time, mi.ParamFlags.Differentiable)
        cb.put("height", self.height, mi.ParamFlags.Differentiable)
        cb.put("tile_positions", self.model.buffers.positions, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=[]):
        if "time" in keys or "height" in keys or "tile_positions" in keys:
            self._remap()    # DDMModel.map refuses non-finite values
        else:
            super().parameters_changed(keys)

    def to_string(self):
        s = self.model.stats()
        return (f"DDM[mode={s['mode']}, tiles={s['tiles_placed']} (pruned {s['tiles_pruned']}), "
                f"vertices={s['vertices']}, hddm_bytes={s['hddm_bytes']}, "
                f"mesh_bytes={s['mesh_bytes']}]")


def register():
    mi.register_shape("ddm", constructor(SPEC, DDM))
