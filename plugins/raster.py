"""``<integrator type="raster">``: the GPU-style renderer of :mod:`mi_displace.render.raster`.

.. code-block:: xml

    <integrator type="raster">
        <integer name="aa" value="1"/>          <!-- aa x aa fixed samples per pixel -->
        <integer name="max_layers" value="8"/>  <!-- alpha-test pass-throughs; default: sized from the scene -->
        <string name="visibility" value="raytrace"/>   <!-- raytrace|zbuffer -->
        <string name="shadows" value="ray"/>           <!-- ray|map|none -->
        <integer name="shadow_resolution" value="2048"/>  <!-- shadow-map texels per side -->
        <float name="shadow_bias" value="0.5"/>        <!-- shadow-map depth bias, texels -->
        <float name="shadow_normal_offset" value="0.5"/> <!-- lookup offset x sin(theta), texels -->
        <integer name="area_samples" value="16"/>      <!-- fixed points per area light -->
        <integer name="area_shadow_resolution" value="256"/>  <!-- per point, shadows="map" -->
    </integrator>

``mi.render(scene)`` returns a (height, width, 3) image; ``spp`` and ``seed`` are ignored
(the result is deterministic).  ``integrator.shapes`` (a list of meshes, default ``None``:
the scene's) lets a scene without shapes be drawn by z-buffer and shadow maps, with no
acceleration structure built (``docs/raster.md``).  An emitter it cannot draw is a
``ValueError`` naming it when the frame starts, before any kernel, and when
``mi_displace.render.scene.load`` loads the scene (``setup_problem(scene)``).
"""
import mitsuba as mi

from mi_displace.render import lights, raster
from mi_displace.core.collector import collector_paused
from mi_displace.plugins._guard import constructor


class Raster(mi.SamplingIntegrator):
    """One sample per pixel (or aa x aa); delta lights with hard shadows, area lights as
    fixed point sets, constant/envmap ambient."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.aa = int(props.get("aa", 1))
        #: None: raster.layer_limit of the scene (no ray is cut short)
        self.max_layers = props.get("max_layers", None)
        if self.aa < 1:
            raise ValueError(f"raster: 'aa' must be a positive integer, got {self.aa}")
        if self.max_layers is not None and not (isinstance(self.max_layers, int) and self.max_layers >= 1):
            raise ValueError(f"raster: 'max_layers' must be an integer >= 1, got {self.max_layers!r}")
        defaults = raster.Options()
        self.options = raster.Options(
            visibility=str(props.get("visibility", defaults.visibility)),
            shadows=str(props.get("shadows", defaults.shadows)),
            shadow_resolution=int(props.get("shadow_resolution", defaults.shadow_resolution)),
            shadow_bias=float(props.get("shadow_bias", defaults.shadow_bias)),
            shadow_normal_offset=float(props.get("shadow_normal_offset", defaults.shadow_normal_offset)),
            area_samples=int(props.get("area_samples", defaults.area_samples)),
            area_shadow_resolution=int(props.get("area_shadow_resolution",
                                                 defaults.area_shadow_resolution)),
        ).check()
        self.shapes = None

    @collector_paused   # the whole frame: its vectorised calls trace every live BSDF
    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        return raster.render(scene, sensor, self.aa, self.max_layers, self.options, self.shapes)

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
                f"area_samples={o.area_samples}]")


def register():
    mi.register_integrator("raster", constructor("raster", Raster))
