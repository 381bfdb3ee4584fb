"""``<shape type="depth_object">`` and ``<shape type="visual_hull">``: image-based depth
objects (§4) and visual hulls (§5).

.. code-block:: xml

    <shape type="depth_object">
        <string name="filename" value="cup/cube.json"/>  <!-- six images + cube (depth_object.write) -->
        <!-- or a nested source shape, captured at load:  <shape type="ply" name="source" .../>
             with <integer name="resolution" value="256"/> -->
        <integer name="slices" value="150"/>              <!-- planes across the cube -->
    </shape>

The shape is the cube (12 triangles, placed by ``to_world``: any affine transform) the rays enter; its BSDF slices the cube front to back
in the best orthogonal direction and draws the first point inside all six displacement
volumes (:mod:`mi_displace.slicing.depth_object`), shaded diffusely with the view-dependent
colour of the three best-facing images and their normals; elsewhere a Null pass-through.
``visual_hull`` is the same with binary silhouettes.
"""
from __future__ import annotations

import time

import mitsuba as mi
import numpy as np

from mi_displace.core.mesh_io import resolve_path
from mi_displace.slicing.bsdf import DepthObjectBSDF, ViewColour, slice_count
from mi_displace.vdm.mesostructure import nested_objects
from mi_displace.slicing import depth_object as dobj
from mi_displace.plugins._guard import constructor


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

    def __init__(self, props: mi.Properties):
        start = time.perf_counter()
        name = "visual_hull" if self.HULL else "depth_object"
        slices = slice_count(props)
        if slices == "auto":
            raise ValueError(f"{name}: 'slices' must be an integer")
        shapes = nested_objects(props, mi.Shape)
        if "filename" in props:
            images = dobj.read(resolve_path(props.get("filename")))
        elif shapes:
            images = dobj.capture(shapes[0][1], int(props.get("resolution", 256)))
            for key, _ in shapes:
                del props[key]
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
    mi.register_shape("depth_object", constructor("depth_object", DepthObjectShape))
    mi.register_shape("visual_hull", constructor("visual_hull", VisualHullShape))
