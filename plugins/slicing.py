"""``<shape type="slicing">``: displacement mapping by slicing the displacement volume (§3).

.. code-block:: xml

    <shape type="slicing">
        <string name="base" value="torus"/>        <!-- plane | sphere | cylinder | torus | mesh -->
        <float name="major_radius" value="1"/>  <float name="minor_radius" value="0.4"/>
        <integer name="resolution" value="64"/>     <!-- base polygons along u (plane: 1) -->
        <!-- or: <string name="filename" value="base.obj"/> (PLY/OBJ with UVs) -->
        <texture type="bricks" name="height"/>      <!-- D in [0, 1]: the α channel -->
        <float name="scale" value="0.06"/>          <!-- maximum displacement [object units, as displaced] -->
        <integer name="slices" value="25"/>          <!-- or <string name="slices" value="auto"/> -->
        <ref name="sensor" id="camera"/>            <!-- needed by slices="auto" -->
        <string name="direction" value="best"/>     <!-- a | b | c | best | screen -->
        <string name="alpha" value="ramp"/>         <!-- basic (default for a) | ramp -->
        <boolean name="ratio_scaling" value="true"/> <!-- §3.4 orthogonal count scaling -->
        <boolean name="draw_base" value="false"/>   <!-- also draw the base polygons (opaque) -->
        <boolean name="rasterise" value="true"/>    <!-- raster: z-buffer the slices (false: walk) -->
        <boolean name="self_shadows" value="true"/> <!-- false: no walk towards the light -->
        <bsdf type="diffuse"> ... </bsdf>            <!-- its textures are read at the slice uv -->
    </shape>

``scale`` and ``slices`` are editable through ``mi.traverse`` (the slices are rebuilt).
The shape itself is the boundary of the displacement volume (the proxy rays enter); its
BSDF, made here around the nested material, finds per ray the front-most slice fragment
that passes the α-test (:mod:`mi_displace.slicing.sliced`) and is a Null pass-through
where none does, so it works under ``raster`` and ``path`` alike.  Under ``raster`` the
slices of a frame are rasterised by our z-buffer beforehand (``raster_begin``; the α-test
as a fragment discard, :mod:`mi_displace.slicing.rasterised`) and the BSDF shades the
fragment that won; ``rasterise=false`` walks them by ray queries as under ``path``.  Self-shadows come from
the slices themselves (a second slice walk towards the light; ``self_shadows=false`` leaves
it out, as the paper's OpenGL drawing does).  ``build_stats`` reports
the slice counts (what ``auto`` chose), triangles and bytes.
"""
from __future__ import annotations

import math
import time

import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces
from mi_displace.core.texture_height import check_texture_finite, warn_if_srgb
from mi_displace.slicing.bsdf import SlicingBSDF, slice_count
from mi_displace.vdm.mesostructure import nested_objects
from mi_displace.slicing import geometry as geo
from mi_displace.slicing.sliced import DIRECTIONS, SlicedVolume
from mi_displace.plugins._guard import boolean, constructor


