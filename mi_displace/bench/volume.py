"""`mi-displace bench volume`: the slicing renderer's speed with and without displacement,
texture memory, accuracy, and VTK's CPU volume renderer on the same volume.

* ``voxels``: the walnut CT resampled to 256^3 (trilinear), box [-0.5, 0.5]^3;
* ``render_time_warm_s``: ``volume_slicer`` at 512 x 512, one voxel between slices, one map
  (a Gaussian pull, eq. 8, over the upper half, D_k 32^3 at 16 bit), Jacobian normals
  (eq. 6), surface model without shadows (as VTK), warm median of REPEATS (15) renders that
  alternate with the undisplaced ones (a shared machine's load falls on both alike);
  ``undisplaced_time_warm_s``: the same volume and view without the map, same process;
  ``displacement_overhead`` = their ratio (Table 1 analogue: ``fps`` = 1 / render time),
  ``displacement_overhead_cpu`` the same ratio of CPU (process) times;
* ``coverage`` / ``undisplaced_coverage``: the fraction of pixels with radiance > 0 in the
  displaced / undisplaced frame (the pull raises the walnut: it covers more of the screen);
  ``overhead_per_covered_pixel``: the overhead in time per covered pixel, the part of
  ``displacement_overhead`` not explained by the bigger footprint (the headline keeps the
  issue's definition);
* ``texture_bytes``: the map's stored D_k, α, J and ∇α channels at 16 bit; ``object_texture_bytes``:
  the object and gradient textures (float32); ``table2``: bytes of each primitive at the
  paper's Table 2 resolutions (full format and stored channels);
* ``flip``: ``mi-displace compare scenes/volume_walnut_peel.xml`` at 96 x 96, references
  capped at 256 spp (with its ``noise_floor_flip``);
* ``vtk_s``: VTK's ``vtkFixedPointVolumeRayCastMapper`` on the undisplaced 256^3 volume,
  512 x 512, sample distance 1.0, automatic adjustment off, shading on, 2 threads, EGL
  off-screen window, warm median of 3; ``null`` with ``vtk_reason`` ("peer unavailable:
  ...") when ``vtk`` or Mesa's EGL is missing (:mod:`mi_displace.bench.peers.vtk_volume`;
  ``scripts/setup_peers.sh`` installs them).

* ``gridvolume``: the exact reference against Mitsuba's own medium (:func:`gridvolume_comparison`):
  ``volume_walnut_peel.xml`` in ``reference`` mode (``volpath``, the ``displaced_volume`` on
  the exact peel) and the same scene with the volume replaced by a ``gridvolume`` holding
  that field resampled at the walnut's voxel size over the medium box
  (:meth:`~mi_displace.volume.field.DisplacedVolume.resample`), same sensor, lights,
  integrator and spp (``grid_res``², ``grid_spp``), warm median of ``grid_repeats`` renders
  alternating between the two: ``time_ratio`` = ours / grid (target <= 2), ``flip`` between
  the two images (``flip_noise_floor``: between two of our renders, other seeds),
  ``mean_ratio`` of their mean radiance, the grid's shape and bytes.

``--quick`` runs the same with :data:`QUICK` sizes (a 64^3 walnut, 128^2 frames, 2 warm
renders each, the comparison at 32^2 with references capped at 16 spp, the grid comparison
at 32^2 and 4 spp).
"""
from __future__ import annotations

import statistics
import tempfile
import time
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bench._timing import print_record
from mi_displace.core.resources import data_path, scene_path

WALNUT = data_path("volumes", "walnut_128x96x114_uint16.raw")
SCENE = scene_path("volume_walnut_peel.xml")
RES, SIZE, ISO = 256, 512, 0.3
EYE, TARGET, FOV = (0.9, -2.3, 1.3), (0.0, 0.0, 0.0), 34.0
TARGETS = {"undisplaced_vs_vtk": 2.0, "displacement_overhead": 1.6}
#: Warm renders of each frame (after a cold one); at 0.05-0.1 s a frame, 5 left the ratio
#: drifting by +-0.3 between runs on a loaded machine
REPEATS = 15


