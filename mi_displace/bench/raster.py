"""`mi-displace bench raster`: z-buffer visibility against ray tracing and a real GL pipeline.

All in one process, 512 x 512, one directional light + ambient, warm medians:

* ``faces``: the displaced sphere (ripples) tessellated to ~4M triangles;
* ``zbuffer_s``: ``raster`` with ``visibility="zbuffer"``, ``shadows="none"`` (the work of a
  GL draw with per-fragment Lambert shading), the mesh outside the scene (no acceleration
  structure anywhere); ``zbuffer_shadow_map_s``: the same with a 2048^2 shadow map;
* ``raytrace_s``: ``visibility="raytrace"``, ``shadows="none"``, *including* Mitsuba's
  acceleration build over the mesh (what every geometry change costs a ray tracer);
  ``raytrace_shadow_rays_s``: with shadow rays; ``accel_build_s``: the build alone;
* ``llvmpipe_s``: the same mesh drawn by Mesa's llvmpipe (OpenGL 4.5 on the CPU, headless
  EGL, through ``moderngl``) with per-vertex Lambert shading and depth test, frame incl.
  read-back; ``llvmpipe_upload_s``: with the vertex upload; ``null`` with
  ``llvmpipe_reason`` ("peer unavailable: ...") when ``moderngl`` or Mesa's EGL is missing
  (:mod:`mi_displace.bench.peers.llvmpipe`; ``scripts/setup_peers.sh`` installs them);
* ``ddm_frame_s``: an animated HDDM frame of the paper's camel-scale scene (Spot tiled with
  70 x 70 chains, ``maps`` at 256², ~4.7M vertices): ``time`` edit (mapping) + z-buffer
  draw + shading at 512², no build; ``ddm_frame_shadow_map_s`` with a shadow map;
  ``ddm_frame_raytrace_s``: the same frame with the shape in the scene (the update
  rebuilds Mitsuba's acceleration structure) and ray-traced visibility.

``--quick`` runs the same with :data:`QUICK` sizes (128^2, a 10k-triangle sphere, Spot with
10 x 10 chains and 64^2 maps).

``python -m mi_displace.bench.raster --figures DIR`` also measures the z-buffer / ray
tracing consistency on the repository's scenes and the shadow-map trade (resolution,
bias, normal offset against shadow rays: FLIP, shadow-mask error, time), writing JSON and
a PNG plot.  ``--area-sweep FILE`` measures the ``area_samples`` trade on Mitsuba's
Cornell box (area light on a rectangle) against a path-traced reference (max_depth 2).
"""
from __future__ import annotations

import argparse
import json as _json
from pathlib import Path
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bench._timing import median_time
from mi_displace.bench.peers import measure
from mi_displace.core.resources import data_path, scene_path
from mi_displace.render import raster

SPOT = str(data_path("spot", "spot_triangulated.obj"))
RES = 512


class Sizes(NamedTuple):
    """What a run draws: the sphere at ``resolution`` ``nu`` (about nu^2 triangles), films
    of ``res`` x ``res`` pixels, the camel scene's ``camel_tiles`` x ``camel_tiles`` chains
    with ``camel_maps`` x ``camel_maps`` HDDM maps."""
    nu: int
    res: int
    camel_tiles: int
    camel_maps: int


FULL = Sizes(2000, RES, 70, 256)
QUICK = Sizes(100, 128, 10, 64)
SUN_DIRECTION = (-1.0, 1.0, -1.0)
ALBEDO = (0.7, 0.6, 0.5)


def sphere(nu: int) -> dict:
    return {"type": "displaced", "base": "sphere", "resolution": nu, "scale": 0.05,
            "height": {"type": "ripples", "frequency": 16.0},
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(ALBEDO)}}}


def camera(res: int = RES, origin=(0, -5, 1.5), target=(0, 0, 0), fov: float = 30) -> dict:
    return {"type": "perspective", "fov": fov, "near_clip": 0.1, "far_clip": 100.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target),
                                                       up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}