class Slicing(mi.Mesh):
    """Boundary of the displacement volume with the slicing BSDF (module docstring)."""

    def __init__(self, props: mi.Properties):
        start = time.perf_counter()
        base_name = props.get("base", "mesh" if "filename" in props else "plane")
        height = props.get("height", None)
        if not isinstance(height, mi.Texture):
            raise ValueError("slicing: 'height' must be a nested texture (D in [0, 1])")
        check_texture_finite(height)
        warn_if_srgb(height, "slicing")
        scale = float(props.get("scale", 0.1))
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"slicing: 'scale' must be a positive number, got {scale}")
        slices = slice_count(props)
        direction = str(props.get("direction", "best"))
        if direction not in DIRECTIONS:
            raise ValueError(f"slicing: 'direction' must be one of {', '.join(DIRECTIONS)}, got {direction!r}")
        alpha = str(props.get("alpha", "basic" if direction == "a" else "ramp"))
        ratio_scaling = boolean("slicing", props, "ratio_scaling", True)
        draw_base = boolean("slicing", props, "draw_base", False)
        self.rasterise = boolean("slicing", props, "rasterise", True)
        sensor = props.get("sensor", None)
        if slices == "auto" and not isinstance(sensor, mi.Sensor):
            raise ValueError("slicing: slices='auto' needs the scene's camera: "
                             "<ref name=\"sensor\" id=\"...\"/> (declared before this shape)")
        resolution = props.get("resolution", 1 if base_name == "plane" else 64)
        params = surfaces.base_params("slicing", base_name, props)
        to_world = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, np.float64)
        filename = props.get("filename", None) if base_name == "mesh" else None
        bm = geo.make_base_mesh(base_name, params, filename, resolution, to_world)
        auto = slices == "auto"
        if auto:
            slices = geo.auto_slices(sensor, bm.bbox(scale), bm.world_scale(scale))
        volume = SlicedVolume(bm, height, scale, slices, direction, alpha, ratio_scaling, draw_base)

        bsdfs = nested_objects(props, mi.BSDF)
        if len(bsdfs) > 1:
            raise ValueError(f"slicing: expected at most one nested BSDF, got {len(bsdfs)}")
        material = bsdfs[0][1] if bsdfs else mi.load_dict({"type": "diffuse"})
        inner = mi.Properties("slicing")
        inner["height"] = height
        inner["material"] = material
        inner["self_shadows"] = bool(props.get("self_shadows", True))
        bsdf = SlicingBSDF(inner, volume)
        props[bsdfs[0][0] if bsdfs else "bsdf"] = bsdf
        walls = volume.walls
        super().__init__(props.id() or "slicing", len(walls.positions), len(walls.faces), props,
                         False, True)
        self.scale, self.slices = mi.Float(scale), mi.Float(slices)
        geo.fill_mesh(self, walls)
        self.volume, self.bsdf_ref = volume, bsdf
        self._settings = (direction, alpha, ratio_scaling, draw_base)
        self.build_stats = {**volume.stats, "slices_auto": auto, "build_s": time.perf_counter() - start}

    def raster_begin(self, sensor: mi.Sensor, aa: int) -> None:
        """Called by the ``raster`` integrator before it draws a frame: rasterise the
        slices at the sensor's samples (:mod:`mi_displace.slicing.rasterised`), unless
        ``rasterise`` is false, the slices are screen-space planes or the sensor is not one
        the z-buffer projects (perspective, orthographic): then they are walked."""
        pinhole = sensor.class_name() in ("PerspectiveCamera", "OrthographicCamera")
        if self.rasterise and pinhole and self.volume.direction != "screen":
            from mi_displace.slicing.rasterised import draw
            self.volume.frame = draw(self.volume, sensor, aa)

    def raster_end(self) -> None:
        """Called after the frame: later renders (``path``, another view) walk again."""
        self.volume.frame = None

    def traverse(self, cb):
        super().traverse(cb)
        cb.put("scale", self.scale, mi.ParamFlags.NonDifferentiable)
        cb.put("slices", self.slices, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=[]):
        if "scale" not in keys and "slices" not in keys:
            return super().parameters_changed(keys)
        start = time.perf_counter()
        scale, slices = float(self.scale[0]), float(self.slices[0])
        if slices != int(slices):
            raise ValueError(f"slicing: 'slices' must be an integer, got {slices}")
        old = self.volume
        volume = SlicedVolume(old.bm, old.height, scale, int(slices), *self._settings)
        geo.fill_mesh(self, volume.walls)   # same topology: only the walls' heights move
        self.volume = self.bsdf_ref.model = volume
        self.bsdf_ref._cache = None
        self.build_stats = {**volume.stats, "slices_auto": False, "build_s": time.perf_counter() - start}

    def to_string(self):
        return f"Slicing[{self.build_stats}]"


def register():
    mi.register_shape("slicing", constructor("slicing", Slicing))
