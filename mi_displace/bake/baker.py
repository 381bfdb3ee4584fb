"""The baker (§3): displacement and normal maps of a high-poly over a low-poly.

Pipeline (every per-texel step is Dr.Jit; see each module):

1. inputs — load both meshes; no low-poly: :func:`unwrap.make_low_poly`; no UVs:
   :func:`unwrap.unwrap` (xatlas), both noted in ``bake.json``;
2. :class:`trace.HighPoly` builds Mitsuba's acceleration structure over the high-poly (the
   paper's clipping tree, §3.3) and :class:`uv_raster.UVLayout` the flat UV layout;
3. per block of texel rows (at most :data:`CHUNK_SAMPLES` samples, §4 "render them in parts
   and then assemble"): :func:`uv_raster.rasterize_rows` -> :func:`trace.trace` ->
   per-texel averages of the aa x aa samples (scatter-add);
4. edge padding (:mod:`padding`), maps in every requested format (:mod:`formats`), the
   diagnostics image (:mod:`diagnostics`) and ``bake.json``.

Units: distances in the meshes' object units; resolutions in texels.
"""
from __future__ import annotations

import datetime
import json
import math
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake import diagnostics as diag
from mi_displace.bake import albedo, curvature, formats, occlusion, padding, surface_maps, unwrap
from mi_displace.bake.fragments import write_fragments
from mi_displace.bake.meshdata import (MeshData, check_mesh, defect_summary, edge_counts,
                                       face_defects, load_mesh, save_obj, uv_triangle_stats,
                                       weld_ids)
from mi_displace.bake.mikktspace import mikktspace
from mi_displace.bake.trace import AMBIGUOUS, EMPTY, HighPoly, LowPolyDevice, OK, trace
from mi_displace.bake.uv_raster import (OVERLAP_RESOLUTION, UVLayout, overlap_texels,
                                        rasterize_rows)

CHUNK_SAMPLES = 1 << 20        # samples per block of rows (bounds device memory)
BYTES_PER_TEXEL = 172          # host: maps, status, padding transform and encoded copies
BYTES_PER_SAMPLE = 252         # device: samples, rays, intersections, interpolated frame
MAX_RESOLUTION = 16384
DISTANCE_MARGIN = 1.5           # default max_distance = margin x one-sided Hausdorff low -> high
DISTANCE_FLOOR_REL = 0.005      # ... plus this fraction of the high-poly's diagonal
DISTANCE_SAMPLES = 20_000       # low-poly surface samples of that Hausdorff distance
DEFAULT_DELTA_REL = 1e-5


def default_max_distance(high: MeshData, low: MeshData) -> tuple[float, dict]:
    """The search distance derived from the pair: DISTANCE_MARGIN x the one-sided Hausdorff
    distance of the low-poly to the high-poly (how far the high-poly strays from it, measured
    on the low-poly's vertices and DISTANCE_SAMPLES area samples) + DISTANCE_FLOOR_REL of the
    diagonal [object units].  A fixed fraction of the diagonal lets texels on thin parts reach
    far surfaces; this stays as close as the pair allows."""
    from trimesh.sample import sample_surface

    from mi_displace.evaluate.metrics import point_mesh_distance

    start = time.perf_counter()
    points, _ = sample_surface(low.to_trimesh(), DISTANCE_SAMPLES, seed=0)
    points = np.concatenate([points, low.positions.astype(np.float64)])
    hausdorff = float(point_mesh_distance(points, high.to_trimesh()).max())
    distance = DISTANCE_MARGIN * hausdorff + DISTANCE_FLOOR_REL * high.diagonal
    return distance, {"rule": f"{DISTANCE_MARGIN} x one-sided Hausdorff low->high + "
                              f"{DISTANCE_FLOOR_REL:g} x diagonal",
                      "hausdorff_low_to_high": hausdorff, "seconds": time.perf_counter() - start}


