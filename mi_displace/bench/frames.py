"""``mi-displace bench frames [--json] [--quick] [--out DIR]``: what a user feels per frame.

For every approximation on its packaged scene (:data:`ROWS`), and for ``raster`` on a
reference geometry, all in one process, at ``res`` x ``res`` pixels:

* ``load_s``: :func:`mi_displace.render.scene.load` (XML, plugin builds: tables, maps,
  slices, tessellation; ``fit_to_sensors``; acceleration structure), wall seconds;
* ``first_frame_s``: the first frame after the load (tracing + kernel compilation, or a
  kernel-cache hit when an earlier run compiled the same kernels); ``still_frame_s``: median
  of ``orbit`` more frames of the same view with nothing changed (what the other benchmarks
  call a warm render);
* ``orbit_frame_s``: median wall seconds of a frame after a camera move, over ``orbit``
  positions: the sensor's ``to_world`` edited through ``mi.traverse`` (a rotation of
  ±:data:`ORBIT_DEG` degrees about the camera's up axis through the scene's bounding-box
  centre, at angles new to each run: :func:`_spread`), :func:`mi_displace.fit_to_sensors`,
  render; ``orbit_first_s``: the first of them (the first frame from a new view);
* ``edit_frame_s``: median wall seconds of a frame after a ``mi.traverse`` edit of the row's
  main parameter (``edit_key``, scaled by factors spread over [1 - :data:`EDIT_SPAN`, 1 +
  :data:`EDIT_SPAN`]), over ``edits`` values; ``edit_first_s``: the first of them;
* ``fps`` = 1 / ``orbit_frame_s``, beside ``paper_fps`` (the paper's own frame rate on its
  GPU, ``paper`` says where; null when the paper gives none) and ``fps_vs_paper``;
* ``kernel_share``: of one extra orbit frame (``profiled_frame_s``, from a view between the
  first two positions, which no frame had yet) timed under ``dr.JitFlag.KernelHistory``, the
  share of its wall time spent in Dr.Jit's kernels and memory operations (the sum of
  ``execution_time`` of every ``dr.kernel_history()`` entry); the rest (``1 - share``) is
  Python, tracing, compilation and launches; ``kernels`` (launches in that frame),
  ``cache_misses`` (of them, kernels compiled anew: a view-dependent value traced as a
  constant), ``codegen_ms`` (Dr.Jit's IR generation), ``compile_ms`` (LLVM / PTX compilation
  of the misses); ``edit_profile``: the same of one more edit frame, at a value no frame had;
* ``fixed_frame_s``: the fixed cost per frame, the median frame with the film at
  :data:`FIXED_RES` squared (:func:`fixed_cost`; ``fixed_kernel_share``, ``fixed_kernels``);
* ``frozen_orbit_frame_s``, ``frozen_fps``: the orbit again with the frame frozen (``raster``
  with ``freeze`` on, :func:`frozen_orbit_frame`), median wall seconds and its rate; None
  where the frame is not frozen;
* ``frozen_frame_s``, ``frozen_ratio``, ``frozen_identical``, ``frozen_error``: the frame
  frozen on that film (``raster`` with ``freeze`` on; the volume slicer's whole ``mi.render``
  under ``dr.freeze``), against the plain frame, images compared bit for bit also after a
  camera move and an edit (:func:`freeze_lever`);
* ``peak_rss_mb``: the process's peak resident memory after the row
  (``resource.getrusage``), ``jit_peak_mb``: the peak of Dr.Jit's allocator for the variant's
  backend (``drjit.detail.malloc_watermark``); both only grow, so a row's own peak shows as a
  step from the row before.

Every frame is ``mi.render`` at one sample per pixel, as a GPU draws it and as the papers
measured: ``raster`` with ``aa=1``, the volume slicer with the scene's own settings but ``aa``
1 (one ray a pixel, each slice drawn once per pixel: :func:`frame_integrator`), evaluated
and synchronised.
Python's garbage is collected before and the collector paused during the timed frames.

``--quick`` runs every row with :data:`QUICK` sizes (64^2, 3 positions, 3 edits, small tables
and tessellations); ``--out DIR`` also writes ``frames_bench.json`` there.
"""
from __future__ import annotations