def scene(shapes: dict, options: raster.Options, sensor: dict | None = None,
          lights: dict | None = None) -> mi.Scene:
    d = {"type": "scene", "sensor": sensor or camera(),
         "integrator": {"type": "raster", "visibility": options.visibility,
                        "shadows": options.shadows,
                        "shadow_resolution": options.shadow_resolution},
         "ambient": {"type": "constant", "radiance": {"type": "rgb", "value": 0.1}}}
    d.update(lights or {"sun": {"type": "directional", "direction": list(SUN_DIRECTION),
                                "irradiance": {"type": "rgb", "value": 1.0}}})
    d.update(shapes)
    return mi.load_dict(d)


def _image(sc: mi.Scene) -> np.ndarray:
    img = np.asarray(mi.render(sc))
    if not np.all(np.isfinite(img)) or img.mean() <= 0:
        raise RuntimeError("bench raster: image is not finite or black")
    return img


def _unbuilt(shape, options: raster.Options, **kw) -> mi.Scene:
    """A scene without shapes whose raster integrator draws ``shape`` (no accel build)."""
    sc = scene({}, options, **kw)
    sc.integrator().shapes = [shape]
    return sc


# --- the GL peer ----------------------------------------------------------------------

def llvmpipe_frame(shape, sensor: mi.Sensor, res: int = RES) -> dict:
    """Draw ``shape`` through llvmpipe as ``sensor`` (fov 30) sees it
    (:func:`mi_displace.bench.peers.llvmpipe.mesh_frame`)."""
    from mi_displace.bench.peers import llvmpipe

    to_camera = np.linalg.inv(np.array(sensor.world_transform().matrix, np.float64).reshape(4, 4))
    return llvmpipe.mesh_frame(
        np.asarray(shape.vertex_positions_buffer(), np.float32).reshape(-1, 3),
        np.asarray(shape.vertex_normals_buffer(), np.float32).reshape(-1, 3),
        np.asarray(shape.faces_buffer(), np.uint32).reshape(-1, 3), to_camera, 30.0, res,
        -np.array(SUN_DIRECTION) / np.linalg.norm(SUN_DIRECTION), ALBEDO)


# --- the measurements -------------------------------------------------------------------

def ddm_camel(sizes: Sizes = FULL, time_value: float = 0.0) -> dict:
    """The paper's camel-scale scene (Fig. 9, Table 1; :data:`FULL`: Spot tiled with 70 x 70
    chains, HDDM maps at 256²), animated by a texture-space velocity."""
    return {"type": "ddm", "base": "mesh", "filename": SPOT, "tile": "chain",
            "tiles_u": sizes.camel_tiles, "tiles_v": sizes.camel_tiles, "height": 0.03,
            "mode": "maps", "map_resolution": sizes.camel_maps,
            "velocity_u": 0.05, "time": time_value,
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(ALBEDO)}}}