def available_memory() -> int:
    """Bytes of memory available to this process (MemAvailable of /proc/meminfo)."""
    env = os.environ.get("MI_DISPLACE_BAKE_MEMORY")
    if env:
        return int(float(env))
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 8 << 30


def memory_estimate(width: int, height: int, aa: int) -> int:
    """Peak bytes of a bake: host maps plus one block of device samples."""
    samples = min(width * height * aa * aa, max(CHUNK_SAMPLES, width * aa * aa))
    return width * height * BYTES_PER_TEXEL + samples * BYTES_PER_SAMPLE


def check_settings(res, aa, max_distance, pad, memory: int | None = None) -> tuple[int, int]:
    """Validate the numeric settings before any kernel runs; returns (width, height)."""
    if isinstance(res, (tuple, list)):
        width, height = res
    else:
        width = height = res
    for name, v in (("res", width), ("res", height), ("aa", aa)):
        if isinstance(v, bool) or int(v) != v or v < 1:
            raise ValueError(f"{name}: must be a positive integer, got {v!r}")
    width, height = int(width), int(height)
    if max(width, height) > MAX_RESOLUTION or width * height * aa * aa >= 2**31:
        raise ValueError(f"res: {width}x{height} with aa {aa} exceeds the limit "
                         f"({MAX_RESOLUTION} texels a side, 2^31 samples)")
    if max_distance is not None and not (math.isfinite(max_distance) and max_distance > 0):
        raise ValueError(f"max_distance: must be a positive finite distance, got {max_distance!r}")
    if not pad >= 0:
        raise ValueError(f"padding: must be >= 0 texels, got {pad!r}")
    need = memory_estimate(width, height, aa)
    have = available_memory() if memory is None else memory
    if need > 0.8 * have:
        raise ValueError(f"res: a {width}x{height} bake with aa {aa} needs about "
                         f"{need / 2**30:.1f} GiB but only {have / 2**30:.1f} GiB is available; "
                         "lower 'res' or 'aa'")
    return width, height


@dataclass
class BakeResult:
    """Maps (NumPy, float32, row 0 = top = v 1) and everything ``bake.json`` records."""

    maps: dict
    status: np.ndarray
    covered: np.ndarray
    low: MeshData
    record: dict = field(default_factory=dict)


def prepare_inputs(high, low=None, target_faces: int = 5000, smoothing_iterations: int = 10,
                   unwrap_resolution: int = 1024) -> tuple[MeshData, MeshData, dict]:
    """Load (paths) or check (MeshData) both meshes; simplify / unwrap where needed."""
    timings = {}
    start = time.perf_counter()
    high = check_mesh(high, "high-poly") if isinstance(high, MeshData) else load_mesh(high, "high-poly")
    if low is not None:
        low = check_mesh(low, "low-poly") if isinstance(low, MeshData) else load_mesh(low, "low-poly")
        defects = defect_summary(face_defects(low.positions, low.faces))
        if defects:   # kept (its faces are the user's), but its normals and frame break there
            warnings.warn(f"low-poly is not a 2-manifold: {defects}; vertex normals and the "
                          "tangent frame are undefined there (remove those faces)", stacklevel=3)
    timings["load_s"] = time.perf_counter() - start
    if low is None:
        start = time.perf_counter()
        low = unwrap.make_low_poly(high, target_faces, smoothing_iterations)
        timings["simplify_s"] = time.perf_counter() - start
    if low.uvs is None:
        start = time.perf_counter()
        low = unwrap.unwrap(low, resolution=unwrap_resolution)
        timings["unwrap_s"] = time.perf_counter() - start
    lo, hi = low.positions.min(0), low.positions.max(0)
    hlo, hhi = high.positions.min(0), high.positions.max(0)
    gap = np.maximum(np.maximum(lo - hhi, hlo - hi), 0.0)
    if np.linalg.norm(gap) > 0.05 * high.diagonal or not (0.1 < low.diagonal / high.diagonal < 10):
        raise ValueError(
            f"low-poly does not sit near the high-poly: bounding boxes {lo.tolist()}..{hi.tolist()} "
            f"and {hlo.tolist()}..{hhi.tolist()} (gap {float(np.linalg.norm(gap)):.3g}, diagonals "
            f"{low.diagonal:.3g} vs {high.diagonal:.3g}); align the meshes (same units and frame)")
    return high, low, timings