import gc
import json as _json
import resource
import statistics
import time
import warnings
from pathlib import Path
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bench._timing import output_dir
from mi_displace.core.dicing import fit_to_sensors
from mi_displace.core.resources import scene_path

#: Half the orbit's angle about the camera's up axis, degrees.
ORBIT_DEG = 20.0
#: The main parameter's edits span its loaded value times [1 - EDIT_SPAN, 1 + EDIT_SPAN].
EDIT_SPAN = 0.3


class Paper(NamedTuple):
    """The paper's own frame rate for a row: ``fps`` (low, high) frames per second, and
    ``source`` (paper, table or figure, the case, the GPU)."""
    fps: tuple | None
    source: str


class Row(NamedTuple):
    """One measured configuration: ``name``; the packaged ``scene`` file loaded with
    ``params`` (XML ``$name`` values, besides ``res``) and ``quick_params`` on top with
    ``--quick``; ``edit_key``: the ``mi.traverse`` key (or its ending, :func:`_edit_key`) of
    its main parameter, or where that is not exposed of a colour (a number or a colour, scaled
    by the edit factors);
    ``integrator``: ``"raster"`` (rendered by ``raster`` with ``aa=1``) or ``"volume_slicer"``
    (the scene's own, at one ray a pixel: :func:`frame_integrator`); ``paper``: the paper's
    frame rate."""
    name: str
    scene: str
    params: dict
    quick_params: dict
    edit_key: str
    integrator: str
    paper: Paper


_NO_RATE = Paper(None, "no frame rate in the papers of this project")
_VDM = Paper((112.0, 112.0), "VDM Fig. 9: torus, 4800 triangles, ATI Radeon 9700 Pro")
_SLICING = Paper((35.0, 40.0), "slicing paper, Fig. 1 and its timings: donut, 625 polygons, 15-25 slices, GeForce 2 GTS")
#: The edit of the rows whose main parameter (depth) ``mi.traverse`` does not expose: the
#: material's colour.
_MATERIAL = "vdm_material.reflectance.value"
_VDM_QUICK = {"vdm_res": 16, "vdm_phi": 8, "vdm_theta": 4, "vdm_curvatures": 4}
_DONUT_QUICK = {"coarse": 16}


def _torus(mode: str, key: str, paper: Paper, quick: dict | None = None) -> Row:
    return Row(mode if mode != "approximation" else "vdm", "vdm_torus.xml",
               {"mode": mode, "integrator": "raster"}, quick or {}, key, "raster", paper)


def _donut(direction: str) -> Row:
    return Row(f"slicing_{direction}", "slicing_donut.xml",
               {"mode": "approximation", "integrator": "raster", "direction": direction},
               _DONUT_QUICK, "scale", "raster", _SLICING)


ROWS = (
    _torus("bump", "bsdf.scale", _NO_RATE),
    _torus("relief", _MATERIAL, _NO_RATE),
    _torus("horizon", _MATERIAL, _NO_RATE),
    _torus("approximation", _MATERIAL, _VDM, _VDM_QUICK),
    _donut("a"),
    _donut("best"),
    _donut("screen"),
    Row("depth_object", "slicing_cup_depth.xml", {"mode": "approximation", "integrator": "raster"},
        {"slices": 32}, "irradiance.value", "raster",
        Paper((2.7, 2.7), "slicing §4, Fig. 12-14: creature depth object, 400^2 pixels, 150 slices, GeForce 2 GTS")),
    Row("hddm_maps", "ddm_thorns_sphere.xml", {"mode": "approximation", "integrator": "raster"},
        {}, "height", "raster",
        Paper((8.1, 8.5), "HDDM Table 1: human face, thorn tile, 430k vertices, GeForce 6600 / 6800")),
    Row("restored", "bake_bunny.xml", {"mode": "approximation", "integrator": "raster"},
        {}, "reflectance.value", "raster", _NO_RATE),
    Row("volume_slicer", "volume_nucleon_pull.xml",
        {"mode": "approximation", "integrator": "volume_slicer"}, {}, "volume.map0_amount", "volume_slicer",
        Paper((6.24, 18.81), "volume Table 1: 134-256 voxel data sets, 512^2, Quadro FX 4400")),
    Row("raster_reference", "vdm_torus.xml", {"mode": "reference", "integrator": "raster"},
        {"resolution": 256}, "scale", "raster", _NO_RATE),
)