class Sizes(NamedTuple):
    """What a run renders: the walnut resampled to ``voxels``^3, frames of ``size`` x
    ``size`` pixels, ``repeats`` warm renders of each, the comparison scene at ``flip_res``
    x ``flip_res`` with references capped at ``flip_max_spp``; the gridvolume comparison at
    ``grid_res`` x ``grid_res``, ``grid_spp`` spp, ``grid_repeats`` warm renders each."""
    voxels: int
    size: int
    repeats: int
    flip_res: int
    flip_max_spp: int
    grid_res: int = 256
    grid_spp: int = 64
    grid_repeats: int = 3


FULL = Sizes(RES, SIZE, REPEATS, 96, 256)
QUICK = Sizes(64, 128, 2, 32, 16, 32, 4, 1)

#: Paper's Table 2 maps: (primitive, resolution); our D_k needs >= 2 nodes per axis.
TABLE2 = [("peel", (128, 128, 2), 320), ("slabs", (128, 128, 2), 320),
          ("gaussian", (32, 32, 32), 640), ("seam", (64, 64, 64), 5120)]


def walnut_256(voxels: int = RES):
    """The walnut CT resampled to ``voxels``^3 (trilinear; default 256), as an ObjectVolume
    in [-0.5, 0.5]^3."""
    from scipy.ndimage import zoom

    from mi_displace.volume.objects import ObjectVolume, load_raw

    w = load_raw(WALNUT)
    data = zoom(w.data, (voxels / w.shape[0], voxels / w.shape[1], voxels / w.shape[2]), order=1)
    return ObjectVolume(data, [-0.5] * 3, [0.5] * 3, value_range=(0.0, 1.0),
                        name=f"walnut {voxels}^3")


# The bench frame's light, the Gaussian pull's placement M (§6) and the volumes' transfer
# settings, shared with scripts/volume_before_after.sh and scripts/volume_flag_ab.py.
PULL = ("gaussian", {"amount": 0.5, "sigma": 0.15})
PULL_RESOLUTION = (32, 32, 32)
PULL_TO_WORLD = np.array([[1.0, 0, 0, -0.5], [0, 1, 0, -0.5], [0, 0, 0.5, 0], [0, 0, 0, 1]])
VOLUME_KW = dict(mode="approximation", tf_low=0.0, tf_high=1.0)


def sun_scene():
    """The bench frame's scene: one directional light (irradiance 2.5), nothing else."""
    return mi.load_dict({"type": "scene", "sun": {"type": "directional", "direction": [-0.5, 0.6, -1],
                                                  "irradiance": {"type": "rgb", "value": 2.5}}})


def _sensor(size: int = SIZE):
    return mi.load_dict({"type": "perspective", "fov": FOV,
                         "to_world": mi.ScalarTransform4f().look_at(origin=list(EYE), target=list(TARGET), up=[0, 0, 1]),
                         "film": {"type": "hdrfilm", "width": size, "height": size}})


def _interleaved_renders(scene, sensor, volumes, settings, repeats=REPEATS) -> list[tuple[float, float, float, np.ndarray]]:
    """(cold, warm median, warm median CPU time, image) per volume; the warm renders alternate
    between the volumes so that a shared machine's load falls on all of them alike (CPU time,
    i.e. process time of all threads, is the less load-sensitive of the two)."""
    from mi_displace.volume import slicer

    times = [[] for _ in volumes]
    cpu = [[] for _ in volumes]
    images = [None] * len(volumes)
    for _ in range(repeats + 1):
        for i, vol in enumerate(volumes):
            dr.sync_thread()
            start, start_cpu = time.perf_counter(), time.process_time()
            images[i] = np.array(slicer.render(scene, sensor, vol, settings))
            times[i].append(time.perf_counter() - start)
            cpu[i].append(time.process_time() - start_cpu)
    for img in images:
        if not np.isfinite(img).all():
            raise ValueError("bench volume: non-finite pixels in the slicer's image")
    return [(t[0], statistics.median(t[1:]), statistics.median(c[1:]), img) for t, c, img in zip(times, cpu, images)]


