"""``<integrator type="raster">``: the GPU-style renderer of :mod:`mi_displace.render.raster`.

.. code-block:: xml

    <integrator type="raster">
        <integer name="aa" value="1"/>          <!-- aa x aa fixed samples per pixel -->
        <integer name="max_layers" value="8"/>  <!-- alpha-test pass-throughs -->
    </integrator>

``mi.render(scene)`` returns a (height, width, 3) image; ``spp`` and ``seed`` are ignored
(the result is deterministic).
"""
import mitsuba as mi

from mi_displace.render import raster
from mi_displace.plugins._guard import constructor


class Raster(mi.SamplingIntegrator):
    """One sample per pixel (or aa x aa), delta lights with hard shadows, ambient term."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.aa = int(props.get("aa", 1))
        self.max_layers = int(props.get("max_layers", 8))
        if self.aa < 1:
            raise ValueError(f"raster: 'aa' must be a positive integer, got {self.aa}")
        if self.max_layers < 1:
            raise ValueError(f"raster: 'max_layers' must be >= 1, got {self.max_layers}")

    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        return raster.render(scene, sensor, self.aa, self.max_layers)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        return raster.shade(scene, mi.Ray3f(ray), self.max_layers, active), mi.Bool(active), []

    def to_string(self):
        return f"Raster[aa={self.aa}, max_layers={self.max_layers}]"


def register():
    mi.register_integrator("raster", constructor("raster", Raster))