class Sizes(NamedTuple):
    """What a run draws: frames of ``res`` x ``res`` pixels, ``orbit`` camera positions and
    ``edits`` parameter values per row; ``quick`` applies each row's ``quick_params``."""
    res: int
    orbit: int
    edits: int
    quick: bool


FULL = Sizes(512, 10, 10, False)
QUICK = Sizes(64, 3, 3, True)


def _timed(step) -> float:
    """Wall seconds of ``step()`` (queued kernels drained before and after)."""
    dr.sync_thread()
    start = time.perf_counter()
    step()
    dr.sync_thread()
    return time.perf_counter() - start


def _orbit(scene, angles) -> list:
    """Sensor ``to_world`` transforms: the loaded one rotated by each of ``angles`` (degrees)
    about the camera's up axis through the centre of the scene's bounding box (the world origin when the scene has no shape: a volume drawn by its
    integrator)."""
    to_world = mi.ScalarTransform4f(np.array(scene.sensors()[0].world_transform().matrix).reshape(4, 4))
    up = to_world @ mi.ScalarVector3f(0, 1, 0)
    box = scene.bbox()
    centre = mi.ScalarVector3f(box.center() if box.valid() else 0.0)
    return [mi.ScalarTransform4f().translate(centre) @ mi.ScalarTransform4f().rotate(up, float(angle))
            @ mi.ScalarTransform4f().translate(-centre) @ to_world
            for angle in angles]


def _spread(low: float, high: float, count: int, rng) -> np.ndarray:
    """``count`` increasing values in [low, high]: one in each of ``count`` equal strata, all at
    the same random place in theirs.  Random on purpose: a value traced into a kernel as a
    constant makes a new kernel, and a value an earlier run used would find that kernel in
    Dr.Jit's on-disk cache, which a user moving a camera or a slider does not."""
    return low + (np.arange(count) + rng.uniform()) * (high - low) / count


def _edit_key(params, key: str) -> str:
    """The one ``mi.traverse`` key equal to ``key`` or ending in ``"." + key`` (shapes and
    emitters without an id get an address as their prefix)."""
    found = [k for k in params.keys() if k == key or k.endswith("." + key)]
    if len(found) != 1:
        raise ValueError(f"edit_key {key!r}: {len(found)} matching scene parameters {found}")
    return found[0]


def _series(step, values) -> list:
    """Wall seconds of ``step(value)`` for each value, garbage collected before and the
    collector paused during the calls."""
    gc.collect()
    gc.disable()
    try:
        return [_timed(lambda: step(value)) for value in values]
    finally:
        gc.enable()


def _profile(step) -> dict:
    """One call of ``step`` under ``dr.JitFlag.KernelHistory``: wall seconds, the share spent
    in Dr.Jit's kernels and memory operations, the number of kernel launches, how many of them
    missed Dr.Jit's in-memory kernel cache, Dr.Jit's code-generation and the backend's
    compilation milliseconds."""
    dr.kernel_history()   # drop what earlier work left
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        wall = _timed(step)
    history = dr.kernel_history()
    kernels = [h for h in history if h["type"] == dr.KernelType.JIT]
    return {"profiled_frame_s": wall,
            "kernel_share": sum(h["execution_time"] for h in history) / 1e3 / wall,
            "kernels": len(kernels),
            "cache_misses": sum(1 for h in kernels if not h["cache_hit"]),
            "codegen_ms": sum(h["codegen_time"] for h in kernels),
            "compile_ms": sum(h["backend_time"] for h in kernels)}


