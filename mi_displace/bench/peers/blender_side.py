"""Blender's half of ``mi-displace bench bake_blender``: Cycles selected-to-active bakes.

Run by a Python that has ``bpy`` (Blender as a module), not by mi_displace's own
(:func:`mi_displace.bench.peers.blender.bake` starts it)::

    python blender_side.py HIGH.obj LOW.obj RES MAX_DISTANCE OUT_DIR [AO_SAMPLES AO_DISTANCE]
    python blender_side.py HIGH.obj LOW.obj RES MAX_DISTANCE OUT_DIR albedo TEXTURE.png

Imports both OBJs without axis conversion (object coordinates unchanged; the low-poly keeps
the normals written in its ``vn`` lines as custom normals, the high-poly is smooth-shaded),
then bakes at RES x RES, one sample per texel, margin 0, cage extrusion MAX_DISTANCE and
ray distance 2 MAX_DISTANCE (rays from the inflated low-poly inwards: the +-MAX_DISTANCE
band of our baker), into float images saved as ``OUT_DIR/<name>.npy`` (H, W, 4), row 0 =
top (v = 1) like our maps:

* ``normal_tangent``, ``normal_object`` (selected to active; colours (n + 1) / 2);
* ``position_high`` (selected to active: where the ray hit the high-poly);
* ``position_low``, ``normal_low`` (the low-poly alone: its point and interpolated normal);
* ``normal_tangent_directx`` (``normal_g = NEG_Y``);
* with AO_SAMPLES: ``ao`` (selected to active, AO_SAMPLES render samples, the world's AO
  distance AO_DISTANCE) and ``pointiness`` (the high-poly's Geometry > Pointiness as
  emission, selected to active: Blender's nearest to a curvature bake).

The ``albedo`` form bakes only ``albedo``: the high-poly (with its UVs) under a diffuse
material whose colour is TEXTURE.png (an sRGB image, linear interpolation), Cycles' DIFFUSE
bake with the colour pass alone, selected to active.

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


def main(high_path, low_path, res, max_distance, out_dir, ao_samples=0, ao_distance=1.0,
         texture=None):
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

    def run(name, kind, selected, space="TANGENT", green="POS_Y", passes=None):
        bpy.ops.object.select_all(action="DESELECT")
        if selected:
            high.select_set(True)
        low.select_set(True)
        bpy.context.view_layer.objects.active = low
        bake.use_selected_to_active = selected
        bake.cage_extrusion = max_distance
        bake.max_ray_distance = 2 * max_distance
        bake.normal_space = space
        bake.normal_g = green
        start = time.perf_counter()
        bpy.ops.object.bake(type=kind, use_selected_to_active=selected, normal_space=space,
                            cage_extrusion=max_distance, max_ray_distance=2 * max_distance,
                            margin=0, normal_g=green, **({"pass_filter": passes} if passes else {}))
        seconds[name] = time.perf_counter() - start
        px = np.empty(res * res * 4, np.float32)
        image.pixels.foreach_get(px)
        np.save(f"{out_dir}/{name}.npy", px.reshape(res, res, 4)[::-1].copy())

    if texture is not None:
        colour = bpy.data.materials.new("albedo")
        colour.use_nodes = True
        nodes = colour.node_tree.nodes
        nodes.clear()   # the default Principled BSDF and output would stay the active output
        lookup, diffuse = nodes.new("ShaderNodeTexImage"), nodes.new("ShaderNodeBsdfDiffuse")
        output = nodes.new("ShaderNodeOutputMaterial")
        lookup.image = bpy.data.images.load(texture)
        colour.node_tree.links.new(lookup.outputs["Color"], diffuse.inputs["Color"])
        colour.node_tree.links.new(diffuse.outputs["BSDF"], output.inputs["Surface"])
        high.data.materials.clear()
        high.data.materials.append(colour)
        run("albedo", "DIFFUSE", True, passes={"COLOR"})
        with open(f"{out_dir}/blender.json", "w") as f:
            json.dump({"version": bpy.app.version_string, "seconds": seconds}, f, indent=2)
        return
    run("normal_tangent", "NORMAL", True, "TANGENT")
    run("normal_object", "NORMAL", True, "OBJECT")
    run("position_high", "POSITION", True)
    run("position_low", "POSITION", False)
    run("normal_low", "NORMAL", False, "OBJECT")
    run("normal_tangent_directx", "NORMAL", True, "TANGENT", "NEG_Y")
    if ao_samples:
        world = bpy.data.worlds.new("bake")
        scene.world = world
        world.light_settings.distance = ao_distance
        scene.cycles.samples = ao_samples
        run("ao", "AO", True)
        scene.cycles.samples = 1
        pointy = bpy.data.materials.new("pointiness")
        pointy.use_nodes = True
        nodes = pointy.node_tree.nodes
        nodes.clear()   # the default Principled BSDF and output would stay the active output
        geometry, emission = nodes.new("ShaderNodeNewGeometry"), nodes.new("ShaderNodeEmission")
        output = nodes.new("ShaderNodeOutputMaterial")
        pointy.node_tree.links.new(geometry.outputs["Pointiness"], emission.inputs["Color"])
        pointy.node_tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
        high.data.materials.clear()
        high.data.materials.append(pointy)
        run("pointiness", "EMIT", True)
    with open(f"{out_dir}/blender.json", "w") as f:
        json.dump({"version": bpy.app.version_string, "seconds": seconds}, f, indent=2)


if __name__ == "__main__":
    if len(sys.argv) > 7 and sys.argv[6] == "albedo":
        main(*sys.argv[1:3], int(sys.argv[3]), float(sys.argv[4]), sys.argv[5], texture=sys.argv[7])
    else:
        main(sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), sys.argv[5],
             *([int(sys.argv[6]), float(sys.argv[7])] if len(sys.argv) > 7 else []))