def vtk_time(obj, size: int = SIZE) -> tuple[float | None, str | None]:
    """VTK fixed-point ray casting of the undisplaced volume (module docstring): ``(seconds,
    None)``, or ``(None, "peer unavailable: <why>")``."""
    from mi_displace.bench.peers import measure, vtk_volume

    return measure(vtk_volume.raycast_time, obj, EYE, TARGET, FOV, size, ISO)


def table2() -> list[dict]:
    """Texture bytes of each primitive at the paper's Table 2 resolutions (16 bit): the full
    16-channel format (``kb``) and the non-zero channels actually stored (``stored_kb``)."""
    from mi_displace.volume.displacement import PlacedMap

    rows = []
    for kind, res, paper_kb in TABLE2:
        s = PlacedMap(kind, resolution=res).sampled(16, 1.5)
        rows.append({"map": kind, "resolution": list(res), "kb": s.nbytes(all_channels=True) / 1024,
                     "stored_kb": s.nbytes() / 1024, "paper_kb": paper_kb})
    return rows


def displaced_volume_of(medium):
    """The ``displaced_volume`` plugin that is ``medium``'s sigma_t (found among the objects
    ``mi.traverse(medium)`` reaches: the one with a ``medium_box``), or a ValueError."""
    found = [node for _, _, node, _ in mi.traverse(medium).properties.values() if hasattr(node, "medium_box")]
    if not found:
        raise ValueError("gridvolume comparison: the scene's medium has no displaced_volume sigma_t "
                         "with editable maps")
    return found[0]


def grid_scene(scene, shape=None):
    """``scene`` (one ``volume_proxy`` holding a ``heterogeneous`` medium whose sigma_t is a
    ``displaced_volume``) with that medium's sigma_t replaced by a Mitsuba ``gridvolume``: the
    volume resampled (:meth:`~mi_displace.volume.field.DisplacedVolume.resample`) on ``shape``
    (nz, ny, nx) cells over the medium box (default: the object's voxel size), inside a
    ``cube`` of that box; same sensor, lights, integrator, albedo, phase function and scale.

    Returns:
        (the grid scene, the grid's (nz, ny, nx) shape).
    """
    holder = next((s for s in scene.shapes() if s.interior_medium() is not None), None)
    if holder is None:
        raise ValueError("gridvolume comparison: the scene has no shape with an interior medium")
    medium = holder.interior_medium()
    plugin = displaced_volume_of(medium)
    lo, hi = (np.asarray(b, float) for b in plugin.medium_box())
    if shape is None:
        shape = np.maximum(np.ceil((hi - lo) / plugin.volume.obj.voxel_size - 1e-6), 2).astype(int)[::-1]
    data = plugin.volume.resample(lo, hi, shape)
    params = mi.traverse(medium)
    scene_dict = {
        "type": "scene", "integrator": scene.integrator(), "sensor": scene.sensors()[0],
        "box": {"type": "cube", "bsdf": {"type": "null"},
                "to_world": mi.ScalarTransform4f().translate(mi.ScalarPoint3f((lo + hi) / 2))
                .scale(mi.ScalarVector3f((hi - lo) / 2)),
                "interior": {"type": "heterogeneous", "phase": medium.phase_function(),
                             "scale": float(params["scale"]),
                             "albedo": float(params["albedo.value.value"][0]),
                             "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(data[..., None]),
                                         "to_world": mi.ScalarTransform4f().translate(mi.ScalarPoint3f(lo))
                                         .scale(mi.ScalarVector3f(hi - lo))}}}}
    scene_dict.update({f"emitter_{i}": e for i, e in enumerate(scene.emitters())})
    return mi.load_dict(scene_dict), tuple(int(s) for s in shape)


