"""``<integrator type="volume_slicer">``: the paper's slicing volume renderer (§4.2) of
:mod:`mi_displace.volume.slicing`, GPU-style and deterministic.

.. code-block:: xml

    <integrator type="volume_slicer">
        <ref name="volume" id="walnut"/>              <!-- a displaced_volume -->
        <string name="model" value="scatter"/>        <!-- scatter (matches volpath) | surface -->
        <string name="normals" value="jacobian"/>     <!-- gradient | jacobian | blend | fd (surface) -->
        <float name="spacing" value="1.0"/>           <!-- slice distance, object voxels -->
        <float name="albedo" value="0.8"/>            <!-- scatter: the medium's albedo, or -->
        <!-- <ref name="albedo" id="..."/>               a displaced_volume output="albedo" (also the surface colour) -->
        <rgb name="color" value="0.8, 0.7, 0.55"/>    <!-- surface: diffuse reflectance -->
        <float name="iso" value="0.5"/>               <!-- surface: iso value of tau(O) -->
        <boolean name="shadows" value="true"/>
        <integer name="aa" value="1"/>
        <boolean name="reuse_lookup" value="true"/>   <!-- shade with the density step's D_k lookup (false: read again; same image, slower) -->
    </integrator>

A separate integrator rather than a mode of ``raster``: ``raster`` shades the first opaque
surface a ray meets, while slicing composites every slice through a volume and needs the
volume object itself (not scene geometry), its light-transmittance grid and its normal
method.  ``mi.render`` returns a (height, width, 3) image; ``spp`` and ``seed`` are ignored.
"""
import mitsuba as mi

from mi_displace.volume import slicing
from mi_displace.plugins._guard import boolean, constructor


class VolumeSlicer(mi.SamplingIntegrator):
    """View-aligned slices through the displaced bounding box, composited front to back."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        volume = props.get("volume", None)
        if volume is None or not hasattr(volume, "volume"):
            raise ValueError("volume_slicer: needs <ref name=\"volume\" id=...> to a displaced_volume")
        self.plugin = volume
        color = props.get("color", None)
        albedo = props.get("albedo", 0.8)
        if not isinstance(albedo, (int, float)):
            if getattr(albedo, "albedo", None) is None:
                raise ValueError("volume_slicer: 'albedo' must be a number or a <ref> to a displaced_volume "
                                 "with output=\"albedo\"")
            albedo = albedo.albedo
        self.settings = slicing.SliceSettings(
            model=props.get("model", "scatter"), normals=props.get("normals", "jacobian"),
            spacing=float(props.get("spacing", 1.0)), albedo=albedo,
            color=(0.8, 0.7, 0.55) if color is None else tuple(mi.ScalarColor3f(color)),
            iso=float(props.get("iso", 0.5)), sharpness=float(props.get("sharpness", 4.0)),
            shadows=boolean("volume_slicer", props, "shadows", True),
            light_resolution=props.get("light_resolution", None), aa=int(props.get("aa", 1)),
            reuse_lookup=boolean("volume_slicer", props, "reuse_lookup", True))
        slicing.check_slices(volume.volume, self.settings)

    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        return slicing.render(scene, sensor, self.plugin.volume, self.settings)

    def to_string(self):
        s = self.settings
        return f"VolumeSlicer[model={s.model}, normals={s.normals}, spacing={s.spacing}]"


def register():
    mi.register_integrator("volume_slicer", constructor("volume_slicer", VolumeSlicer))
