"""``mi-displace bench slicing [--json]``: displacement by slicing and depth objects.

All in one process (times are wall seconds; medians of 3 warm runs after a cold one,
Python's garbage collected before and paused during the timed runs; the like-for-like
pair ``llvmpipe_s`` / ``render_time_same_work_s``: measured first, before any other
scene is drawn, as medians of 9 frames drawn alternately, one of each in turn, after two
warm-up frames each):

* ``render_time_warm_s``: the bricked donut (scenes/slicing_donut.xml) at 512^2, 25 slices,
  best direction, under ``raster`` with one sample per pixel (as a GPU draws it: the slice
  polygons rasterised by our z-buffer, mi_displace.slicing.rasterised);
  ``build_time_warm_s``: loading it (slice polygons + their BVHs);
  ``render_time_walk_warm_s``: the same frame with the slices walked by ray queries
  (``rasterise=false``, the renderer before the z-buffer path; ``speedup_vs_walk``;
  ``flip_walk_vs_rasterised``: FLIP between the two frames);
  ``render_time_a_warm_s``: direction a (the 25 surface-aligned slices llvmpipe draws);
  ``render_time_same_work_s``: the work llvmpipe does (mi_displace.bench.peers.llvmpipe): direction
  a, 25 slices, no base polygons (``draw_base=false``: under the basic α-test slice 0
  passes everywhere, so the image is the same), no self-shadow walk
  (``self_shadows=false``), no shadow ray (``shadows="none"``), one sample per pixel;
  ``speedup_vs_llvmpipe_same_work``; ``render_time_same_work_later_s`` /
  ``llvmpipe_later_s`` / ``speedup_vs_llvmpipe_same_work_later``: the same pair timed
  again the same way at the end, after every other scene of the benchmark was drawn (the
  kernels and buffers they left make our frame slower: see docs/slicing.md). The peer
  shades with the interpolated base normal from a 1024^2 height texture; we shade with the
  displaced normal of the procedural height (a few lookups per pixel);
  ``auto_slices``: what ``slices="auto"`` chooses for this view;
* ``true_displacement_time_warm_s``: the same donut tessellated by ``displaced`` at
  ``resolution`` 2048 (converged: ``converged_flip`` = FLIP between 1024 and 2048), under
  ``raster``, render only (``true_displacement_build_s``: its tessellation + BVH);
* ``flip``: the sliced donut against that converged donut (both raster, 512^2);
* ``render_time_screen_warm_s`` / ``flip_screen``: the same with screen-space slices;
* ``depth_object_time_warm_s``: the cup depth object at 400^2, 150 slices (the paper's
  high-quality case), raster, one sample per pixel; ``depth_object_time_noskip_warm_s``:
  the same without empty-space skipping (every plane tested);
* ``llvmpipe_s``: the paper's algorithm as OpenGL on Mesa llvmpipe (moderngl + EGL): the
  donut's 25 surface-aligned slices per base polygon, α-test by ``discard``, 512^2, one
  frame; ``llvmpipe_64_s`` / ``llvmpipe_150_s`` at 64 / 150 slices; ``null`` with
  ``llvmpipe_reason`` ("peer unavailable: ...") when ``moderngl`` or Mesa's EGL is missing
  (:mod:`mi_displace.bench.peers.llvmpipe`; ``scripts/setup_peers.sh`` installs them);
* ``load_average``: the machine's 1-minute load average at the end (timings are wall
  seconds on a shared machine);
* ``slices_bytes`` (slice polygons + walls of ``best``: all three directions, §3.4 ratio
  scaling), ``slices_bytes_direction_a`` (25 surface-aligned slices), ``slices_bytes_screen``
  (walls only) vs ``displaced_bytes`` (the converged mesh).

``--quick`` runs every part with :data:`QUICK` sizes (128^2 frames, llvmpipe at 25 slices
only, the true displacement at resolution 128 / 256, the cup at 100^2 with 32 slices).
"""
from __future__ import annotations

import gc
import json as _json
import os
import statistics
import time
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.resources import scenes_dir

SCENES = scenes_dir()
RES = 512


class Sizes(NamedTuple):
    """What a run draws: the donut at ``res`` x ``res`` pixels, llvmpipe at each of
    ``gl_slices`` slice counts (the first must be 25: the like-for-like pair), the true
    displacement at ``reference_resolutions`` (coarser, converged), the cup at ``cup_res``
    x ``cup_res`` pixels with ``cup_slices`` slices."""
    res: int
    gl_slices: tuple
    reference_resolutions: tuple
    cup_res: int
    cup_slices: int


FULL = Sizes(RES, (25, 64, 150), (1024, 2048), 400, 150)
QUICK = Sizes(128, (25,), (128, 256), 100, 32)


