"""`mi-displace bench core`: tessellation, acceleration build and raster speed.

* ``tessellate_4m_s``: a ripple-displaced sphere tessellated to ~4M triangles straight
  into the ``mi.Mesh`` buffers (Dr.Jit end to end), warm median;
* ``accel_build_4m_s``: Mitsuba building its acceleration structure over that mesh;
* ``raster_512_1m_s``: the ``raster`` integrator at 512 x 512 on a ~1M-triangle scene with
  two delta lights, warm median, beside ``path_1spp_512_1m_s`` (Mitsuba's ``path``,
  max_depth 2, 1 spp) on the same scene in the same process.

``--quick`` runs the same with :data:`QUICK` sizes (the spheres at resolution 200 and 100,
128^2); the field names keep the full run's sizes.
"""
from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bench._timing import median_time, print_record


class Sizes(NamedTuple):
    """The tessellated sphere's ``resolution`` (``big``: the ~4M-triangle one; ``small``:
    the ~1M-triangle scene) and the film's ``res`` x ``res`` pixels."""
    big: int
    small: int
    res: int


FULL = Sizes(2000, 1000, 512)
QUICK = Sizes(200, 100, 128)


def _sphere(nu: int) -> dict:
    return {"type": "displaced", "base": "sphere", "resolution": nu, "scale": 0.05,
            "height": {"type": "ripples", "frequency": 16.0},
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.6, 0.5]}}}


def _scene(shape, integrator: dict, res: int = 512) -> mi.Scene:
    return mi.load_dict({
        "type": "scene", "integrator": integrator,
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(
                       origin=[0, -5, 1.5], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}},
        "point": {"type": "point", "position": [3, -3, 4], "intensity": {"type": "rgb", "value": 40}},
        "sun": {"type": "directional", "direction": [-1, 1, -1],
                "irradiance": {"type": "rgb", "value": 0.5}},
        "shape": shape})


def _render(scene: mi.Scene, **kw) -> None:
    img = mi.render(scene, **kw)
    dr.eval(img)
    dr.sync_thread()


def run(sizes: Sizes = FULL) -> dict:
    """Measure everything; returns the JSON record (seconds, counts)."""
    shape_4m = None

    def tessellate():
        nonlocal shape_4m
        shape_4m = mi.load_dict(_sphere(sizes.big))
        dr.sync_thread()

    tess = median_time(tessellate, 3)
    faces_4m = shape_4m.face_count()

    def accel():
        scene = mi.load_dict({"type": "scene", "shape": shape_4m})
        dr.sync_thread()
        return scene

    accel_s = median_time(accel, 3)
    shape_1m = mi.load_dict(_sphere(sizes.small))
    raster_scene = _scene(shape_1m, {"type": "raster"}, sizes.res)
    path_scene = _scene(shape_1m, {"type": "path", "max_depth": 2}, sizes.res)
    raster_s = median_time(lambda: _render(raster_scene), repeats=5)
    path_s = median_time(lambda: _render(path_scene, spp=1), repeats=5)
    img = np.asarray(mi.render(raster_scene))
    if not np.all(np.isfinite(img)) or img.mean() <= 0:
        raise RuntimeError("bench core: raster image is not finite or black")
    return {
        "variant": mi.variant(),
        "faces_4m": faces_4m,
        "tessellate_4m_s": tess,
        "accel_build_4m_s": accel_s,
        "tessellate_vs_accel": tess / accel_s,
        "faces_1m": shape_1m.face_count(),
        "raster_512_1m_s": raster_s,
        "path_1spp_512_1m_s": path_s,
        "raster_vs_path_1spp": raster_s / path_s,
        "targets": {"tessellate_4m_s": 0.3, "raster_512_1m_s": 0.15},
    }


def main(json: bool = False, quick: bool = False) -> dict:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and print its record."""
    record = run(QUICK if quick else FULL)
    print_record(record, json)
    return record
