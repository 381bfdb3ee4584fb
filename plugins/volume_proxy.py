"""``<shape type="volume_proxy">``: the box that holds a ``displaced_volume``'s medium under
``volpath`` (the adapter of its ``medium_box``)."""
import mitsuba as mi
import numpy as np

from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.volume import EXAMPLE_XML
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "volume_proxy", "shape",
    "The box that holds a `displaced_volume`'s medium under `volpath`: exactly the box the "
    "volume reports to Mitsuba (its proxy box, §4.2, or `bounds`), as a 12-triangle mesh with "
    "the user's BSDF (`null`) and media.  Measured (Mitsuba 3.9.1): with a container larger "
    "than the volume's own box, `volpath` darkens parts of the medium that a brute-force "
    "quadrature of the same single-scattering integral lights (the same with a native "
    "`gridvolume`); with this box the two agree.",
    (Param("volume", "volume", REQUIRED, "the `displaced_volume` whose medium it holds (a `<ref>`)"),),
    example=EXAMPLE_XML + """
<shape type="volume_proxy">
    <ref name="volume" id="volume"/>
    <bsdf type="null"/>
    <medium type="heterogeneous" name="interior">
        <ref name="sigma_t" id="volume"/>
        <float name="albedo" value="0.8"/>
    </medium>
</shape>""",
    limits="Render it with `volpath`: `path` ignores media.",
)

CORNERS = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=np.float32)
# two outward-facing triangles per face of the unit cube (corner index = x + 2 y + 4 z)
FACES = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]], dtype=np.uint32)


class VolumeProxy(mi.Mesh):
    def __init__(self, props: mi.Properties, values: dict):
        volume = values["volume"]
        if not hasattr(volume, "medium_box"):
            raise ValueError("volume_proxy: parameter 'volume' must be a <ref> to a displaced_volume")
        lo, hi = volume.medium_box()
        super().__init__(props.id() or "volume_proxy", 8, 12, props, False, False)
        params = mi.traverse(self)
        params["vertex_positions"] = mi.Float((lo + CORNERS * (hi - lo)).astype(np.float32).ravel())
        params["faces"] = mi.UInt32(FACES.ravel())
        params.update()


def register():
    mi.register_shape("volume_proxy", constructor(SPEC, VolumeProxy))