def _timed(fn, repeats=3, warm=1):
    """Median wall seconds of ``repeats`` calls after ``warm`` ones, with Python's garbage
    collected before and paused during the timed calls (as ``timeit`` does: the previous
    scenes' garbage is not charged to this frame), and the last result."""
    for _ in range(warm):
        fn()
    gc.collect()
    gc.disable()
    try:
        times = []
        for _ in range(repeats):
            dr.sync_thread()
            start = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - start)
    finally:
        gc.enable()
    return statistics.median(times), out


def _render(scene, integrator):
    return np.asarray(mi.render(scene, integrator=integrator), np.float32)[..., :3]


def _load(path, **params):
    dr.sync_thread()
    start = time.perf_counter()
    scene = mi.load_file(str(path), **{k: str(v) for k, v in params.items()})
    dr.sync_thread()
    return scene, time.perf_counter() - start


def _interleaved(first, second, repeats=9, warm=2):
    """Median wall seconds of ``first`` and ``second`` called alternately (``warm`` calls
    each first; garbage collected before and paused during the timed calls): both
    measured at the same moments of a shared machine."""
    for _ in range(warm):
        first(), second()
    gc.collect()
    gc.disable()
    try:
        times = ([], [])
        for _ in range(repeats):
            for fn, out in zip((first, second), times):
                dr.sync_thread()
                start = time.perf_counter()
                fn()
                out.append(time.perf_counter() - start)
    finally:
        gc.enable()
    return statistics.median(times[0]), statistics.median(times[1])


def donut_gl(scene, slices_list=(25,), res: int = RES, ours=None) -> dict:
    """llvmpipe frame times of the donut's surface-aligned slices at ``res`` x ``res`` (see
    module doc); with ``ours`` (a callable drawing our same-work frame) the 25-slice frame is
    timed alternately with it (``render_time_same_work_s``).  Without the peer:
    ``llvmpipe_s`` null and ``llvmpipe_reason``."""
    from mi_displace.bench.peers import measure

    out, reason = measure(_donut_gl, scene, slices_list, res, ours)
    return out if reason is None else {"llvmpipe_s": None, "llvmpipe_reason": reason}


def _donut_gl(scene, slices_list, res: int, ours) -> dict:
    from mi_displace.bench.peers import llvmpipe
    from mi_displace.slicing import geometry as geo

    volume = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
    R = 1024
    g = (np.arange(R) + 0.5) / R
    u, v = np.meshgrid(g, g)
    D = np.asarray(volume.D(mi.Point2f(mi.Float(u.ravel()), mi.Float(v.ravel()))), np.float32).reshape(R, R)
    mvp = llvmpipe.look_at_mvp([0, -4.2, 2.4], [0, 0, -0.1], [0, 0, 1], 30.0, 1.0)
    out = {"llvmpipe_renderer": llvmpipe.renderer()}
    for n in slices_list:
        gl = llvmpipe.GLSlices(geo.aligned_slices(volume.bm, volume.scale, n), D, mvp, res, res,
                               light=(0.8, -0.45, 0.4))
        if n == 25 and ours is not None:   # like for like: alternate frames
            t, out["render_time_same_work_s"] = _interleaved(gl.frame, ours)
        else:
            t, _ = _timed(gl.frame, 5, warm=2)
        covered = float((np.abs(gl.image() - np.array([0.12, 0.13, 0.15])).max(-1) > 0.02).mean())
        gl.release()
        out["llvmpipe_s" if n == 25 else f"llvmpipe_{n}_s"] = t
        out.setdefault("llvmpipe_coverage", covered)
    return out


