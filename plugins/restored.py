"""``<shape type="restored">``: a low-poly restored with a baked displacement map (paper 003 §5).

.. code-block:: xml

    <shape type="restored">
        <string name="map" value="bake_out/d16.png"/>   <!-- any baked map with its sidecar -->
        <string name="low" value="bake_out/low.obj"/>   <!-- optional: default from the sidecar -->
        <integer name="levels" value="2"/>              <!-- rounds of 1->4 subdivision -->
        <!-- or <integer name="split" value="3"/>: the uniform 1->N^2 pattern -->
        <boolean name="keep_holes" value="true"/>       <!-- drop faces over void texels -->
        <bsdf type="diffuse"/>
    </shape>

The mesh is built once by :func:`mi_displace.bake.restore.restore` (Dr.Jit subdivision and
displacement, alias-welded seams, recomputed normals) and uploaded into this ``mi.Mesh``.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.restore import low_for_map, restore
from mi_displace.plugins._guard import constructor


class Restored(mi.Mesh):
    """Low-poly + map -> subdivided, displaced triangle mesh (object units of the low-poly)."""

    def __init__(self, props: mi.Properties):
        if "map" not in props:
            raise ValueError("restored: needs a 'map' (a baked map with its .json sidecar)")
        resolver = mi.file_resolver()   # paths relative to the scene file
        map_path = str(resolver.resolve(str(props.get("map"))))
        low = str(resolver.resolve(str(props.get("low")))) if "low" in props else low_for_map(map_path)
        levels = props.get("levels", 2)
        split = props.get("split", None)
        out = restore(low, map_path, levels=levels, split=split,
                      keep_holes=bool(props.get("keep_holes", True)))
        super().__init__(props.id() or "restored", len(out.positions), len(out.faces), props, True, True)
        to_world = mi.Transform4f(mi.ScalarTransform4f(mi.ScalarMatrix4f(np.array(
            props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float32))))
        p = to_world @ mi.Point3f(*[mi.Float(np.ascontiguousarray(out.positions[:, k])) for k in range(3)])
        n = dr.normalize(to_world @ mi.Normal3f(*[mi.Float(np.ascontiguousarray(out.normals[:, k]))
                                                  for k in range(3)]))
        params = mi.traverse(self)
        params["vertex_positions"] = dr.ravel(p)
        params["vertex_normals"] = dr.ravel(n)
        params["vertex_texcoords"] = mi.Float(np.ascontiguousarray(out.uvs.ravel()))
        params["faces"] = mi.UInt32(np.ascontiguousarray(out.faces.ravel()))
        params.update()
        self.build_stats = {"restore_s": out.seconds, "vertices": len(out.positions),
                            "faces": len(out.faces)}

    def to_string(self):
        return f"Restored[vertices={self.build_stats['vertices']}, faces={self.build_stats['faces']}]"


def register():
    mi.register_shape("restored", constructor("restored", Restored))