def gridvolume_comparison(sizes: Sizes = FULL) -> dict:
    """The ``gridvolume`` part of the record (module docstring)."""
    from mi_displace.evaluate.metrics import assert_finite, flip
    from mi_displace.render.scene import load

    scene, _ = load(SCENE, mode="reference", res=sizes.grid_res, spp=sizes.grid_spp)
    start = time.perf_counter()
    grid, shape = grid_scene(scene)
    resample_s = time.perf_counter() - start
    times, images = {"ours": [], "grid": []}, {"ours": [], "grid": []}
    for repeat in range(sizes.grid_repeats + 1):   # the first of each is cold
        for name, s in (("ours", scene), ("grid", grid)):
            dr.sync_thread()
            start = time.perf_counter()
            image = mi.render(s, spp=sizes.grid_spp, seed=repeat)
            dr.eval(image)
            dr.sync_thread()
            times[name].append(time.perf_counter() - start)
            images[name].append(assert_finite(image, f"gridvolume comparison: {name}"))
    ours, grid_s = (statistics.median(times[k][1:]) for k in ("ours", "grid"))
    return {"resolution": [sizes.grid_res, sizes.grid_res], "spp": sizes.grid_spp,
            "grid_shape": list(shape), "grid_bytes": int(np.prod(shape)) * 4, "resample_s": resample_s,
            "reference_s": ours, "gridvolume_s": grid_s, "time_ratio": ours / grid_s,
            "reference_cold_s": times["ours"][0], "gridvolume_cold_s": times["grid"][0],
            "flip": flip(images["grid"][-1], images["ours"][-1])[0],
            "flip_noise_floor": flip(images["ours"][0], images["ours"][-1])[0],
            "mean_ratio": float(images["ours"][-1].mean() / images["grid"][-1].mean()), "target": 2.0}


def run(sizes: Sizes = FULL, with_flip: bool = True) -> dict:
    from mi_displace.volume import slicer
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap
    from mi_displace.volume.field import DisplacedVolume

    obj = walnut_256(sizes.voxels)
    sensor = _sensor(sizes.size)
    scene = sun_scene()
    settings = slicer.SliceSettings(model="surface", normals="jacobian", spacing=1.0, shadows=False, iso=ISO)
    pull = PlacedMap(*PULL, resolution=PULL_RESOLUTION, to_world=PULL_TO_WORLD)
    plain = DisplacedVolume(obj, DisplacementChain([]), **VOLUME_KW)
    displaced = DisplacedVolume(obj, DisplacementChain([pull], bits=16), **VOLUME_KW)
    (cold_u, warm_u, cpu_u, img_u), (cold_d, warm_d, cpu_d, img_d) = _interleaved_renders(
        scene, sensor, [plain, displaced], settings, sizes.repeats)
    vtk_s, vtk_reason = vtk_time(obj, sizes.size)
    coverage_u, coverage_d = (float((img.max(-1) > 0).mean()) for img in (img_u, img_d))
    record = {
        "voxels": int(obj.data.size),
        "resolution": [sizes.size, sizes.size],
        "render_time_warm_s": warm_d,
        "render_time_cold_s": cold_d,
        "undisplaced_time_warm_s": warm_u,
        "undisplaced_time_cold_s": cold_u,
        "displacement_overhead": warm_d / warm_u,
        "displacement_overhead_cpu": cpu_d / cpu_u,
        "fps": 1.0 / warm_d,
        "texture_bytes": displaced.chain.nbytes(),
        "object_texture_bytes": obj.nbytes(),
        "coverage": coverage_d,
        "undisplaced_coverage": coverage_u,
        "overhead_per_covered_pixel": (warm_d / coverage_d) / (warm_u / coverage_u),
        "vtk_s": vtk_s,
        "vtk_reason": vtk_reason,
        "undisplaced_vs_vtk": (warm_u / vtk_s) if vtk_s else None,
        "table2": table2(),
        "gridvolume": gridvolume_comparison(sizes),
        "targets": TARGETS,
        "variant": mi.variant(),
    }
    if with_flip:
        from mi_displace.evaluate.compare import compare

        with tempfile.TemporaryDirectory() as tmp:
            r = compare(SCENE, tmp, params={"res": sizes.flip_res}, max_spp=sizes.flip_max_spp)
        record.update(flip=r["flip_mean"], flip_noise_floor=r["noise_floor_flip"],
                      flip_reference_spp=r["reference_spp"])
    return record


def main(json: bool = False, quick: bool = False) -> dict:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and print its record."""
    record = run(QUICK if quick else FULL)
    print_record(record, json, width=26)
    return record