def main(json: bool = False, quick: bool = False) -> int:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``); print JSON or one line per field."""
    from mi_displace.evaluate.metrics import flip

    sizes = QUICK if quick else FULL
    res = sizes.res
    raster = mi.load_dict({"type": "raster", "aa": 1})
    donut = SCENES / "slicing_donut.xml"
    r: dict = {"variant": mi.variant(), "resolution": res, "slices": 25, "direction": "best"}

    # like for like, first (a process that has drawn nothing else yet, as llvmpipe's
    # fresh context): our same-work frame alternating with llvmpipe's
    scene, _ = _load(donut, mode="approximation", integrator="raster", res=res, direction="a",
                     draw_base="false")
    next(s for s in scene.shapes() if hasattr(s, "volume")).bsdf_ref.self_shadows = False
    unshadowed = mi.load_dict({"type": "raster", "aa": 1, "shadows": "none"})
    same_work = lambda: _render(scene, unshadowed)
    r.update(donut_gl(scene, sizes.gl_slices, res, ours=same_work))
    if "render_time_same_work_s" not in r:   # no llvmpipe here: timed alone
        r["render_time_same_work_s"], _ = _timed(same_work, 5, warm=2)
    del scene

    # the sliced donut: build (warm) and render (warm)
    _load(donut, mode="approximation", integrator="raster", res=res)
    scene, build = _load(donut, mode="approximation", integrator="raster", res=res)
    r["build_time_warm_s"] = build
    r["render_time_warm_s"], approx = _timed(lambda: _render(scene, raster))
    shape = next(s for s in scene.shapes() if hasattr(s, "volume"))
    shape.rasterise = False
    r["render_time_walk_warm_s"], walked = _timed(lambda: _render(scene, raster))
    shape.rasterise = True
    r["flip_walk_vs_rasterised"] = flip(walked, approx)[0]
    stats = shape.build_stats
    r["slices_used"] = stats["slices_used"]
    r["slices_bytes"] = stats["bytes"]
    from mi_displace.slicing import geometry as geo

    volume = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
    walls = volume.walls.nbytes()
    r["slices_bytes_direction_a"] = geo.aligned_slices(volume.bm, volume.scale, 25).nbytes() + walls
    r["slices_bytes_screen"] = walls
    del scene
    scene, _ = _load(donut, mode="approximation", integrator="raster", res=res, direction="a")
    r["render_time_a_warm_s"], _ = _timed(lambda: _render(scene, raster))
    del scene
    scene, _ = _load(donut, mode="approximation", integrator="raster", res=res, slices="auto")
    r["auto_slices"] = next(s for s in scene.shapes() if hasattr(s, "volume")).build_stats["slices"]
    del scene
    scene, _ = _load(donut, mode="approximation", integrator="raster", res=res, direction="screen")
    r["render_time_screen_warm_s"], screen = _timed(lambda: _render(scene, raster))
    del scene

    # true displacement under raster: converged tessellation
    ref = {}
    coarse, fine = sizes.reference_resolutions
    for resolution in (coarse, fine):
        scene, build = _load(donut, mode="reference", integrator="raster", res=res,
                             resolution=resolution)
        t, ref[resolution] = _timed(lambda: _render(scene, raster))
        if resolution == fine:
            r["true_displacement_time_warm_s"], r["true_displacement_build_s"] = t, build
            r["displaced_bytes"] = scene.shapes()[0].build_stats["bytes"]
            r["displaced_faces"] = scene.shapes()[0].build_stats["faces"]
        del scene
    r["true_displacement_resolution"] = fine
    r["converged_flip"] = flip(ref[fine], ref[coarse])[0]
    r["flip"] = flip(ref[fine], approx)[0]
    r["flip_screen"] = flip(ref[fine], screen)[0]
    r["memory_ratio"] = r["displaced_bytes"] / r["slices_bytes"]

    # depth object: the cup at 400^2, 150 slices
    cup = SCENES / "slicing_cup_depth.xml"
    cup_params = dict(mode="approximation", integrator="raster", res=sizes.cup_res,
                      slices=sizes.cup_slices)
    _load(cup, **cup_params)
    scene, build = _load(cup, **cup_params)
    r["depth_object_build_s"] = build
    r["depth_object_time_warm_s"], _ = _timed(lambda: _render(scene, raster))
    obj = next(s for s in scene.shapes() if hasattr(s, "depth_object")).depth_object
    obj.skip_empty = False
    r["depth_object_time_noskip_warm_s"], _ = _timed(lambda: _render(scene, raster))
    del scene
    # the same-work frame again, at the end of a process that has drawn every scene above
    scene, _ = _load(donut, mode="approximation", integrator="raster", res=res, direction="a",
                     draw_base="false")
    next(s for s in scene.shapes() if hasattr(s, "volume")).bsdf_ref.self_shadows = False
    later = donut_gl(scene, (25,), res, ours=lambda: _render(scene, unshadowed))
    if "render_time_same_work_s" in later:   # alternating with a fresh llvmpipe context
        r["render_time_same_work_later_s"] = later["render_time_same_work_s"]
        r["llvmpipe_later_s"] = later["llvmpipe_s"]
    else:
        r["render_time_same_work_later_s"], _ = _timed(lambda: _render(scene, unshadowed), 5, warm=2)
    del scene
    if r.get("llvmpipe_s"):
        r["speedup_vs_llvmpipe"] = r["llvmpipe_s"] / r["render_time_warm_s"]
        r["speedup_vs_llvmpipe_same_work"] = r["llvmpipe_s"] / r["render_time_same_work_s"]
    if r.get("llvmpipe_later_s"):
        r["speedup_vs_llvmpipe_same_work_later"] = r["llvmpipe_later_s"] / r["render_time_same_work_later_s"]
    r["speedup_vs_true_displacement"] = r["true_displacement_time_warm_s"] / r["render_time_warm_s"]
    r["speedup_vs_walk"] = r["render_time_walk_warm_s"] / r["render_time_warm_s"]
    r["load_average"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    if json:
        print(_json.dumps(r, indent=2))
    else:
        for k, v in r.items():
            print(f"{k:32s} {v}")
    return 0
