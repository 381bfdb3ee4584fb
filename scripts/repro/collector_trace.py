"""Smallest reproduction (docs/platform.md): Python's collector, run while Dr.Jit traces a
vectorised call, frees a Python BSDF that only a reference cycle kept alive, while Dr.Jit is
dispatching to it through a plain pointer: the process aborts (SIGABRT).

Usage: ``python collector_trace.py MODE [VARIANT]`` (``llvm_ad_rgb``).  Two Python BSDFs are
alive: the scene's and a dropped one held only by a cycle; the render traces both.  MODE:

* ``bare``: nothing paused, a collection at (almost) every allocation: the process dies;
* ``methods``: the same with every BSDF method run with the collector paused (as the
  package's plugin methods are): it still dies, the collection runs between the methods;
* ``frame``: the same with the whole render run with the collector paused (as the package's
  ``raster`` frame is): exits 0;
* ``turn``: as ``bare``, but the dropped BSDF is registered after the scene's: a collection
  frees it *before* its turn in the trace: exits 0 (Dr.Jit skips it);
* ``after``: as ``bare`` at Python's default thresholds, and the scene's BSDF runs
  ``gc.collect()`` in ``eval``, freeing the dropped one *after* its turn: exits 0.
"""
import gc
import sys

import drjit as dr
import mitsuba as mi

from mi_displace.core.collector import collector_paused

MODE = sys.argv[1]
mi.set_variant(sys.argv[2] if len(sys.argv) > 2 else "llvm_ad_rgb")
paused = collector_paused if MODE == "methods" else (lambda method: method)


class Grey(mi.BSDF):
    """A Lambertian BSDF in Python (albedo 0.5)."""

    def __init__(self, props):
        super().__init__(props)
        self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [self.m_flags]

    @paused
    def eval(self, ctx, si, wo, active=True):
        if MODE == "after" and not hasattr(self, "cycle"):   # the scene's instance
            gc.collect()
        return mi.Color3f(0.5 / dr.pi) * dr.maximum(mi.Frame3f.cos_theta(wo), 0)

    @paused
    def pdf(self, ctx, si, wo, active=True):
        return mi.warp.square_to_cosine_hemisphere_pdf(wo)

    @paused
    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    @paused
    def sample(self, ctx, si, sample1, sample2, active=True):
        bs = mi.BSDFSample3f()
        bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
        bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
        bs.eta, bs.sampled_type, bs.sampled_component = 1.0, +mi.BSDFFlags.DiffuseReflection, 0
        return bs, mi.Color3f(0.5)


def drop_one():
    """A Grey that nothing but a reference cycle holds (a dropped scene's BSDF)."""
    dropped = mi.load_dict({"type": "grey"})
    dropped.cycle = dropped


mi.register_bsdf("grey", Grey)
print(f"mitsuba {mi.__version__}, drjit {dr.__version__}, variant {mi.variant()}, mode {MODE}",
      flush=True)
gc.disable()
if MODE != "turn":
    drop_one()       # registered first: traced first
scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
                      "sensor": {"type": "perspective",
                                 "film": {"type": "hdrfilm", "width": 8, "height": 8}},
                      "ball": {"type": "sphere", "center": [0, 0, 5], "bsdf": {"type": "grey"}},
                      "light": {"type": "constant"}})
if MODE == "turn":
    drop_one()       # registered after the scene's BSDF: traced after it
render = scene.integrator().render
if MODE == "frame":
    render = collector_paused(render)
if MODE != "after":
    gc.set_threshold(1, 1, 1)   # collect at (almost) every allocation: a busy trace, made
gc.enable()                     # deterministic
image = render(scene, scene.sensors()[0])   # traces Grey's methods for both instances
print(f"ok, mean {dr.mean(image.array)[0]:.4f}")
