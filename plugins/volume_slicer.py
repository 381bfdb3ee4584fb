"""``<integrator type="volume_slicer">``: the paper's slicing volume renderer (§4.2) of
:mod:`mi_displace.volume.slicer`, GPU-style and deterministic.  The adapter: :data:`SPEC`
reads the parameters, :func:`mi_displace.volume.slicer.render` draws the frame.

A separate integrator rather than a mode of ``raster``: ``raster`` shades the first opaque
surface a ray meets, while slicing composites every slice through a volume and needs the
volume object itself (not scene geometry), its light-transmittance grid and its normal
method.  ``mi.render`` returns a (height, width, 3) image; ``spp`` and ``seed`` are ignored.
"""
import mitsuba as mi

from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.render import lights
from mi_displace.volume import EXAMPLE_XML, slicer
from mi_displace.volume.field import NORMALS
from mi_displace.plugins._guard import constructor

SPEC = PluginSpec(
    "volume_slicer", "integrator",
    "The volume renderer of the discontinuous displacement paper (§4.2): view-aligned slices "
    "through the displaced object's proxy box composited front to back, each sample read "
    "through the inverse displacement maps; single scattering towards the lights (`scatter`, "
    "the model `volpath` computes) or a shaded iso-surface (`surface`).",
    (
        Param("volume", "volume", REQUIRED, "the `displaced_volume` to draw (a `<ref>`)"),
        Param("model", "string", "scatter", "`scatter` (matches volpath) or `surface`",
              choices=slicer.MODELS),
        Param("normals", "string", "jacobian", "surface model: how normals are found", choices=NORMALS),
        Param("spacing", "float", 1.0, "distance between slices", unit="object voxels", low=0, open_low=True),
        Param("albedo", "float|volume", 0.8, "scatter: the medium's albedo, or a `displaced_volume` "
              "with output=\"albedo\" (then also the surface colour)", low=0, high=1),
        Param("color", "rgb", (0.8, 0.7, 0.55), "surface model: diffuse reflectance"),
        Param("iso", "float", 0.5, "surface model: iso value of tau(O)", low=0, high=1,
              open_low=True, open_high=True),
        Param("sharpness", "float", 4.0, "surface model: extinction ramp of the iso-surface",
              unit="1/voxel", low=0, open_low=True),
        Param("shadows", "bool", True, "shadows through a light-transmittance grid"),
        Param("light_resolution", "int", None, "light grid nodes per side (default: about one per "
              "object voxel, 24–96)", low=2, high=1024),
        Param("aa", "int", 1, "rays per pixel side (aa × aa box pattern)", low=1, high=16),
        Param("reuse_lookup", "bool", True, "shade with the density step's D_k lookup (false: "
              "read again; the same image, slower)"),
    ),
    example=EXAMPLE_XML + """
<integrator type="volume_slicer">
    <ref name="volume" id="volume"/>
    <string name="model" value="surface"/>
</integrator>""",
    stats="none (the frame is drawn at render time)",
    limits="Deterministic single scattering only; `spp` and `seed` are ignored.  Draws delta "
           "lights and `constant` ambient light; any other emitter (`area`, `envmap`, …) is "
           "refused, naming it.",
)


class VolumeSlicer(mi.SamplingIntegrator):
    """View-aligned slices through the displaced bounding box, composited front to back."""

    def __init__(self, props: mi.Properties, values: dict):
        super().__init__(props)
        volume, albedo = values["volume"], values["albedo"]
        if not hasattr(volume, "volume"):
            raise ValueError("volume_slicer: parameter 'volume' must be a <ref> to a displaced_volume")
        if not isinstance(albedo, float):
            if getattr(albedo, "albedo", None) is None:
                raise ValueError("volume_slicer: parameter 'albedo' must be a number or a <ref> to a "
                                 "displaced_volume with output=\"albedo\"")
            albedo = albedo.albedo
        self.plugin = volume
        self.settings = slicer.SliceSettings(
            model=values["model"], normals=values["normals"], spacing=values["spacing"],
            albedo=albedo, color=values["color"], iso=values["iso"], sharpness=values["sharpness"],
            shadows=values["shadows"], light_resolution=values["light_resolution"],
            aa=values["aa"], reuse_lookup=values["reuse_lookup"])
        slicer.check_slices(volume.volume, self.settings)

    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        return slicer.render(scene, sensor, self.plugin.volume, self.settings)

    def setup_problem(self, scene) -> str | None:
        """An emitter the slicer does not model (one line), or ``None``; scene loaders
        call it after loading."""
        return lights.emitter_problem(scene, "volume_slicer")

    def to_string(self):
        s = self.settings
        return f"VolumeSlicer[model={s.model}, normals={s.normals}, spacing={s.spacing}]"


def register():
    mi.register_integrator("volume_slicer", constructor(SPEC, VolumeSlicer))
