"""Blender's half of ``mi-displace bench bake_blender``: Cycles selected-to-active bakes.

Run by a Python that has ``bpy`` (Blender as a module), not by mi_displace's own
(:func:`mi_displace.bench.peers.blender.bake` starts it)::

    python blender_side.py HIGH.obj LOW.obj RES MAX_DISTANCE OUT_DIR

Imports both OBJs without axis conversion (object coordinates unchanged; the low-poly keeps
the normals written in its ``vn`` lines as custom normals, the high-poly is smooth-shaded),
then bakes at RES x RES, one sample per texel, margin 0, cage extrusion MAX_DISTANCE and
ray distance 2 MAX_DISTANCE (rays from the inflated low-poly inwards: the +-MAX_DISTANCE
band of our baker), into float images saved as ``OUT_DIR/<name>.npy`` (H, W, 4), row 0 =
top (v = 1) like our maps:

* ``normal_tangent``, ``normal_object`` (selected to active; colours (n + 1) / 2);
* ``position_high`` (selected to active: where the ray hit the high-poly);
* ``position_low``, ``normal_low`` (the low-poly alone: its point and interpolated normal).

Cycles clears the texels it does not bake to (0, 0, 0).  ``OUT_DIR/blender.json`` holds the
seconds of each ``bpy.ops.object.bake`` call and Blender's version.
"""
import json
import sys
import time

import bpy
import numpy as np



def _import(path):
    bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    return bpy.context.selected_objects[0]


def main(high_path, low_path, res, max_distance, out_dir):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1
    high, low = _import(high_path), _import(low_path)
    for poly in high.data.polygons:
        poly.use_smooth = True
    image = bpy.data.images.new("bake", res, res, alpha=True, float_buffer=True)
    mat = bpy.data.materials.new("bake")
    mat.use_nodes = True
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = image
    mat.node_tree.nodes.active = node
    low.data.materials.clear()
    low.data.materials.append(mat)
    bake = scene.render.bake
    bake.margin = 0
    seconds = {}

    def run(name, kind, selected, space="TANGENT"):
        bpy.ops.object.select_all(action="DESELECT")
        if selected:
            high.select_set(True)
        low.select_set(True)
        bpy.context.view_layer.objects.active = low
        bake.use_selected_to_active = selected
        bake.cage_extrusion = max_distance
        bake.max_ray_distance = 2 * max_distance
        bake.normal_space = space
        start = time.perf_counter()
        bpy.ops.object.bake(type=kind, use_selected_to_active=selected, normal_space=space,
                            cage_extrusion=max_distance, max_ray_distance=2 * max_distance,
                            margin=0)
        seconds[name] = time.perf_counter() - start
        px = np.empty(res * res * 4, np.float32)
        image.pixels.foreach_get(px)
        np.save(f"{out_dir}/{name}.npy", px.reshape(res, res, 4)[::-1].copy())

    run("normal_tangent", "NORMAL", True, "TANGENT")
    run("normal_object", "NORMAL", True, "OBJECT")
    run("position_high", "POSITION", True)
    run("position_low", "POSITION", False)
    run("normal_low", "NORMAL", False, "OBJECT")
    with open(f"{out_dir}/blender.json", "w") as f:
        json.dump({"version": bpy.app.version_string, "seconds": seconds}, f, indent=2)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), sys.argv[5])