def ddm_frames(out: dict, sizes: Sizes = FULL) -> None:
    """``ddm_frame_*`` fields: an animated HDDM frame, z-buffer vs ray tracing."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        shape = mi.load_dict(ddm_camel(sizes))
    sensor = camera(sizes.res, origin=(0, -2.2, 0.6), target=(0, 0, 0.0), fov=40)
    out["ddm_vertices"] = shape.vertex_count()
    out["ddm_faces"] = shape.face_count()
    params = mi.traverse(shape)
    state = {"t": 0.0}

    def frame(sc, edit):
        def run():
            state["t"] += 1 / 24
            edit(state["t"])
            _image(sc)
        return run

    def edit_shape(t):
        params["time"] = t
        params.update()

    zb = _unbuilt(shape, raster.Options(visibility="zbuffer", shadows="none"), sensor=sensor)
    out["ddm_frame_s"] = median_time(frame(zb, edit_shape))
    zbm = _unbuilt(shape, raster.Options(visibility="zbuffer", shadows="map"), sensor=sensor)
    out["ddm_frame_shadow_map_s"] = median_time(frame(zbm, edit_shape))
    del zb, zbm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rt = scene({"camel": ddm_camel(sizes)}, raster.Options(shadows="none"), sensor=sensor)
    scene_params = mi.traverse(rt)

    def edit_scene(t):
        scene_params["camel.time"] = t
        scene_params.update()   # the scene rebuilds its acceleration structure

    out["ddm_frame_raytrace_s"] = median_time(frame(rt, edit_scene), 3)


def run(sizes: Sizes = FULL, with_ddm: bool = True, with_gl: bool = True) -> dict:
    """Measure everything; returns the JSON record (seconds, counts).

    Args:
        sizes: :data:`FULL` (the documented numbers) or :data:`QUICK`.
        with_ddm: measure the ``ddm_frame_*`` fields.
        with_gl: measure the llvmpipe peer (else ``llvmpipe_s`` is null).
    """
    record = {"variant": mi.variant(), "resolution": sizes.res}
    shape = mi.load_dict(sphere(sizes.nu))
    dr.sync_thread()
    record["faces"] = shape.face_count()
    sensor = camera(sizes.res)
    zb = _unbuilt(shape, raster.Options(visibility="zbuffer", shadows="none"), sensor=sensor)
    record["zbuffer_s"] = median_time(lambda: _image(zb))
    zb_image = _image(zb)
    zbm = _unbuilt(shape, raster.Options(visibility="zbuffer", shadows="map"), sensor=sensor)
    record["zbuffer_shadow_map_s"] = median_time(lambda: _image(zbm))
    del zbm

    def build():
        return scene({"shape": shape}, raster.Options(shadows="none"), sensor=sensor)

    record["accel_build_s"] = median_time(lambda: (build(), dr.sync_thread()), 3)
    record["raytrace_s"] = median_time(lambda: _image(build()), 3)
    rt_image = _image(build())
    rtr = scene({"shape": shape}, raster.Options(shadows="ray"), sensor=sensor)
    record["raytrace_shadow_rays_s"] = record["accel_build_s"] + median_time(lambda: _image(rtr), 3)
    del rtr
    record["zbuffer_vs_raytrace_pixels_differing"] = float(
        np.mean(np.abs(zb_image - rt_image).max(axis=2) > 1e-3))
    record["llvmpipe_s"] = None
    gl, reason = (measure(llvmpipe_frame, shape, zb.sensors()[0], sizes.res) if with_gl
                  else (None, "not requested (run(with_gl=False))"))
    if gl is not None:
        gl_image = gl.pop("image")
        record.update(gl)
        # the same pixels covered (both backgrounds are 0.1)
        covered = np.abs(zb_image - 0.1).max(axis=2) > 1e-3
        gl_covered = np.abs(gl_image - 0.1).max(axis=2) > 1e-3
        record["llvmpipe_coverage_agreement"] = float(np.mean(covered == gl_covered))
        record["zbuffer_vs_llvmpipe"] = record["zbuffer_s"] / record["llvmpipe_s"]
    else:
        record["llvmpipe_reason"] = reason
    del zb, shape
    if with_ddm:
        ddm_frames(record, sizes)
    record["targets"] = {"zbuffer_s": "< llvmpipe_s", "ddm_frame_s": 0.5}
    return record


# --- figures: spawn offsets, consistency and the shadow-map trade ------------------------

def thorn_scene(k: float = 1.0, offset=(0.0, 0.0, 0.0), res: int = 64, theta: float = 80.0,
                tiles=(16, 8)) -> mi.Scene:
    """DDM thorns (exact) on a unit sphere, camera at ``theta`` degrees from the pole, a low
    point key light and a directional fill, all scaled by ``k`` about the origin and then
    moved by ``offset`` (the point light's intensity scaled by k^2: the same image)."""
    t, o = np.radians(theta), np.array(offset, float)
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "raster"},
        "sensor": {"type": "perspective", "fov": 20, "near_clip": 0.01 * k,
                   "to_world": mi.ScalarTransform4f().look_at(
                       origin=(o + k * np.array([0, -5 * np.sin(t), 5 * np.cos(t)])).tolist(),
                       target=o.tolist(), up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}},
        "s": {"type": "ddm", "base": "sphere", "tile": "thorn", "tiles_u": tiles[0],
              "tiles_v": tiles[1], "height": 0.3, "mode": "exact",
              "to_world": mi.ScalarTransform4f().translate(o.tolist()).scale(k),
              "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.3]}}},
        "point": {"type": "point", "position": (o + k * np.array([4.5, -1.5, 0.6])).tolist(),
                  "intensity": {"type": "rgb", "value": 45 * k * k}},
        "sun": {"type": "directional", "direction": [0.3, 1, -0.5],
                "irradiance": {"type": "rgb", "value": 0.25}}})


