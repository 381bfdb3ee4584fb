"""``<shape type="volume_isosurface">``: the adapter of :mod:`mi_displace.volume.isosurface`."""
import time

import mitsuba as mi

from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.volume import EXAMPLE_XML
from mi_displace.volume.isosurface import isosurface
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "volume_isosurface", "shape",
    "The iso-surface of a `displaced_volume`'s exactly displaced field, by marching cubes on a "
    "grid over its proxy box: a triangle mesh for `path`, the surface reference of the volume "
    "slicer's `surface` model.",
    (
        Param("volume", "volume", REQUIRED, "the `displaced_volume` (a `<ref>`)"),
        Param("iso", "float", 0.5, "level of tau(O')", low=0, high=1, open_low=True, open_high=True),
        Param("resolution", "int", 256, "grid nodes along the proxy box's longest side", low=4, high=2048),
    ),
    example=EXAMPLE_XML + """
<shape type="volume_isosurface">
    <ref name="volume" id="volume"/>
    <integer name="resolution" value="32"/>
    <bsdf type="diffuse"/>
</shape>""",
    stats="vertices, faces, marching_cubes_s",
    limits="Its accuracy is the grid's: features thinner than a grid cell are lost.",
)


class VolumeIsosurface(mi.Mesh):
    def __init__(self, props: mi.Properties, values: dict):
        volume = values["volume"]
        if not hasattr(volume, "volume"):
            raise ValueError("volume_isosurface: parameter 'volume' must be a <ref> to a displaced_volume")
        start = time.perf_counter()
        verts, faces = isosurface(volume.volume, values["iso"], values["resolution"])
        super().__init__(props.id() or "volume_isosurface", len(verts), len(faces), props, True, False)
        params = mi.traverse(self)
        params["vertex_positions"] = mi.Float(verts.ravel())
        params["faces"] = mi.UInt32(faces.ravel())
        params.update()
        self.recompute_vertex_normals()
        self.build_stats = {"vertices": int(len(verts)), "faces": int(len(faces)),
                            "marching_cubes_s": time.perf_counter() - start}


def register():
    mi.register_shape("volume_isosurface", constructor(SPEC, VolumeIsosurface))