def camera_move_profile(scene, angles, render) -> tuple[dict, bool, list]:
    """Render ``scene`` (``render()`` returns a NumPy image) from the first two of the
    :func:`_orbit` views at ``angles`` [degrees], then the third under :func:`_profile`.

    Returns:
        (the third frame's profile, whether the float32 camera matrix differs between the
        first and the third view, the three images).
    """
    sensor = mi.traverse(scene.sensors()[0])
    images = []

    def move(to_world):
        sensor["to_world"] = to_world
        sensor.update()
        images.append(render())

    first, second, third = _orbit(scene, angles)
    move(first)
    move(second)
    profile = _profile(lambda: move(third))
    moved = not np.array_equal(np.array(first.matrix, np.float32), np.array(third.matrix, np.float32))
    return profile, moved, images


#: Film side of the frames that measure the fixed cost per frame (:func:`fixed_cost`), pixels.
FIXED_RES = 8


def fixed_cost(sensor, frame, count: int) -> dict:
    """What a frame costs that has (almost) no pixels: the film of ``sensor`` (its
    ``mi.traverse`` parameters) set to :data:`FIXED_RES` squared, one frame to compile, then
    ``fixed_frame_s``: the median wall seconds of ``count`` calls of ``frame()`` — Python,
    tracing, launches and the passes whose size does not follow the film (slices, tables,
    light grids), with ``fixed_kernel_share`` and ``fixed_kernels`` of one more under
    :func:`_profile`.  The film stays at that size."""
    sensor["film.size"] = mi.ScalarVector2u(FIXED_RES, FIXED_RES)
    sensor.update()
    frame()
    times = _series(lambda _: frame(), range(count))
    profile = _profile(frame)
    return {"fixed_frame_s": statistics.median(times), "fixed_kernel_share": profile["kernel_share"],
            "fixed_kernels": profile["kernels"]}


def freeze_lever(plain, frozen, changes, count: int, refused=lambda: None) -> dict:
    """The frame frozen, measured on the film :func:`fixed_cost` left: the frames
    ``plain()`` and ``frozen()`` (the second recorded on its first call), each timed
    ``count`` times after one untimed call; their images compared bit for bit now and after
    each of ``changes`` (a camera move, an edit): a value the recording held as a constant
    that the edit changed shows as a different image.

    ``refused()`` says after the first frozen call why it drew unfrozen (``raster``'s
    ``freeze`` falls back, :class:`mi_displace.render.raster.FrozenFrames`), or ``None``;
    a ``RuntimeError`` from ``frozen()`` (``dr.freeze`` of a whole ``mi.render``) is a
    refusal too.

    Returns ``frozen_frame_s`` (median), ``frozen_ratio`` (frozen / plain medians),
    ``frozen_identical`` (all images equal) and ``frozen_error`` (why it was not frozen:
    the first line of the reason; the other fields are then None)."""
    def image(render):
        return np.array(render())

    try:
        with warnings.catch_warnings():   # the refusal is this record's field, not a warning
            warnings.simplefilter("ignore")
            image(frozen)
        why = refused()
    except RuntimeError as error:   # dr.freeze refused to record (a read-back inside)
        why = str(error.__cause__ or error).strip().splitlines()[0]   # the cause names the reason
    if why is not None:
        return {"frozen_frame_s": None, "frozen_ratio": None, "frozen_identical": None, "frozen_error": why}
    image(plain)
    plain_s = statistics.median(_series(lambda _: image(plain), range(count)))
    frozen_s = statistics.median(_series(lambda _: image(frozen), range(count)))
    identical = np.array_equal(image(plain), image(frozen))
    for change in changes:
        change()
        identical &= np.array_equal(image(plain), image(frozen))
    return {"frozen_frame_s": frozen_s, "frozen_ratio": frozen_s / plain_s,
            "frozen_identical": bool(identical), "frozen_error": None}