class Baker:
    """Device state of one high/low pair: acceleration structures and the low-poly frame.

    Building it is the "acceleration structure" part of a bake's time; :meth:`run` can be
    called many times (other resolutions, aa, max_distance) on the same state.
    """

    def __init__(self, high: MeshData, low: MeshData, cage=None, cage_offset: float | None = None):
        normals = low.normals()
        tangents, signs = mikktspace(low.positions, low.faces, normals, low.uvs)
        cage_pos = None
        if cage is not None:
            cage = cage if isinstance(cage, MeshData) else load_mesh(cage, "cage")
            # corresponding face corners (an OBJ reader may number the vertices differently)
            cage_pos = np.zeros_like(low.positions)
            if len(cage.faces) == len(low.faces):
                cage_pos[low.faces] = cage.positions[cage.faces]
            if len(cage.faces) != len(low.faces) or not np.array_equal(
                    cage_pos[low.faces], cage.positions[cage.faces]):
                raise ValueError(f"cage: must have the low-poly's faces, corner for corner "
                                 f"({len(low.faces)} faces), got {len(cage.faces)} faces"
                                 + (" that do not share the low-poly's vertices"
                                    if len(cage.faces) == len(low.faces) else ""))
        elif cage_offset is not None:
            if not (math.isfinite(cage_offset) and cage_offset > 0):
                raise ValueError(f"cage_offset: must be a positive distance, got {cage_offset!r}")
            cage_pos = low.positions + cage_offset * normals
        self.high, self.low = high, low
        self.high_dev = HighPoly(high)
        self.layout = UVLayout(low)
        self.low_dev = LowPolyDevice(low, normals, tangents, signs, cage_pos)
        self.cage_mode = cage_pos is not None

    #: channels of the interleaved (H, W, C) result, name -> (first channel, count); the
    #: back depth (dual-depth) and the surface maps (:meth:`layout`) follow when baked
    CHANNELS = {"displacement": (0, 1), "normal_tangent": (1, 3), "normal_object": (4, 3),
                "direction_tangent": (7, 3), "normal_mitsuba": (10, 3), "status": (13, 1)}

    @staticmethod
    def layout(dual_depth: bool, surface_names=()) -> dict:
        """:data:`CHANNELS`, then ``back_depth`` if ``dual_depth``, then each surface map
        (:data:`surface_maps.CHANNELS`): name -> (first channel, count)."""
        layout, c = dict(Baker.CHANNELS), 14
        for name in (["back_depth"] if dual_depth else []) + list(surface_names):
            n = surface_maps.CHANNELS[name][0] if name in surface_maps.CHANNELS else 1
            layout[name], c = (c, n), c + n
        return layout

    def run(self, width: int, height: int, aa: int, max_distance: float, delta: float,
            dual_depth: bool, conservative: bool = True,
            continuation: bool = False, progress=None,
            surface: surface_maps.SurfaceMaps | None = None) -> tuple[np.ndarray, dict]:
        """Bake all texels (``surface``: the surface maps to evaluate too, or None).

        Returns:
            (H, W, C) float32 image with the channels of :meth:`layout` (status as a float
            code), and counts.
        """
        H, W = height, width
        fallback = surface_maps.fallbacks(surface.settings) if surface is not None else []
        C = 14 + dual_depth + len(fallback)
        # one device buffer for the whole map, viewed by NumPy without a copy at the end
        # (Dr.Jit's allocation cache reuses its pages on the next bake of the same size)
        flat = dr.empty(mi.Float, H * W * C)
        conservative_samples = 0
        tri_hit = dr.zeros(mi.UInt32, self.layout.face_count)
        rows = max(1, CHUNK_SAMPLES // (W * aa * aa))
        start = time.perf_counter()
        # opaque: the kernels do not change with the distances (nor with the block, below)
        max_distance, delta = dr.opaque(mi.Float, max_distance), dr.opaque(mi.Float, delta)
        keys = dr.opaque(mi.UInt64, aa * aa + 1)   # sample keys: texel x (aa^2 + 1) + sub
        for row0 in range(0, H, rows):  # blocks of rows (bounded memory), not per texel
            n_rows = min(rows, H - row0)
            s = rasterize_rows(self.layout, W, H, row0, n_rows, aa, conservative)
            conservative_samples += s.conservative
            if dr.width(s.prim) == 0:  # no UV chart in these rows
                _fill_empty(flat, row0 * W, n_rows * W, C, max_distance, dual_depth, fallback)
                continue
            dr.scatter(tri_hit, 1, s.prim)
            r = trace(self.high_dev, self.low_dev, s.prim, s.b1, s.b2, max_distance, delta,
                      dual_depth, continuation)
            surface_values = []
            if surface is not None:
                key = (mi.UInt64(s.texel) + dr.opaque(mi.UInt64, row0 * W)) * keys + mi.UInt64(s.sub)
                surface_values = surface.evaluate(r, key, delta)
            _texel_average(r, s.texel, n_rows * W, aa, max_distance, flat, row0 * W,
                           surface_values, fallback)
            if progress is not None:
                progress(f"  rows {row0 + n_rows}/{H} traced ({time.perf_counter() - start:.1f} s)")
        ores = min(max(width, height), OVERLAP_RESOLUTION)
        extra = {"uv_overlap_texels": overlap_texels(self.layout, ores),
                 "uv_overlap_resolution": ores, "conservative_samples": conservative_samples,
                 "triangles_without_texels": int(self.layout.face_count
                                                 - np.count_nonzero(np.asarray(tri_hit)))}
        return np.asarray(flat).reshape(H, W, C), extra


def _fill_empty(flat: mi.Float, first: int, n_tex: int, C: int, max_distance: float,
                dual_depth: bool, fallback: list) -> None:
    """What :func:`_texel_average` writes for texels without samples, for a whole block:
    displacement 0, +z for the normals and the direction, status ``empty``, back depth
    -max_distance, the surface maps' ``fallback`` values."""
    idx = dr.arange(mi.UInt32, n_tex * C)
    c = idx % C
    first = dr.opaque(mi.UInt32, first)
    value = mi.Float(0.0)
    for name in ("normal_tangent", "normal_object", "direction_tangent", "normal_mitsuba"):
        value = dr.select(c == Baker.CHANNELS[name][0] + 2, 1.0, value)     # the z component
    if dual_depth:
        value = dr.select(c == 14, -max_distance, value)
    for k, v in enumerate(fallback):
        if v:
            value = dr.select(c == 14 + dual_depth + k, v, value)
    dr.scatter(flat, value, idx + first * C)


def _texel_average(r, texel, n_tex: int, aa: int, max_distance: float, flat: mi.Float,
                   first: int, extra=(), extra_empty=()) -> None:
    """Per-texel mean of the samples that hit (Dr.Jit), interleaved into ``flat``.

    ``flat`` holds C channels per texel; this block's ``n_tex`` texels start at texel
    ``first``.  ``extra``: per-sample surface-map channels (mi.Float each) averaged like the
    others, ``extra_empty`` their values where no sample hit.

    Only ``ok`` and ``ambiguous`` samples carry values (a back-facing hit is never measured).
    Texels without one keep displacement 0, the low-poly normal and the tangent-space z axis
    until padding fills them from their nearest texel with a value; their status is the worst
    of their samples.  A texel with at least one hit takes the worst status of its hits
    (``ok`` or ``ambiguous``): with anti-aliasing, one missed sample does not discard the
    average of the others.
    """
    hit = (r.status == OK) | (r.status == AMBIGUOUS)
    values = [r.displacement, *r.normal_tangent, *r.normal_object, *r.direction_tangent,
              *r.normal_mitsuba]
    if r.back_depth is not None:
        values.append(r.back_depth)
    first_extra = len(values)
    values += list(extra)
    # status: the worst of the samples that hit, if any did (an anti-aliased texel keeps its
    # average when one sample misses), else the worst of all (miss / beyond / backface)
    st = dr.zeros(mi.UInt32, n_tex)
    # ReduceMode.Local: the default may expand per-thread copies, baking the block size
    # into the kernel (a new kernel per resolution)
    local = dr.ReduceMode.Local
    dr.scatter_reduce(dr.ReduceOp.Max, st, r.status, texel, mode=local)
    st_hit = dr.zeros(mi.UInt32, n_tex)
    dr.scatter_reduce(dr.ReduceOp.Max, st_hit, dr.select(hit, r.status, 0), texel, mode=local)
    fallback = [dr.zeros(mi.Float, n_tex) for _ in range(3)]
    for k in range(3):  # the low-poly normal (what misses carry) of any sample of the texel
        dr.scatter(fallback[k], r.normal_object[k], texel)
    if aa == 1:  # one sample per texel: plain scatter
        cnt = dr.zeros(mi.Float, n_tex)
        dr.scatter(cnt, dr.select(hit, 1.0, 0.0), texel)
        sums = [dr.zeros(mi.Float, n_tex) for _ in values]
        for buf, v in zip(sums, values):
            dr.scatter(buf, v, texel, hit)
    else:
        w = dr.select(hit, 1.0, 0.0)
        cnt = dr.zeros(mi.Float, n_tex)
        dr.scatter_add(cnt, w, texel, mode=local)
        sums = [dr.zeros(mi.Float, n_tex) for _ in values]
        for buf, v in zip(sums, values):
            dr.scatter_add(buf, v, texel, hit, mode=local)
    has = cnt > 0
    inv = dr.select(has, dr.rcp(cnt), 0.0)
    z = mi.Vector3f(0, 0, 1)
    nt = dr.normalize(dr.select(has, mi.Vector3f(*sums[1:4]), z))
    no = dr.select(has, mi.Vector3f(*sums[4:7]), mi.Vector3f(*fallback))
    no = dr.normalize(dr.select(dr.squared_norm(no) > 0, no, z))  # empty texels: +z
    dirn = dr.normalize(dr.select(has, mi.Vector3f(*sums[7:10]), z))
    nm = dr.normalize(dr.select(has, mi.Vector3f(*sums[10:13]), z))
    channels = [sums[0] * inv, *nt, *no, *dirn, *nm, mi.Float(dr.select(has, st_hit, st))]
    if r.back_depth is not None:
        channels.append(dr.select(has, sums[13] * inv, -max_distance))
    channels += [dr.select(has, sums[first_extra + k] * inv, v) for k, v in enumerate(extra_empty)]
    C = len(channels)
    base = (dr.arange(mi.UInt32, n_tex) + dr.opaque(mi.UInt32, first)) * C
    for c, v in enumerate(channels):
        dr.scatter(flat, v, base + c)
    dr.eval(flat)


def bake(high, low=None, res=1024, out_dir=None, aa: int = 1, max_distance: float | None = None,
         pad: float = 8, map_formats=formats.DEFAULT_FORMATS, diagnostics: bool = False,
         cage=None, cage_offset: float | None = None, target_faces: int = 5000,
         smoothing_iterations: int = 10, conservative: bool = True,
         min_hit_fraction: float = 0.5, delta: float | None = None,
         ao_samples: int = 64, ao_distance: float | None = None, ao_seed: int = 0,
         curvature_range: float | None = None, high_texture=None, high_colors=None,
         green: str = "+y", progress=None) -> BakeResult:
    """Bake maps of ``high`` over ``low`` (paths or :class:`MeshData`).

    Args:
        high: the original (detailed) mesh.
        low: the simplified mesh; ``None`` makes one (smoothing + fast-simplification to
            ``target_faces`` after ``smoothing_iterations`` Taubin passes); without UVs it is
            unwrapped with xatlas.
        res: map size in texels (int, or (width, height)).
        out_dir: folder for maps, sidecars, ``low.obj`` and ``bake.json`` (``None``: no files).
        aa: sub-samples per texel side (aa x aa regular grid; 1 = texel centre).
        max_distance: largest displacement magnitude searched [object units]; default derived from
            the pair (:func:`default_max_distance`), recorded in ``bake.json``.
        pad: edge padding radius [texels]; texels that missed the high-poly are filled
            from their nearest hit texel within the same radius.
        map_formats: names from :data:`formats.FORMATS`, or ``"all"`` (the albedo formats
            only with a colour source).
        diagnostics: diagnostics mode (§3.1): one more ray per sample looks for a second
            crossing beyond the hit (overhangs), and ``diagnostics.png`` is written.
        cage / cage_offset: cage mesh (the low-poly's topology) or an offset along the
            vertex normals [object units]; rays then run from the cage through the low-poly.
        min_hit_fraction: fewest covered texels that must find the high-poly; below it the
            low-poly is taken not to sit near the high-poly (ValueError, no empty map).
        delta: ray start offset [object units]; default 1e-5 of the diagonal.
        ao_samples / ao_distance / ao_seed: ambient occlusion (formats ``ao``, ``ao_float``):
            cosine-weighted rays per bake sample, their length [object units; default
            :data:`occlusion.DEFAULT_DISTANCE_REL` x the high-poly's diagonal] and the seed
            (the same seed gives the same map); evaluated at the high-poly hit
            (:mod:`occlusion`).
        curvature_range: H_ref [1 / object units] of the curvature and cavity maps (formats
            ``curvature``, ``cavity`` and their ``_float``); default the 99th percentile of
            ``|H|`` over the measured texels (:mod:`curvature`).
        high_texture / high_colors: the high-poly's colour for the albedo maps: an image
            (path or (H, W, 3) linear RGB) looked up with the high-poly's UVs, or (V, 3)
            linear RGB per high-poly vertex; giving one adds ``albedo`` to the formats if
            no albedo format is listed (:mod:`albedo`).
        green: ``"+y"`` (OpenGL: Blender, Mitsuba, Unity) or ``"-y"`` (DirectX: Unreal)
            for the tangent-space normal maps meant for other tools (:mod:`formats`).
        progress: callable taking one line of text per stage (the CLI prints them); None: quiet.
    """
    t0 = time.perf_counter()
    say = progress or (lambda line: None)
    inputs = {k: None if v is None else v.name if isinstance(v, MeshData) else os.path.abspath(v)
              for k, v in (("high", high), ("low", low), ("cage", cage))}
    every = map_formats == "all" or tuple(map_formats) == ("all",)
    map_formats = formats.check_formats(map_formats)
    colour_given = high_texture is not None or high_colors is not None
    if every and not colour_given:   # 'all' the inputs allow: no albedo without a colour
        map_formats = tuple(f for f in map_formats if formats.SURFACE_FORMATS.get(f) != "albedo")
    if colour_given and not any(formats.SURFACE_FORMATS.get(f) == "albedo" for f in map_formats):
        map_formats += ("albedo",)
    needed = {formats.SURFACE_FORMATS[f] for f in map_formats if f in formats.SURFACE_FORMATS}
    if "albedo" in needed and not colour_given:
        raise ValueError("formats: the albedo maps need the high-poly's colour (high_texture "
                         "or high_colors)")
    if green not in formats.GREEN:
        raise ValueError(f"green: must be one of {', '.join(formats.GREEN)}, got {green!r}")
    occlusion.check_settings(ao_samples, ao_distance, ao_seed)
    if curvature_range is not None and not (math.isfinite(curvature_range) and curvature_range > 0):
        raise ValueError(f"curvature_range: must be a positive curvature, got {curvature_range!r}")
    width, height = check_settings(res, aa, max_distance, pad)
    high, low, timings = prepare_inputs(high, low, target_faces, smoothing_iterations)
    say(f"inputs: high-poly {len(high.faces):,} faces, low-poly {len(low.faces):,} faces "
        f"({time.perf_counter() - t0:.1f} s)")
    if max_distance is None:
        max_distance, distance_info = default_max_distance(high, low)
        say(f"search distance {max_distance:.4g} ({distance_info['rule']}; Hausdorff "
            f"{distance_info['hausdorff_low_to_high']:.4g}, {distance_info['seconds']:.1f} s)")
    else:
        max_distance, distance_info = float(max_distance), {"rule": "given"}
    delta = DEFAULT_DELTA_REL * high.diagonal if delta is None else float(delta)
    uv_stats = uv_triangle_stats(low.uvs, low.faces)
    start = time.perf_counter()
    baker = Baker(high, low, cage, cage_offset)
    if ao_distance is None:
        ao_distance = occlusion.DEFAULT_DISTANCE_REL * high.diagonal
    settings = surface_maps.SurfaceSettings(
        "ao" in needed, int(ao_samples), float(ao_distance), int(ao_seed), "curvature" in needed,
        albedo.HighPolyColour(high, high_texture, high_colors) if "albedo" in needed else None)
    surface = surface_maps.SurfaceMaps(baker.high_dev, settings) if needed else None
    dr.eval()
    timings["accel_s"] = time.perf_counter() - start
    say(f"acceleration structures and MikkTSpace frame ({timings['accel_s']:.1f} s)")
    start = time.perf_counter()
    dual = "dual_d8_n16" in map_formats
    image, extra = baker.run(width, height, aa, max_distance, delta, dual, conservative,
                             diagnostics, say, surface)
    timings["raster_trace_s"] = time.perf_counter() - start
    status = image[..., Baker.CHANNELS["status"][0]].astype(np.uint8)
    covered = status != EMPTY
    start = time.perf_counter()
    # texels that found the high-poly feed the padding; misses inside charts are filled too
    found = (status == OK) | (status == AMBIGUOUS)
    image, filled = padding.pad(image, found, pad)
    filled |= covered
    # validity: 1 where the high-poly was measured; padded outward from the charts only, so
    # misses inside a chart (holes of the high-poly) stay 0 and restoration keeps them open
    valid, _ = padding.pad(found.astype(np.float32), covered, pad)
    timings["padding_s"] = time.perf_counter() - start
    maps = split_channels(image, Baker.layout(dual, settings.names()))
    surface_record = {}
    if settings.ao:
        surface_record["ao"] = {"samples": settings.ao_samples, "distance": settings.ao_distance,
                                "seed": settings.ao_seed, "point": "high-poly hit"}
    if settings.curvature:
        ref = curvature.curvature_range(maps["curvature"], found, curvature_range)
        maps["cavity"] = curvature.cavity(maps["curvature"], ref)
        surface_record["curvature_range"] = ref
    maps["valid"] = valid
    maps["filled"] = filled     # texels holding a value (covered or padded): quantisation range
    timings["bake_s"] = timings["accel_s"] + timings["raster_trace_s"] + timings["padding_s"]
    say(f"padding ({timings['padding_s']:.1f} s)")
    count = diag.counts(status)
    n_cov = int(covered.sum())
    hits = count["ok"] + count["ambiguous"]
    if uv_stats["uv_degenerate_triangles"] or extra["uv_overlap_texels"]:
        warnings.warn(f"low-poly UVs: {uv_stats['uv_degenerate_triangles']} degenerate triangles, "
                      f"{extra['uv_overlap_texels']} texels covered by overlapping triangles "
                      "(texture mapping not unambiguous, §3.1)", stacklevel=2)
    if n_cov == 0 or hits < min_hit_fraction * n_cov:
        raise ValueError(
            f"low-poly does not sit near the high-poly: only {hits} of {n_cov} covered texels "
            f"reached it within max_distance={max_distance:.4g} (misses {count['miss']}, beyond "
            f"{count['beyond']}); align the meshes or raise max_distance")
    from mi_displace import __version__

    record = {
        "inputs": inputs,
        "tool": {"mi_displace": __version__, "mitsuba": mi.__version__, "drjit": dr.__version__},
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "high": {"name": high.name, "vertices": len(high.positions), "faces": len(high.faces),
                 "diagonal": high.diagonal},
        "low": {"name": low.name, "vertices": len(low.positions), "faces": len(low.faces),
                "notes": low.notes, **uv_stats, **edge_counts(low.faces, weld_ids(low.positions))},
        "settings": {"width": width, "height": height, "aa": aa, "max_distance": max_distance,
                     "max_distance_rule": distance_info,
                     "delta": delta, "padding": pad, "formats": list(map_formats),
                     "cage": None if cage is None else str(cage) if not isinstance(cage, MeshData) else cage.name,
                     "cage_offset": cage_offset, "conservative": conservative,
                     "diagnostics": diagnostics, "green": green, **surface_record,
                     "variant": mi.variant()},
        "counts": {**count, "covered": n_cov, "padded": int(filled.sum() - n_cov), **extra},
        "displacement_range": [float(maps["displacement"][covered].min()),   # n_cov > 0 here
                               float(maps["displacement"][covered].max())],
        "timings": timings,
    }
    result = BakeResult(maps, status, covered, low, record)
    if out_dir is not None:
        write_outputs(result, Path(out_dir), map_formats, diagnostics)
        say(f"wrote {len(record['files'])} files ({timings['write_s']:.1f} s)")
    timings["total_s"] = time.perf_counter() - t0
    if out_dir is not None:
        (Path(out_dir) / "bake.json").write_text(json.dumps(record, indent=2))
    return result


def split_channels(image: np.ndarray, layout: dict) -> dict:
    """Views of the interleaved bake image per map name (``layout``: :meth:`Baker.layout`)."""
    return {name: image[..., c] if n == 1 else image[..., c:c + n]
            for name, (c, n) in layout.items() if name != "status"}


def write_outputs(result: BakeResult, out_dir: Path, map_formats, diagnostics_image: bool) -> None:
    """Write ``low.obj``, every map with its sidecar, the Mitsuba scene fragments
    (:mod:`fragments`) and the diagnostics image."""
    start = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    low = result.low
    save_obj(out_dir / "low.obj", low.positions, low.faces, low.uvs, low.normals())
    meta = {"low": "low.obj", "low_faces": int(len(low.faces)),
            "max_distance": result.record["settings"]["max_distance"],
            "aa": result.record["settings"]["aa"],
            "cage": result.record["settings"]["cage"] or result.record["settings"]["cage_offset"]}
    settings = result.record["settings"]
    for key in ("ao", "curvature_range"):
        if key in settings:
            meta[key] = settings[key]
    formats.write_png_raw(out_dir / "valid.png", (result.maps["valid"] > 0.5).astype(np.uint8) * 255)
    meta["valid"] = "valid.png"
    files = []
    for f in map_formats:
        path = formats.write_map(out_dir, f, result.maps, meta, settings["green"])
        files += [path.name, *formats.read_metadata(path).get("companions", {}).values()]
    files.append("valid.png")
    files += write_fragments(out_dir, map_formats, low, settings["green"])
    if diagnostics_image:
        formats.write_png_raw(out_dir / "diagnostics.png", diag.image(result.status))
        files.append("diagnostics.png")
    result.record["files"] = ["low.obj"] + files
    result.record["timings"]["write_s"] = time.perf_counter() - start
