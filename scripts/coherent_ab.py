"""A/B in ONE process of the raster frame's rays traced as coherent rays (Embree's packet
traversal) against the same frames traced as incoherent ones: ``raster.COHERENT`` (primary
rays, alpha-test continuations, shadow rays) and the slicing shapes' walks during a frame
(``SlicedVolume.coherent``, set by the plugin's ``raster_begin``).  Prints whether the images
are identical (and finite), then ROUNDS x (median wall seconds of REPS frames drawn
alternately, incoherent and coherent) and their ratio: both see the same moments of a
shared machine.

    ./.venv/bin/python scripts/coherent_ab.py SCENE [name=value ...]

    SCENE       a file in scenes/ (e.g. slicing_donut.xml); name=value: its defaults
                (integrator=raster res=512 unless given)

Frames are drawn by ``raster`` with aa=1 at one sample per pixel, as ``mi-displace bench
frames`` draws them.  Environment: WHICH (``both``, ``raster`` or ``slicing``: the flags
cleared in the incoherent frames; ``all``: both, and the z-buffer's slivers drawn by row
pieces in those frames too, ``zbuffer.TALL`` 0, i.e. every frame lever of this kind against
none), REPS (7), ROUNDS (3)."""
import os
import sys

import numpy as np

from ab_timing import alternate


def main(scene_file: str, *params: str) -> None:
    import drjit as dr
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    from mi_displace.core.resources import scene_path
    from mi_displace.render import raster, zbuffer
    from mi_displace.render.scene import load

    which = os.environ.get("WHICH", "both")
    if which not in ("both", "raster", "slicing", "all"):
        sys.exit(f"WHICH must be both, raster, slicing or all, not {which!r}")
    tall = zbuffer.TALL
    values = {"integrator": "raster", "res": 512}
    values.update(p.split("=", 1) for p in params)
    scene, _ = load(scene_path(scene_file), **values)
    integrator = mi.load_dict({"type": "raster", "aa": 1})
    sliced = [s for s in scene.shapes() if hasattr(s, "volume") and hasattr(s, "raster_begin")]

    def frame(coherent: bool) -> np.ndarray:
        raster.COHERENT = coherent or which == "slicing"
        zbuffer.TALL = tall if coherent or which != "all" else 0
        begins = []
        for shape in sliced if which != "raster" else []:   # a handful of shapes
            begin = type(shape).raster_begin
            begins.append((type(shape), begin))

            def raster_begin(self, sensor, aa, begin=begin):
                begin(self, sensor, aa)
                self.volume.coherent = coherent
            type(shape).raster_begin = raster_begin
        try:
            return np.asarray(mi.render(scene, integrator=integrator, spp=1), np.float32)
        finally:
            raster.COHERENT, zbuffer.TALL = True, tall
            for cls, begin in begins:
                cls.raster_begin = begin

    a, b = frame(False), frame(True)
    print(f"{scene_file} {' '.join(params)} (coherent: {which}): identical {np.array_equal(a, b)}, "
          f"finite {bool(np.isfinite(b).all())}, mean {float(b.mean()):.4f}")
    alternate(lambda label: frame(label == "coherent"), ("incoherent", "coherent"))

if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(*sys.argv[1:])
