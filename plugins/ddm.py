"""``<shape type="ddm">``: a base surface tiled with copies of detail tiles through
T(u, v, w) = S(u, v) + n(u, v) w (DDM, eq. 1) or its geometry-image form (HDDM, eq. 2).

.. code-block:: xml

    <shape type="ddm" id="thorns">
        <string name="base" value="sphere"/>        <!-- plane|sphere|cylinder|torus|teapot|mesh -->
        <float name="radius" value="1"/>
        <string name="tile" value="thorn"/>         <!-- thorn|flower|chain|hair|hexagon|stone[:SEED]|file.obj, comma list -->
        <string name="layout" value="rect"/>        <!-- rect|hex|alternate|random -->
        <integer name="tiles_u" value="32"/>
        <integer name="tiles_v" value="16"/>
        <float name="height" value="0.15"/>         <!-- object units per unit tile z -->
        <string name="mode" value="maps"/>          <!-- exact|maps (reference|approximation) -->
        <integer name="map_resolution" value="256"/>
        <string name="normals" value="tangent"/>    <!-- tangent|jacobian|naive -->
        <bsdf type="diffuse"/>
    </shape>

Every parameter is described in ``docs/ddm.md`` (mesh bases also take ``chart_border``
clamp|drop; ``map_resolution="auto"`` takes ``dicing_rate`` / ``tolerance``).  ``time``,
``height`` and ``tile_positions`` are editable and differentiable through ``mi.traverse``:
changing them re-maps the vertices (positions, normals) in place, keeping faces, geometry
images and tiles.
"""
from __future__ import annotations

import math

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces
from mi_displace.ddm.animation import Animation
from mi_displace.ddm.model import BASE_PARAMS, DDMConfig, DDMModel
from mi_displace.plugins._guard import constructor, take_sensors

FLOAT_KEYS = ("gap_u", "gap_v", "w_offset", "u0", "v0", "height", "epsilon", "time", "tolerance",
              "dicing_rate")
INT_KEYS = ("tiles_u", "tiles_v", "seed")
STRING_KEYS = ("base", "filename", "tile", "tile_target", "layout", "mode", "normals", "chart_border")
ANIMATION_KEYS = ("velocity_u", "velocity_v", "rotation_rate", "w_amplitude", "w_frequency",
                  "alpha0", "alpha_rate")


def _int(value, name: str, low: int = 0) -> int:
    """A whole number >= ``low`` (2.5 is refused, not truncated)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not (math.isfinite(number) and number == int(number) and number >= low):
        what = "an integer or 'auto'" if name == "map_resolution" else f"an integer >= {low}"
        raise ValueError(f"ddm: '{name}' must be {what}, got {value!r}")
    return int(number)


def config_from_props(props: mi.Properties) -> DDMConfig:
    """Read a :class:`DDMConfig` from plugin properties (every key optional)."""
    cfg = DDMConfig()
    for key in STRING_KEYS:
        if key in props:
            setattr(cfg, key, str(props.get(key)))
    for key in FLOAT_KEYS:
        if key in props:
            setattr(cfg, key, float(props.get(key)))
    for key in INT_KEYS:
        if key in props:
            setattr(cfg, key, _int(props.get(key), key, 0 if key == "seed" else 1))
    if "map_resolution" in props:   # an integer, or the string "auto"
        value = props.get("map_resolution")
        cfg.map_resolution = "auto" if str(value).strip() == "auto" else _int(value, "map_resolution")
    cfg.base_params = surfaces.base_params("ddm", cfg.base, props, BASE_PARAMS)
    cfg.animation = Animation(**{k: float(props.get(k)) for k in ANIMATION_KEYS if k in props})
    return cfg


class DDM(mi.Mesh):
    """Tiles mapped over a base; a mi.Mesh whose vertices a Dr.Jit kernel writes."""

    def __init__(self, props: mi.Properties):
        self.sensors = take_sensors(props)   # referenced for map_resolution="auto"
        self.to_world = mi.ScalarTransform4f(mi.ScalarMatrix4f(np.array(
            props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float32)))
        self.model = DDMModel(config_from_props(props), sensors=self.sensors, to_world=self.to_world)
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
    mi.register_shape("ddm", constructor("ddm", DDM))