def blocked_fraction(sc: mi.Scene, spawn=None) -> float:
    """Fraction of camera hits whose shadow ray toward the point light is blocked;
    ``spawn(si, target, active)`` makes the shadow ray (default ``raster.spawn_ray_to``;
    Mitsuba's own: ``lambda si, p, a: si.spawn_ray_to(p)``)."""
    spawn = spawn or raster.spawn_ray_to
    ray, _, _, _ = raster.pixel_rays(sc.sensors()[0], 1)
    si = sc.ray_intersect(ray)
    light = [e for e in sc.emitters() if e.class_name() == "PointLight"][0]
    ds, _ = light.sample_direction(si, mi.Point2f(0.5), si.is_valid())
    blocked = sc.ray_test(spawn(si, ds.p, si.is_valid()), si.is_valid())
    valid = np.array(si.is_valid())
    return float(np.array(blocked)[valid].mean())


def perturbed(sc: mi.Scene, relative: float = 1e-7, keep_normals: bool = True,
              seed: int = 0) -> None:
    """Move the vertices of shape ``s`` by ``relative`` x a normal deviate (in place)."""
    params = mi.traverse(sc)
    positions = np.array(params["s.vertex_positions"])
    normals = np.array(params["s.vertex_normals"])
    noise = np.random.default_rng(seed).standard_normal(positions.shape)
    params["s.vertex_positions"] = mi.Float((positions * (1 + relative * noise)).astype(np.float32))
    if keep_normals:
        params["s.vertex_normals"] = mi.Float(normals)
    params.update()


def spawn_offsets() -> dict:
    """Issue 12 item 8: shadow decisions under Mitsuba's spawn offset and ours when the
    thorn scene is scaled or moved, and the image change of a 1e-7 vertex perturbation
    with and without the normals kept."""
    from mi_displace.evaluate.metrics import flip as flip_error

    mitsuba = lambda si, p, a: si.spawn_ray_to(p)  # noqa: E731
    rows = []
    for k, offset in ((1.0, (0, 0, 0)), (1e-3, (0, 0, 0)), (1e3, (0, 0, 0)), (1.0, (1000, 0, 0))):
        sc = thorn_scene(k, offset, res=128, tiles=(32, 16))
        rows.append({"scale": k, "offset": list(offset),
                     "blocked_mitsuba_spawn": blocked_fraction(sc, mitsuba),
                     "blocked_spawn_offset": blocked_fraction(sc)})
    ulps = {}
    for offset in ((0, 0, 0), (1000, 0, 0)):
        sc = thorn_scene(1.0, offset, res=128, tiles=(32, 16))
        for half_ulps in (2, 8, 32, 128, 512):
            default, raster.SPAWN_HALF_ULPS = raster.SPAWN_HALF_ULPS, half_ulps
            ulps[f"{offset[0]}:{half_ulps}"] = blocked_fraction(sc)
            raster.SPAWN_HALF_ULPS = default
    perturbation = []
    for theta in (70.0, 80.0, 85.0, 88.0, 89.5):
        for keep in (True, False):
            sc = thorn_scene(1.0, res=256 if keep else 128, theta=theta, tiles=(32, 16))
            before = _image(sc)
            perturbed(sc, keep_normals=keep)
            after = _image(sc)
            perturbation.append({"theta": theta, "normals_kept": keep,
                                 "res": 256 if keep else 128,
                                 "flip": float(flip_error(before, after)[0]),
                                 "pixels_changed_1e-3": float(
                                     np.mean(np.abs(after - before).max(axis=2) > 1e-3))})
    return {"scaled": rows, "blocked_by_half_ulps": ulps, "perturbation": perturbation}