def frozen_orbit_frame(first, refused, move, views) -> float | None:
    """The orbit again with the frame frozen (``first()`` records it, ``move(view)`` moves
    the camera and draws): the median wall seconds, or ``None`` when it was not frozen
    (``refused()``, or ``dr.freeze`` raised)."""
    try:
        with warnings.catch_warnings():   # the refusal is freeze_lever's field, not a warning
            warnings.simplefilter("ignore")
            first()
    except RuntimeError:   # dr.freeze refused to record: freeze_lever reports why
        return None
    if refused() is not None:
        return None
    return statistics.median(_series(move, views))


def frozen_frame(row: Row, scene, integrator):
    """``(frame, refused)`` for :func:`freeze_lever`: for ``"raster"`` rows the same
    ``raster`` with ``freeze`` on (what a user sets), else the whole ``mi.render`` under
    ``dr.freeze``."""
    if row.integrator == "raster":
        frozen = mi.load_dict({"type": "raster", "aa": 1, "freeze": True})
        return (lambda: mi.render(scene, integrator=frozen, spp=1),
                lambda: frozen.frozen.refused.get(id(scene)))
    whole = dr.freeze(lambda scene, integrator: mi.render(scene, integrator=integrator, spp=1))
    return lambda: whole(scene, integrator), lambda: None


def frame_integrator(row: Row, scene):
    """What draws ``row``'s frames at one sample per pixel: ``raster`` with ``aa=1`` for
    ``"raster"`` rows; for ``"volume_slicer"`` rows the scene's own ``volume_slicer`` with its
    ``aa`` set to 1 (the packaged scenes use 2, i.e. 4 rays a pixel, for their comparisons
    against ``volpath``; the paper draws each slice once per pixel)."""
    if row.integrator == "raster":
        return mi.load_dict({"type": "raster", "aa": 1})
    integrator = scene.integrator()
    integrator.settings.aa = 1
    return integrator


def measure(row: Row, sizes: Sizes) -> dict:
    """The record of one row (fields in the module doc)."""
    from mi_displace.render.scene import load

    params = {**row.params, **(row.quick_params if sizes.quick else {}), "res": sizes.res}
    rng = np.random.default_rng()   # unseeded on purpose: see _spread
    gc.collect()
    scene, timings = load(scene_path(row.scene), **params)
    integrator = frame_integrator(row, scene)

    images = []

    def frame():
        images[:] = [mi.render(scene, integrator=integrator, spp=1)]
        dr.eval(images[0])

    def check():   # after a series, not inside the timed frames
        if not np.isfinite(np.asarray(images[0])).all():
            raise FloatingPointError(f"bench frames: row {row.name!r} rendered NaN or Inf")

    first = _timed(frame)
    still = _series(lambda _: frame(), range(sizes.orbit))
    sensor = mi.traverse(scene.sensors()[0])

    def move(to_world, draw=frame):
        sensor["to_world"] = to_world
        sensor.update()
        fit_to_sensors(scene)
        draw()

    angles = _spread(-ORBIT_DEG, ORBIT_DEG, sizes.orbit, rng)
    orbit = _series(move, _orbit(scene, angles))
    check()
    unseen = _orbit(scene, [(angles[0] + angles[1]) / 2])[0]   # a view no frame had yet
    profile = _profile(lambda: move(unseen))

    edits = mi.traverse(scene)
    key = _edit_key(edits, row.edit_key)
    loaded = type(edits[key])(edits[key])

    def edit(factor):
        edits[key] = loaded * float(factor)
        edits.update()
        frame()

    factors = _spread(1 - EDIT_SPAN, 1 + EDIT_SPAN, sizes.edits, rng)
    edit_times = _series(edit, factors)
    check()
    edit_profile = _profile(lambda: edit((factors[0] + factors[1]) / 2))   # a value new to this run
    frozen_call, refused = frozen_frame(row, scene, integrator)
    frozen_orbit = frozen_orbit_frame(lambda: dr.eval(frozen_call()), refused,
                                      lambda to_world: move(to_world, lambda: dr.eval(frozen_call())),
                                      _orbit(scene, angles))
    fixed = fixed_cost(sensor, frame, sizes.orbit)
    frozen = freeze_lever(lambda: mi.render(scene, integrator=integrator, spp=1), frozen_call,
                          [lambda: move(unseen), lambda: edit(factors[0])], sizes.orbit, refused)
    orbit_s = statistics.median(orbit)
    paper = max(row.paper.fps) if row.paper.fps else None
    record = {
        "name": row.name, "scene": row.scene,
        "params": {k: str(v) for k, v in params.items()},
        "integrator": str(integrator).split("[")[0],
        "load_s": timings["build_s"], "first_frame_s": first,
        "still_frame_s": statistics.median(still),
        "orbit_first_s": orbit[0], "orbit_frame_s": orbit_s,
        "edit_key": key.split(".", 1)[1] if key.startswith("object_") else key,
        "edit_first_s": edit_times[0], "edit_frame_s": statistics.median(edit_times),
        "fps": 1.0 / orbit_s,
        "paper_fps": list(row.paper.fps) if row.paper.fps else None, "paper": row.paper.source,
        "fps_vs_paper": (1.0 / orbit_s) / paper if paper else None,
        **profile,
        "edit_profile": edit_profile,
        "frozen_orbit_frame_s": frozen_orbit,
        "frozen_fps": 1.0 / frozen_orbit if frozen_orbit else None,
        **fixed,
        **frozen,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "jit_peak_mb": dr.detail.malloc_watermark(dr.backend_v(mi.Float)) / 2**20,
    }
    del scene, integrator, edits, sensor
    gc.collect()
    return record


