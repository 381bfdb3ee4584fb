"""``<shape type="depth_object">`` and ``<shape type="visual_hull">``: image-based depth
objects (§4) and visual hulls (§5).

(:data:`SPECS` declares their parameters.)

The shape is the cube (12 triangles, placed by ``to_world``: any affine transform) the rays enter; its BSDF slices the cube front to back
in the best orthogonal direction and draws the first point inside all six displacement
volumes (:mod:`mi_displace.slicing.depth_object`), shaded diffusely with the view-dependent
colour of the three best-facing images and their normals; elsewhere a Null pass-through.
``visual_hull`` is the same with binary silhouettes.
"""
from __future__ import annotations

import dataclasses
import time

import mitsuba as mi
import numpy as np

from mi_displace.core.mesh_io import resolve_path
from mi_displace.core.properties import Param, PluginSpec, refuse_unknown
from mi_displace.slicing.bsdf import DepthObjectBSDF, ViewColour
from mi_displace.slicing.geometry import MAX_SLICES
from mi_displace.vdm.mesostructure import nested_objects
from mi_displace.slicing import depth_object as dobj
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "depth_object", "shape",
    "An image-based depth object (§4): six depth images on the faces of a cube.  The shape "
    "is the cube (12 triangles, placed by `to_world`: any affine transform); its BSDF slices "
    "it front to back in the best orthogonal direction and draws the first point inside all "
    "six displacement volumes, shaded diffusely with the view-dependent colour of the three "
    "best-facing images and their normals; elsewhere a Null pass-through.",
    (
        Param("filename", "string", None, "a cube.json of six images (`mi-displace slicing-capture`)"),
        Param("source", "shape", None, "instead of `filename`: a nested shape, captured at load"),
        Param("resolution", "int", 256, "`source`: pixels along each captured image edge",
              unit="px", low=1, high=8192),
        Param("slices", "int", 25, "planes across the cube", low=1, high=MAX_SLICES),
    ),
    example="""<shape type="depth_object">
    <string name="filename" value="parts/slicing_cup_depth/cube.json"/>
    <integer name="slices" value="16"/>
</shape>""",
    nested="`source` (a shape to capture); no `bsdf` (the colour comes from the images)",
    stats="slices, hull, resolution (image pixels per edge), bytes, build_s",
    limits="Only what the six axis-aligned views see is represented; concavities hidden from "
           "all six are filled.",
)
#: ``visual_hull``: the same cube and parameters with binary silhouettes (§5).
HULL_SPEC = dataclasses.replace(
    SPEC, plugin="visual_hull",
    summary="A visual hull (§5): `depth_object` with binary silhouettes instead of depths "
            "(the intersection of the six extruded silhouettes), drawn and coloured the same way.",
    example=SPEC.example.replace("depth_object", "visual_hull"),
    limits="Concavities are filled: a hull is never smaller than the object.")
SPECS = (SPEC, HULL_SPEC)


def _cube(center, half):
    """(positions (8, 3), faces (12, 3)) of the cube, outward winding."""
    c = np.asarray(center, np.float64)
    corners = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], np.float64)
    faces = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                      [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return c + half * corners, faces


class DepthObjectShape(mi.Mesh):
    """The cube of a depth object (or visual hull) with its BSDF (module docstring)."""

    HULL = False

    def __init__(self, props: mi.Properties, values: dict):
        start = time.perf_counter()
        name = "visual_hull" if self.HULL else "depth_object"
        refuse_unknown(HULL_SPEC if self.HULL else SPEC, props)   # before the capture
        slices, source = values["slices"], values["source"]
        if values["filename"] is not None:
            images = dobj.read(resolve_path(values["filename"]))
        elif source is not None:
            images = dobj.capture(source, values["resolution"])
            del props["source"]
        else:
            raise ValueError(f"{name}: give 'filename' (a cube.json of six images) or a nested "
                             "source shape to capture")
        to_world = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, np.float64)
        obj = dobj.DepthObject(images, slices, hull=self.HULL, to_world=to_world)
        bsdfs = nested_objects(props, mi.BSDF)
        if bsdfs:
            raise ValueError(f"{name}: takes no nested BSDF (colour comes from the images)")
        inner = mi.Properties(name)
        inner["height"] = mi.load_dict({"type": "uniform", "value": 0.0})
        inner["material"] = mi.load_dict({"type": "diffuse", "reflectance": ViewColour(obj)})
        props["bsdf"] = DepthObjectBSDF(inner, obj)
        pos, faces = _cube(images.center, images.half)
        pos = pos @ to_world[:3, :3].T + to_world[:3, 3]
        super().__init__(props.id() or name, 8, 12, props, False, False)
        params = mi.traverse(self)
        params["vertex_positions"] = mi.Float(pos.astype(np.float32).ravel())
        params["faces"] = mi.UInt32(faces.astype(np.uint32).ravel())
        params.update()
        self.depth_object = obj
        self.build_stats = {**obj.stats, "build_s": time.perf_counter() - start}

    def to_string(self):
        return f"DepthObject[{self.build_stats}]"


class VisualHullShape(DepthObjectShape):
    HULL = True


def register():
    mi.register_shape("depth_object", constructor(SPEC, DepthObjectShape))
    mi.register_shape("visual_hull", constructor(HULL_SPEC, VisualHullShape))
