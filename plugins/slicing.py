"""``<shape type="slicing">``: displacement mapping by slicing the displacement volume (§3).

(:data:`SPEC` declares its parameters.)

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

import time
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces
from mi_displace.core.properties import REQUIRED, Param, PluginSpec, refuse_unknown
from mi_displace.core.texture_height import check_texture_finite, warn_if_srgb
from mi_displace.slicing.bsdf import SlicingBSDF
from mi_displace.slicing.trace import ALPHA_TESTS
from mi_displace.vdm.mesostructure import nested_objects
from mi_displace.slicing import geometry as geo
from mi_displace.slicing.sliced import DIRECTIONS, SlicedVolume, crossing, crossing_message
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "slicing", "shape",
    "Displacement mapping by slicing the displacement volume (§3): the shape is the boundary "
    "of the volume; its BSDF finds per ray the front-most slice fragment that passes the "
    "α-test (D from the `height` texture) and is a Null pass-through where none does, so it "
    "works under `raster` (slices z-buffered per frame) and `path` (walked by ray queries) "
    "alike.  Self-shadows come from a second slice walk towards the light.",
    (
        surfaces.base_param("plane"), *surfaces.BASE_DIMENSIONS,
        surfaces.resolution_param(None, "base polygons along u (default: 1 for a plane, else 64)"),
        surfaces.BASE_FILENAME,
        Param("height", "texture", REQUIRED, "D in [0, 1]: the α channel"),
        Param("scale", "float", 0.1, "maximum displacement (as `displaced`'s scale)", unit="object",
              low=0, open_low=True, editable=True),
        Param("slices", "int", 25, "slices along the main direction (auto: from the sensor)",
              low=1, high=geo.MAX_SLICES, auto=True, editable=True),
        Param("sensor", "sensor", None, "the camera `slices=auto` sizes for and that bounds the "
              "b / c slice counts (at most 2 per pixel of the base's length along u / v there) "
              "(`<ref name=\"sensor\" id=\"...\"/>`, declared before this shape)"),
        Param("max_memory_mb", "float", 512, "bound on the slice buffers (predicted per family "
              "before building; more is refused with the numbers)", unit="MB", low=0,
              open_low=True),
        Param("direction", "string", "best", "slice direction (a: parallel to the base, b/c: "
              "orthogonal; best: per view; screen: view-aligned)", choices=DIRECTIONS),
        Param("alpha", "string", None, "α-test (default: basic for direction a, else ramp)",
              choices=ALPHA_TESTS),
        Param("ratio_scaling", "bool", True, "§3.4 orthogonal slice-count scaling"),
        Param("draw_base", "bool", None, "also draw the base polygons (opaque); default: true "
              "on a closed base (sphere, torus, a watertight mesh: the base is a solid, and "
              "the ramp test's cut-outs would open it), false on an open one"),
        Param("rasterise", "bool", True, "under `raster`: z-buffer the slices (false: walk them)"),
        Param("self_shadows", "bool", True, "walk the slices towards the light"),
    ),
    example="""<shape type="slicing">
    <string name="base" value="plane"/>
    <texture type="bricks" name="height"/>
    <float name="scale" value="0.1"/>
    <integer name="slices" value="8"/>
    <bsdf type="diffuse"/>