def run(sizes: Sizes = FULL) -> dict:
    """Every row of :data:`ROWS` at ``sizes``, in one process."""
    import os

    from mi_displace.core.progress import stage

    rows = []
    for row in ROWS:   # a progress line per row (the mi_displace logger)
        with stage(f"bench frames: {row.name} at {sizes.res}^2"):
            rows.append(measure(row, sizes))
    return {"variant": mi.variant(), "resolution": sizes.res, "orbit_positions": sizes.orbit,
            "edits": sizes.edits, "orbit_deg": ORBIT_DEG, "edit_span": EDIT_SPAN,
            "rows": rows, "cpu_count": os.cpu_count(), "load_average": os.getloadavg()[0]}


def _frozen_cell(r: dict) -> str:
    """The frozen fixed cost of a row in ms and its ratio to the plain one, "≠" after it
    when the images differed, or "not frozen"."""
    if r["frozen_ratio"] is None:
        return "not frozen"
    return (f"{1e3 * r['frozen_frame_s']:.1f} ({r['frozen_ratio']:.2f}×)"
            + ("" if r["frozen_identical"] else " ≠"))


def _ms(seconds) -> str:
    return "–" if seconds is None else f"{1e3 * seconds:.0f}"


def markdown(record: dict) -> str:
    """The rows of ``record`` as a markdown table (milliseconds for frames, seconds for loads)."""
    def cell(value, fmt):
        return "–" if value is None else format(value, fmt)

    lines = ["| row | load s | first frame s | still frame ms | orbit frame ms | edit frame ms | fps "
             "| paper fps | × paper | kernels % | launches (compiled) | compile ms orbit / edit "
             f"| frozen orbit ms | fixed ms ({FIXED_RES}²) | frozen fixed ms (× plain) | peak RSS MB "
             "| Dr.Jit peak MB |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in record["rows"]:
        paper = "–" if r["paper_fps"] is None else "–".join(f"{f:g}" for f in dict.fromkeys(r["paper_fps"]))
        lines.append(
            f"| {r['name']} | {r['load_s']:.2f} | {r['first_frame_s']:.2f} | {1e3 * r['still_frame_s']:.0f} "
            f"| {1e3 * r['orbit_frame_s']:.0f} | {1e3 * r['edit_frame_s']:.0f} | {r['fps']:.1f} | {paper} "
            f"| {cell(r['fps_vs_paper'], '.2f')} | {100 * r['kernel_share']:.0f} "
            f"| {r['kernels']} ({r['cache_misses']}) | {r['compile_ms']:.0f} / {r['edit_profile']['compile_ms']:.0f} "
            f"| {_ms(r['frozen_orbit_frame_s'])} | {1e3 * r['fixed_frame_s']:.1f} | {_frozen_cell(r)} "
            f"| {r['peak_rss_mb']:.0f} "
            f"| {r['jit_peak_mb']:.0f} |")
    return "\n".join(lines)


#: Each technique's guide (docs/NAME.md) and the rows of its frames table, written between
#: :data:`GUIDE_BEGIN` and :data:`GUIDE_END` by :func:`write_guides`.
GUIDES = {"vdm.md": ("bump", "relief", "horizon", "vdm"),
          "slicing.md": ("slicing_a", "slicing_best", "slicing_screen", "depth_object"),
          "ddm.md": ("hddm_maps",), "bake.md": ("restored",), "volume.md": ("volume_slicer",),
          "raster.md": ("raster_reference",)}
GUIDE_BEGIN, GUIDE_END = "<!-- frames table: begin -->", "<!-- frames table: end -->"
DOCS = Path(__file__).resolve().parents[2] / "docs"


def guide_table(record: dict, names) -> str:
    """The frames table of one guide: ``names``' rows of ``record`` (the orbit frame, the
    fixed cost, the paper's rate and the ratio to it, both frames with ``freeze``), the
    command and the machine's load."""
    rows = {r["name"]: r for r in record["rows"]}
    lines = [f"`mi-displace bench frames --out docs/figures` ([frames](frames.md), "
             f"`figures/frames_bench.json`): {record['resolution']}², one sample per pixel, "
             f"`{record['variant']}`, {record['cpu_count']} cores, load average "
             f"{record['load_average']:.1f} at the end of the run.", "",
             "| row | orbit frame ms | fps | paper fps | × paper | fixed ms (8²) | with `freeze`: "
             "orbit frame ms / fixed ms | load s |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name in names:
        r = rows[name]
        paper = "–" if r["paper_fps"] is None else "–".join(f"{f:g}" for f in dict.fromkeys(r["paper_fps"]))
        ratio = "–" if r["fps_vs_paper"] is None else f"{r['fps_vs_paper']:.2f}"
        frozen = ("not frozen" if r["frozen_frame_s"] is None
                  else f"{_ms(r['frozen_orbit_frame_s'])} / {1e3 * r['frozen_frame_s']:.1f}")
        lines.append(f"| `{name}` | {1e3 * r['orbit_frame_s']:.0f} | {r['fps']:.1f} | {paper} | {ratio} "
                     f"| {1e3 * r['fixed_frame_s']:.1f} | {frozen} | {r['load_s']:.2f} |")
    return "\n".join(lines)


def guide_text(text: str, record: dict, names) -> str:
    """``text`` (a guide) with its frames table (between the markers) made from ``record``."""
    start, end = text.index(GUIDE_BEGIN) + len(GUIDE_BEGIN), text.index(GUIDE_END)
    return text[:start] + "\n" + guide_table(record, names) + "\n" + text[end:]


def write_guides(record: dict, docs: Path = DOCS) -> None:
    """Rewrite the frames table of every guide of :data:`GUIDES` in ``docs`` from ``record``."""
    for page, names in GUIDES.items():
        path = docs / page
        path.write_text(guide_text(path.read_text(), record, names))


def main(json: bool = False, quick: bool = False, out=None) -> dict:
    """Run every row (:data:`QUICK` sizes with ``quick``); print JSON (``json``) or the markdown
    table; with ``out`` also write ``frames_bench.json`` there."""
    record = run(QUICK if quick else FULL)
    if out is not None:
        (output_dir("frames", out) / "frames_bench.json").write_text(_json.dumps(record, indent=2) + "\n")
    print(_json.dumps(record, indent=2) if json else markdown(record))
    return record


if __name__ == "__main__":   # python -m mi_displace.bench.frames: the guides' tables from the record
    write_guides(_json.loads((DOCS / "figures" / "frames_bench.json").read_text()))
