"""``<integrator type="raster">``: the adapter of :mod:`mi_displace.render.raster`, the
GPU-style renderer (:data:`SPEC` declares its parameters).

``integrator.shapes`` (a list of meshes, default ``None``: the scene's) lets a scene without
shapes be drawn by z-buffer and shadow maps, with no acceleration structure built
(``docs/raster.md``).
"""
import mitsuba as mi

from mi_displace.core.collector import collector_paused
from mi_displace.core.properties import Param, PluginSpec
from mi_displace.render import lights, raster
from mi_displace.plugins._guard import constructor

_DEFAULTS = raster.Options()

SPEC = PluginSpec(
    "raster", "integrator",
    "GPU-style rendering, deterministic: one sample per pixel centre (or a fixed aa × aa "
    "pattern), the first surface that passes the alpha test (null BSDFs: slicing, VDM "
    "silhouettes), shaded once per light — point, spot and directional lights with hard "
    "shadows, area lights as fixed point sets, `constant`/`envmap` as unoccluded ambient.  "
    "Any other emitter is refused by name before a kernel runs.  `mi.render` returns a "
    "(height, width, 3) image; `spp` and `seed` are ignored.",
    (
        Param("aa", "int", 1, "aa × aa fixed samples per pixel", low=1, high=64),
        Param("max_layers", "int", None, "alpha-test pass-throughs per ray (default: sized "
              "from the scene, never cuts a ray short)", low=1),
        Param("visibility", "string", _DEFAULTS.visibility, "ray-traced or z-buffered primary "
              "visibility", choices=raster.VISIBILITY),
        Param("shadows", "string", _DEFAULTS.shadows, "shadow rays, shadow maps or none",
              choices=raster.SHADOWS),
        Param("shadow_resolution", "int", _DEFAULTS.shadow_resolution, "shadow-map texels per side",
              low=1, high=16384),
        Param("shadow_bias", "float", _DEFAULTS.shadow_bias, "shadow-map depth bias", unit="texels", low=0),
        Param("shadow_normal_offset", "float", _DEFAULTS.shadow_normal_offset,
              "shadow-map lookup offset × sin(theta)", unit="texels", low=0),
        Param("area_samples", "int", _DEFAULTS.area_samples, "fixed light points per area emitter "
              "(the quality knob of area lights)", low=1, high=lights.MAX_AREA_SAMPLES),
        Param("area_shadow_resolution", "int", _DEFAULTS.area_shadow_resolution, "cube shadow-map "
              "texels per side of each area-light point (shadows=map)", low=1, high=16384),
        Param("freeze", "bool", False, "record the frame's kernels once (`dr.freeze`) and replay "
              "them: a frame costs its kernels, not Python tracing and launches; recorded again "
              "when an `mi.traverse` parameter's layout or scalar value changes; shapes that draw "
              "themselves (slicing) draw before the recorded frame; scenes Dr.Jit cannot record "
              "(BSDFs whose state it cannot traverse) are drawn unfrozen with one warning; needs "
              "visibility=raytrace, shadows=ray or none"),
    ),
    example="""<integrator type="raster">
    <string name="shadows" value="ray"/>
    <integer name="area_samples" value="4"/>
</integrator>
<shape type="sphere"><bsdf type="diffuse"/></shape>
<emitter type="point"><point name="position" x="2" y="-2" z="3"/></emitter>""",
    stats="none (the frame is drawn at render time)",
    limits="One bounce: no indirect light beyond the ambient term; area lights are point sets "
           "(banding at few samples, a 1/d² peak for receivers touching the light).",
)


class Raster(mi.SamplingIntegrator):
    """One sample per pixel (or aa x aa); delta lights with hard shadows, area lights as
    fixed point sets, constant/envmap ambient."""

    def __init__(self, props: mi.Properties, values: dict):
        super().__init__(props)
        self.aa = values.pop("aa")
        #: None: raster.layer_limit of the scene (no ray is cut short)
        self.max_layers = values.pop("max_layers")
        freeze = values.pop("freeze")
        self.options = raster.Options(**values).check()
        if freeze:
            raster.FrozenFrames.check(self.options)
        #: the frame's recordings (None: every frame traced anew)
        self.frozen = raster.FrozenFrames() if freeze else None
        self.shapes = None

    @collector_paused   # the whole frame: its vectorised calls trace every live BSDF
    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        return raster.render(scene, sensor, self.aa, self.max_layers, self.options, self.shapes,
                             self.frozen)

    @collector_paused
    def sample(self, scene, sampler, ray, medium=None, active=True):
        return (raster.shade(scene, mi.Ray3f(ray), self.max_layers, active,
                             self.options.area_samples), mi.Bool(active), [])

    def setup_problem(self, scene) -> str | None:
        """Why this integrator cannot render ``scene`` (one line), or ``None``: an
        emitter it does not model.  Scene loaders call it after loading."""
        return lights.emitter_problem(scene, "raster")

    def to_string(self):
        o = self.options
        layers = "auto" if self.max_layers is None else self.max_layers
        return (f"Raster[aa={self.aa}, max_layers={layers}, visibility={o.visibility}, "
                f"shadows={o.shadows}, shadow_resolution={o.shadow_resolution}, "
                f"area_samples={o.area_samples}, freeze={self.frozen is not None}]")


def register():
    mi.register_integrator("raster", constructor(SPEC, Raster))
