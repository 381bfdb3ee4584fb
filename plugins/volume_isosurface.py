"""``<shape type="volume_isosurface">``: the iso-surface of a ``displaced_volume``'s exactly
displaced field (:mod:`mi_displace.volume.isosurface`), a triangle mesh for ``path``: the
surface reference of the slicing renderer's ``surface`` model.

.. code-block:: xml

    <shape type="volume_isosurface">
        <ref name="volume" id="volume"/>
        <float name="iso" value="0.5"/>          <!-- level of tau(O') -->
        <integer name="resolution" value="256"/>  <!-- grid nodes along the proxy's longest side -->
        <bsdf type="diffuse"/>
    </shape>
"""
import time

import mitsuba as mi

from mi_displace.volume.isosurface import isosurface
from mi_displace.plugins._guard import constructor


class VolumeIsosurface(mi.Mesh):
    def __init__(self, props: mi.Properties):
        volume = props.get("volume", None)
        if volume is None or not hasattr(volume, "volume"):
            raise ValueError("volume_isosurface: needs <ref name=\"volume\" id=...> to a displaced_volume")
        start = time.perf_counter()
        verts, faces = isosurface(volume.volume, float(props.get("iso", 0.5)), int(props.get("resolution", 256)))
        super().__init__(props.id() or "volume_isosurface", len(verts), len(faces), props, True, False)
        params = mi.traverse(self)
        params["vertex_positions"] = mi.Float(verts.ravel())
        params["faces"] = mi.UInt32(faces.ravel())
        params.update()
        self.recompute_vertex_normals()
        self.build_stats = {"vertices": int(len(verts)), "faces": int(len(faces)),
                            "marching_cubes_s": time.perf_counter() - start}


def register():
    mi.register_shape("volume_isosurface", constructor("volume_isosurface", VolumeIsosurface))