</shape>""",
    nested="the `height` texture; at most one `bsdf` (the material, its textures read at the "
           "slice uv; `diffuse` when none)",
    stats="the slice counts per direction (what auto chose: slices_auto), triangles, bytes, "
          "build_s, and per family (families: slices, triangles, bytes, build_s)",
    limits="Self-shadows and colour come from the slices, so they band at few slices; "
           "`direction=screen` on a mesh base costs four ray queries per plane point tested "
           "(its (u, v, h) found by iteration).",
)


class Slicing(mi.Mesh):
    """Boundary of the displacement volume with the slicing BSDF (module docstring)."""

    def __init__(self, props: mi.Properties, values: dict):
        start = time.perf_counter()
        refuse_unknown(SPEC, props)   # a typo costs no slice build
        base_name = surfaces.base_name("slicing", values, "plane")
        height, scale, slices = values["height"], values["scale"], values["slices"]
        check_texture_finite(height)
        warn_if_srgb(height, "slicing")
        direction = values["direction"]
        alpha = values["alpha"] or ("basic" if direction == "a" else "ramp")
        ratio_scaling, draw_base = values["ratio_scaling"], values["draw_base"]
        self.rasterise = values["rasterise"]
        sensor = values["sensor"]
        if slices == "auto" and sensor is None:
            raise ValueError("slicing: slices='auto' needs the scene's camera: "
                             "<ref name=\"sensor\" id=\"...\"/> (declared before this shape)")
        resolution = values["resolution"] or (1 if base_name == "plane" else 64)
        params = surfaces.base_params("slicing", base_name, values)
        to_world = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, np.float64)
        bm = geo.make_base_mesh(base_name, params, values["filename"], resolution, to_world)
        if draw_base is None:
            draw_base = len(geo.boundary_edges(bm)) == 0
        auto = slices == "auto"
        if auto:
            slices = geo.auto_slices(sensor, bm.bbox(scale), bm.world_scale(scale))
        self._settings = (direction, alpha, ratio_scaling, draw_base, sensor, values["max_memory_mb"])
        volume = SlicedVolume(bm, height, scale, slices, *self._settings)

        bsdfs = nested_objects(props, mi.BSDF)
        if len(bsdfs) > 1:
            raise ValueError(f"slicing: expected at most one nested BSDF, got {len(bsdfs)}")
        material = bsdfs[0][1] if bsdfs else mi.load_dict({"type": "diffuse"})
        inner = mi.Properties("slicing")
        inner["height"] = height
        inner["material"] = material
        inner["self_shadows"] = values["self_shadows"]
        bsdf = SlicingBSDF(inner, volume)
        props[bsdfs[0][0] if bsdfs else "bsdf"] = bsdf
        walls = volume.walls
        super().__init__(props.id() or "slicing", len(walls.positions), len(walls.faces), props,
                         False, True)
        self.scale, self.slices = mi.Float(scale), mi.Float(slices)
        geo.fill_mesh(self, walls)
        self.volume, self.bsdf_ref = volume, bsdf
        self._rays = None   # the thickness check's rays (mesh bases), cast once
        self.build_stats = {**volume.stats, "slices_auto": auto, **self._thickness(),
                            "build_s": time.perf_counter() - start}

    def _thickness(self) -> dict:
        """On a mesh base, the thickness check of ``displaced`` for the slices
        (:func:`mi_displace.slicing.sliced.crossing`): warns naming ``scale`` where one part's
        displacement volume reaches another part of the base."""
        v = self.volume
        if v.bm.base is not None:
            return {}
        check, self._rays = crossing(v.bm, v.height, v.scale, self._rays)
        message = crossing_message(f"slicing {self.id() or '(no id)'!r}", check)
        if message:
            warnings.warn(message, stacklevel=3)
        return {"crossing_vertices": check["crossing_vertices"]}

    def raster_begin(self, sensor: mi.Sensor, aa: int) -> None:
        """Called by the ``raster`` integrator before it draws a frame: rasterise the
        slices at the sensor's samples (:mod:`mi_displace.slicing.rasterised`), unless
        ``rasterise`` is false, the slices are screen-space planes or the sensor is not one
        the z-buffer projects (perspective, orthographic): then they are walked."""
        pinhole = sensor.class_name() in ("PerspectiveCamera", "OrthographicCamera")
        self.volume.coherent = True   # the frame's lanes: its samples in pixel order
        if self.rasterise and pinhole and self.volume.direction != "screen":
            from mi_displace.slicing.rasterised import draw
            self.volume.frame = draw(self.volume, sensor, aa)

    def raster_end(self) -> None:
        """Called after the frame: later renders (``path``, another view) walk again."""
        self.volume.frame = None
        self.volume.coherent = False

    def traverse(self, cb):
        super().traverse(cb)
        cb.put("scale", self.scale, mi.ParamFlags.NonDifferentiable)
        cb.put("slices", self.slices, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=[]):
        graded = [k for k in ("scale", "slices") if dr.grad_enabled(getattr(self, k))]
        if graded:
            raise ValueError(f"slicing: a gradient was enabled on {', '.join(map(repr, graded))}, "
                             "which the slice build cannot differentiate (the slices are rebuilt "
                             "from its value); differentiable: the nested material's parameters "
                             "(bsdf.nested.*)")
        if "scale" not in keys and "slices" not in keys:
            return super().parameters_changed(keys)
        start = time.perf_counter()
        scale, slices = float(self.scale[0]), float(self.slices[0])
        if slices != int(slices):
            raise ValueError(f"slicing: 'slices' must be an integer, got {slices}")
        old = self.volume
        volume = SlicedVolume(old.bm, old.height, scale, int(slices), *self._settings)
        geo.fill_mesh(self, volume.walls)   # same topology: only the walls' heights move
        self.volume = volume
        self.bsdf_ref.set_model(volume)
        self.build_stats = {**volume.stats, "slices_auto": False, **self._thickness(),
                            "build_s": time.perf_counter() - start}

    def to_string(self):
        return f"Slicing[{self.build_stats}]"


def register():
    mi.register_shape("slicing", constructor(SPEC, Slicing))