#: Repository scenes drawn from triangle meshes only (bump_vs_displaced has an analytic
#: sphere, which a rasteriser cannot draw).
CONSISTENCY_SCENES = ("displaced_sphere", "ddm_thorns_sphere", "ddm_chains_spot",
                      "ddm_teapot_morph", "vdm_torus", "vdm_spot", "bake_bunny")


def _load(name: str, res: int) -> mi.Scene:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mi.load_file(str(scene_path(f"{name}.xml")), mode="approximation",
                            integrator="raster", res=res)


def _render(sc: mi.Scene, options: raster.Options) -> tuple[np.ndarray, float]:
    integrator = sc.integrator()
    integrator.options = options
    seconds = median_time(lambda: _image(sc), 3)
    return _image(sc), seconds


def _edge_distance(view, clip, geom, tri, X, Y, active) -> mi.Float:
    """Distance (in grid samples) from sample (X, Y) to the nearest edge line of ``tri``."""
    from mi_displace.render import zbuffer

    _, c = zbuffer._triangles(geom, clip, tri, active)
    h = [view.homogeneous(v) for v in c]
    q = mi.Vector3f(mi.Float(X) + 0.5, mi.Float(Y) + 0.5, 1.0)
    distance = mi.Float(dr.inf)
    for i in range(3):
        n = dr.cross(h[(i + 1) % 3], h[(i + 2) % 3])   # edge line: n . (x, y, 1) = 0
        distance = dr.minimum(distance, dr.abs(dr.dot(n, q)) / dr.norm(mi.Vector2f(n.x, n.y)))
    return dr.select(active, distance, dr.inf)


def consistency(res: int = 256) -> list[dict]:
    """Z-buffer against ray-traced visibility on every mesh scene: per sample, whether the
    same triangle is seen, and for those that differ how close the pixel centre is to the
    z-buffer triangle's edge (smallest barycentric); per pixel, the image difference."""
    from mi_displace.evaluate.metrics import flip as flip_error
    from mi_displace.render import zbuffer

    rows = []
    for name in CONSISTENCY_SCENES:
        sc = _load(name, res)
        sensor, aa = sc.sensors()[0], sc.integrator().aa
        rt_img, rt_s = _render(sc, raster.Options())
        zb_img, zb_s = _render(sc, raster.Options(visibility="zbuffer"))
        ray, _, _, _ = raster.pixel_rays(sensor, aa)
        layers = sc.integrator().max_layers or raster.layer_limit(sc.shapes(), sc)
        si_rt, _, _ = raster.first_opaque_hit(sc, ray, layers, mi.Bool(True))
        geom = zbuffer.gather_geometry(sc.shapes())
        si_zb, _ = raster.zbuffer_hit(sensor, geom, ray, aa, layers)
        same = (si_rt.is_valid() == si_zb.is_valid()) & (
            ~si_rt.is_valid() | ((si_rt.prim_index == si_zb.prim_index)
                                 & (si_rt.shape == si_zb.shape)))
        view = zbuffer.view_from_sensor(sensor, aa)
        keys, clip = zbuffer.rasterise(view, geom, True, aa=aa)
        tri = mi.UInt32(keys & 0xFFFFFFFF)
        X, Y = zbuffer.sample_xy(view, dr.arange(mi.UInt32, dr.width(keys)), aa)
        edge = np.array(_edge_distance(view, clip, geom, tri, X, Y, keys != zbuffer.EMPTY))
        differ = ~np.array(same)
        t_rt, t_zb = np.array(si_rt.t), np.array(si_zb.t)
        with np.errstate(invalid="ignore"):  # inf - inf where both miss
            tie = np.abs(t_rt - t_zb) <= 1e-4 * np.minimum(t_rt, t_zb)  # hits at one depth
        pixels = np.abs(zb_img - rt_img).max(axis=2) > 1e-3
        rows.append({
            "scene": name, "res": res, "aa": aa, "samples": int(differ.size),
            "samples_other_triangle": float(differ.mean()),
            **{f"of_which_within_{d:g}_samples_of_an_edge":
               float(np.mean(edge[differ] < d)) if differ.any() else None
               for d in (1e-4, 1e-3, 1e-2)},
            "of_which_farther_than_1e-2_samples_but_same_depth_1e-4":
                float(np.mean(tie[differ] & (edge[differ] >= 1e-2))) if differ.any() else None,
            "pixels_differing_1e-3": float(pixels.mean()),
            "max_abs_diff": float(np.abs(zb_img - rt_img).max()),
            "flip": float(flip_error(rt_img, zb_img)[0]),
            "raytrace_render_s": rt_s, "zbuffer_render_s": zb_s,
            "triangles": int(dr.width(geom.faces))})
    return rows


def shadow_sweep(name: str = "ddm_thorns_sphere", res: int = 256) -> list[dict]:
    """Shadow maps against shadow rays on one scene: FLIP of the image, disagreement of
    each light's shadow mask (ray-traced visible points), warm render time, for map
    resolution, depth bias and normal offset."""
    from mi_displace.evaluate.metrics import flip as flip_error

    sc = _load(name, res)
    sensor = sc.sensors()[0]
    ray_img, ray_s = _render(sc, raster.Options(visibility="zbuffer", shadows="ray"))
    hit, ray_masks = raster.light_masks(sc, sensor, raster.Options(shadows="ray"))
    hit = np.array(hit)
    default = raster.Options()
    settings = [(r, default.shadow_bias, default.shadow_normal_offset)
                for r in (256, 512, 1024, 2048, 4096)]
    settings += [(2048, b, default.shadow_normal_offset) for b in (0.0, 0.25, 1.0, 2.0)]
    settings += [(2048, default.shadow_bias, o) for o in (0.0, 0.25, 1.0, 2.0, 4.0)]
    rows = [{"method": "ray", "zbuffer_render_s": ray_s, "flip": 0.0}]
    for resolution, bias, offset in settings:
        options = raster.Options(visibility="zbuffer", shadows="map",
                                 shadow_resolution=resolution, shadow_bias=bias,
                                 shadow_normal_offset=offset)
        img, seconds = _render(sc, options)
        _, masks = raster.light_masks(sc, sensor, options)
        errors = [float(np.mean(np.array(m)[hit] != np.array(r)[hit]))
                  for m, r in zip(masks, ray_masks)]
        rows.append({"method": "map", "shadow_resolution": resolution, "shadow_bias": bias,
                     "shadow_normal_offset": offset, "zbuffer_render_s": seconds,
                     "flip": float(flip_error(ray_img, img)[0]), "mask_error_per_light": errors,
                     "mask_error_mean": float(np.mean(errors))})
    return rows


def plot_shadow_sweep(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    ray = rows[0]
    maps = rows[1:]
    default = raster.Options()
    groups = {
        "resolution": [r for r in maps if r["shadow_bias"] == default.shadow_bias
                       and r["shadow_normal_offset"] == default.shadow_normal_offset],
        "bias (2048)": [r for r in maps if r["shadow_resolution"] == 2048
                        and r["shadow_normal_offset"] == default.shadow_normal_offset],
        "normal offset (2048)": [r for r in maps if r["shadow_resolution"] == 2048
                                 and r["shadow_bias"] == default.shadow_bias],
    }
    labels = {"resolution": "shadow_resolution", "bias (2048)": "shadow_bias",
              "normal offset (2048)": "shadow_normal_offset"}
    for (title, group), marker in zip(groups.items(), "os^"):
        group = sorted(group, key=lambda r: r[labels[title]])
        for ax, key in zip(axes, ("flip", "mask_error_mean")):
            ax.plot([r["zbuffer_render_s"] for r in group], [r[key] for r in group],
                    marker=marker, label=title)
            for r in group:
                ax.annotate(f"{r[labels[title]]:g}", (r["zbuffer_render_s"], r[key]),
                            fontsize=7)
    for ax, key in zip(axes, ("FLIP vs shadow rays", "shadow-mask disagreement")):
        ax.axvline(ray["zbuffer_render_s"], color="k", ls="--", lw=0.8,
                   label="shadow rays (no build)")
        ax.set_xlabel("render time, z-buffer + shadows (s)")
        ax.set_ylabel(key)
        ax.set_yscale("log")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


#: The HDDM and VDM comparison scenes whose approximation time the guides quote.
COMPARE_SCENES = ("ddm_thorns_sphere", "ddm_chains_spot", "ddm_teapot_morph", "vdm_torus",
                  "vdm_spot")


def approximation_times(res: int = 256) -> list[dict]:
    """The approximation side of each comparison scene, timed as `compare` does (warm XML
    load, plugins' builds included, + render) with ray tracing, and with the z-buffer
    where the acceleration build (measured alone on the loaded shapes) is not needed."""
    rows = []
    for name in COMPARE_SCENES:
        load_s = median_time(lambda: (_load(name, res), dr.sync_thread()), 3)
        sc = _load(name, res)
        shapes = list(sc.shapes())
        build_s = median_time(lambda: (mi.load_dict(
            {"type": "scene", **{f"s{i}": s for i, s in enumerate(shapes)}}), dr.sync_thread()), 3)
        _, ray_s = _render(sc, raster.Options())
        _, zb_s = _render(sc, raster.Options(visibility="zbuffer"))
        _, zbm_s = _render(sc, raster.Options(visibility="zbuffer", shadows="map"))
        rows.append({"scene": name, "res": res, "load_s": load_s, "accel_build_s": build_s,
                     "raytrace_render_s": ray_s, "zbuffer_render_s": zb_s,
                     "zbuffer_map_render_s": zbm_s,
                     "approximation_raytrace_s": load_s + ray_s,
                     "approximation_zbuffer_map_no_build_s": max(load_s - build_s, 0.0) + zbm_s})
    return rows


def cornell_box(integrator: dict, res: int) -> mi.Scene:
    """Mitsuba's Cornell box (``mi.cornell_box()``), ``res``², box pixel filter."""
    d = mi.cornell_box()
    d["integrator"] = integrator
    d["sensor"]["film"].update(width=res, height=res, rfilter={"type": "box"})
    return mi.load_dict(d)


def area_sweep(res: int = 128, ref_spp: int = 4096, aa: int = 4,
               counts=(1, 4, 16, 64, 256), map_points: int = 16,
               map_resolutions=(64, 256, 1024)) -> dict:
    """``area_samples`` against path (max_depth 2) on the Cornell box: FLIP, mean absolute
    error and warm render time per count, with shadow rays; ``map_points`` points with a
    cube shadow map each at ``map_resolutions`` (FLIP also against the shadow-ray image
    of as many points); the reference's noise floor (FLIP between its two halves) and
    path's own FLIP and time at a few spp."""
    from mi_displace.evaluate.metrics import flip as flip_error

    path = cornell_box({"type": "path", "max_depth": 2}, res)
    halves = [np.array(mi.render(path, spp=ref_spp // 2, seed=s))[..., :3] for s in (0, 1)]
    reference = 0.5 * (halves[0] + halves[1])
    record = {"scene": "mi.cornell_box()", "res": res, "aa": aa, "reference_spp": ref_spp,
              "noise_floor_flip": float(flip_error(halves[0], halves[1])[0]), "raster": [],
              "path": []}
    rays = {}
    settings = [{"area_samples": n} for n in sorted(set(counts) | {map_points})]
    settings += [{"area_samples": map_points, "shadows": "map", "area_shadow_resolution": r}
                 for r in map_resolutions]
    for setting in settings:
        sc = cornell_box(dict({"type": "raster", "aa": aa}, **setting), res)
        img = _image(sc)
        row = dict(setting, flip=float(flip_error(reference, img)[0]),
                   mae=float(np.abs(img - reference).mean()),
                   render_s=median_time(lambda: _image(sc), 3))
        if "shadows" in setting:
            row["flip_vs_shadow_rays"] = float(flip_error(rays[map_points], img)[0])
        else:
            rays[setting["area_samples"]] = img
        record["raster"].append(row)
    for spp in (4, 16, 64):
        seed = 2   # the reference used seeds 0 and 1
        img = np.array(mi.render(path, spp=spp, seed=seed))[..., :3]
        record["path"].append({
            "spp": spp, "flip": float(flip_error(reference, img)[0]),
            "mae": float(np.abs(img - reference).mean()),
            "render_s": median_time(lambda: np.array(mi.render(path, spp=spp, seed=seed)), 3)})
    return record


def figures(out_dir: Path) -> dict:
    """Write ``raster_spawn.json``, ``raster_consistency.json``, ``raster_shadow_sweep.json``,
    ``raster_shadow_sweep.png`` and ``raster_compare_times.json`` to ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    record = {"spawn": spawn_offsets()}
    (out_dir / "raster_spawn.json").write_text(_json.dumps(record["spawn"], indent=2))
    record["consistency"] = consistency()
    (out_dir / "raster_consistency.json").write_text(_json.dumps(record["consistency"], indent=2))
    record["shadow_sweep"] = {"ddm_thorns_sphere": shadow_sweep("ddm_thorns_sphere", 256),
                              "displaced_sphere": shadow_sweep("displaced_sphere", 128)}
    (out_dir / "raster_shadow_sweep.json").write_text(_json.dumps(record["shadow_sweep"], indent=2))
    plot_shadow_sweep(record["shadow_sweep"]["ddm_thorns_sphere"],
                      out_dir / "raster_shadow_sweep.png")
    record["approximation_times"] = approximation_times()
    (out_dir / "raster_compare_times.json").write_text(
        _json.dumps(record["approximation_times"], indent=2))
    print(_json.dumps(record, indent=2))
    return record


def main(json: bool = False, quick: bool = False) -> dict:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``); print JSON (``json``) or one
    ``key = value`` line per field."""
    record = run(QUICK if quick else FULL)
    print(_json.dumps(record, indent=2) if json else
          "\n".join(f"{key} = {value}" for key, value in record.items()))
    return record


if __name__ == "__main__":
    import mi_displace

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figures", metavar="DIR", help="consistency + shadow-map trade")
    parser.add_argument("--area-sweep", metavar="FILE", help="area_samples trade (JSON)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    mi_displace.init()
    if args.area_sweep:
        sweep = area_sweep()
        Path(args.area_sweep).write_text(_json.dumps(sweep, indent=2))
        print(_json.dumps(sweep, indent=2))
    elif args.figures:
        figures(Path(args.figures))
    else:
        main(json=args.json)
