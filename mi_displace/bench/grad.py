"""`mi-displace bench grad`: differentiable ``displaced`` (issue 14) - cost, accuracy, recovery.

1. **1M triangles, plane**: the recovery's plane (:func:`mi_displace.inverse.recover.scene_dict`,
   64^2 Bricks102 bitmap) tessellated at 708^2 cells (1,002,528 triangles), one 256^2
   ``prb_projective`` render at 4 spp with the texels' gradient enabled (``forward_s``:
   re-displacement + render) and ``dr.backward`` of the L2 loss (``backward_s``); the
   process's peak resident memory (``resource.getrusage``) before the forward and after the
   backward.
2. **No-gradient overhead**: with no gradient enabled, the plugin's re-displacement (its
   parameters enter the kernels as ``mi.Float``s, the differentiable code path) against the
   same tessellation called with plain Python floats and a detached texture (the path
   without any AD), best of 5 each, same process (kernels synchronised); plus the plain
   forward render time.
3. **1M triangles, sphere** (``million_sphere``): a 1,046,528-triangle displaced sphere
   (ripples), a ``scale`` edit re-displaced without and with a gradient enabled (Mitsuba's
   BVH rebuild included, warm median of 3), one ``direct_projective`` render at 256^2,
   16 spp with the gradient, and its backward pass.
3b. **Mesh re-displacement** (``mesh_redisplacement``): a texel edit of the bunny
   recovery's 19,424-triangle model, the plugin against the same edit redoing the per-load
   work (thin-shell rays, topology, vertex frames), median of 5 each, same process.
4. **Gradient checks** (:mod:`mi_displace.inverse.gradcheck`): on the 16^2-map plane at
   32^2, ``scale``, ``midlevel`` and a Gaussian bump of texels (``height``), 64 spp, AD and
   central differences (256 spp, same seed per pair) each the mean of 16 seeds
   (``grad_rel_error_*``: the ``prb_projective`` ones); the procedural textures' continuous
   parameters on the sphere under a side light and under a light at the eye (no shadow
   boundaries in view); the four-bump sphere and a rectangle area light (``sppi`` 0 and
   64): the shadow-boundary bias.
5. **Recovery** (:func:`mi_displace.inverse.recover.recover`): 64^2 map, 3 views x 2 lights,
   64^2 images, 8 spp, 40 Adam steps, ``prb_projective``: ``recovery_rms`` = height RMS /
   range after the last step.

``--quick`` runs every part with :data:`QUICK` sizes (16^2 map, 48^2 plane and sphere
tessellations, 32^2 / 16^2 images, one seed per check, one procedural parameter per
texture, 2 recovery steps).

Writes ``grad_bench.json`` and the recovery figures (``recovery/``) under ``--out`` (default:
a folder ``mi_displace_bench/grad`` in the system's temporary directory); the documentation's
figures are refreshed by naming them: ``mi-displace bench grad --out docs/figures``.
"""
from __future__ import annotations

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

from mi_displace.bench._timing import output_dir, print_record
from mi_displace.core import tessellate
from mi_displace.core.texture_height import height_function
from mi_displace.figures.inverse import write
from mi_displace.inverse import gradcheck, recover


class Sizes(NamedTuple):
    """What a run renders: the plane's ``map_size``² height map tessellated at
    ``plane_resolution``² cells, the sphere at ``sphere_resolution`` (``sphere_spp``), both
    at ``image``² pixels; ``edits`` timed edits per path of the mesh re-displacement;
    ``seeds`` AD and FD seeds per plane check, ``check_seeds`` per procedural / shadow check,
    checks at ``check_image``² pixels, every ``procedural_step``-th parameter of
    :data:`~mi_displace.inverse.gradcheck.PROCEDURAL` (2: one per texture); ``iterations``
    recovery steps on a ``map_size``² map seen at ``recovery_image``² pixels."""
    map_size: int
    plane_resolution: int
    image: int
    sphere_resolution: int
    sphere_spp: int
    edits: int
    seeds: int
    check_seeds: int
    check_image: int
    procedural_step: int
    iterations: int
    recovery_image: int


FULL = Sizes(64, 708, 256, 1024, 16, 5, 16, 3, 32, 1, 40, 64)   # 2 * 708^2 = 1,002,528 triangles
QUICK = Sizes(16, 48, 32, 48, 4, 1, 1, 1, 16, 2, 2, 16)


def _peak_rss_gb() -> float:
    """Peak resident set size of this process so far [GB] (Linux: ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def million(truth: np.ndarray, sizes: Sizes = FULL) -> dict:
    """Forward + backward at 1M triangles, 256^2 (:data:`FULL`), and the no-gradient overhead."""
    scene = mi.load_dict(recover.scene_dict(truth, 1, sizes.image, 4, "prb_projective",
                                            resolution=sizes.plane_resolution))
    params = mi.traverse(scene)
    faces = int(params["surface.faces"].shape[0] // 3)
    target = mi.render(scene, spp=4, seed=1)
    surface = [s for s in scene.shapes() if s.id() == "surface"][0].surface

    # 2. no-gradient overhead: the plugin's path vs plain floats, detached texture
    def plugin_path():
        t, _ = surface.build()
        dr.eval(t.positions, t.normals)
        dr.sync_thread()

    def detached_path():
        height = height_function(surface.height_texture, 0.5 / max(surface.grid))
        t = tessellate.displace_parametric(surface.base, lambda uv: tuple(
            dr.detach(x) for x in height(uv)), float(surface.scale[0]), float(surface.midlevel[0]),
            *surface.grid)
        dr.eval(t.positions, t.normals)
        dr.sync_thread()

    def best(fn, n=5):
        times = []
        for _ in range(n):
            clock = time.perf_counter()
            fn()
            times.append(time.perf_counter() - clock)
        return min(times)

    plugin_path(), detached_path()   # compile both
    plugin_s, detached_s = best(plugin_path), best(detached_path)
    clock = time.perf_counter()
    image = mi.render(scene, spp=4, seed=2)
    dr.eval(image)
    dr.sync_thread()
    render_s = time.perf_counter() - clock

    # 1. forward + backward with the texels' gradient (second of two: kernels compiled)
    rss_before = _peak_rss_gb()
    for seed in (3, 4):
        params[recover.KEY] = mi.TensorXf((0.25 + 0.5 * truth)[..., None])
        dr.enable_grad(params[recover.KEY])
        clock = time.perf_counter()
        params.update()
        image = mi.render(scene, params, spp=4, seed=seed)
        loss = dr.mean(dr.square(image - target), axis=None)
        dr.eval(loss)
        dr.sync_thread()
        forward_s = time.perf_counter() - clock
        clock = time.perf_counter()
        dr.backward(loss)
        grad = dr.grad(params[recover.KEY])
        dr.eval(grad)
        dr.sync_thread()
        backward_s = time.perf_counter() - clock
    g = np.asarray(grad)
    return {"faces": faces, "image": sizes.image, "spp": 4, "integrator": "prb_projective",
            "forward_s": forward_s, "backward_s": backward_s,
            "grad_finite": bool(np.all(np.isfinite(g))), "grad_nonzero_texels": int(np.count_nonzero(g)),
            "peak_rss_before_gb": rss_before, "peak_rss_after_backward_gb": _peak_rss_gb(),
            "redisplace_nograd_plugin_s": plugin_s, "redisplace_detached_s": detached_s,
            "nograd_overhead_ratio": plugin_s / detached_s, "forward_render_nograd_s": render_s}


def million_sphere(sizes: Sizes = FULL) -> dict:
    """A ``scale`` edit, forward and backward on a 1,046,528-triangle displaced sphere
    (:data:`FULL`)."""
    spp = sizes.sphere_spp
    scene = gradcheck.sphere_scene({"type": "ripples"}, image_size=sizes.image, spp=spp,
                                   resolution=sizes.sphere_resolution)
    params = mi.traverse(scene)

    def edit_time(grad: bool) -> float:
        times = []
        for i in range(4):
            params["ball.scale"] = mi.Float(0.1 + 0.001 * i)
            if grad:
                dr.enable_grad(params["ball.scale"])
            dr.sync_thread()
            clock = time.perf_counter()
            params.update()
            dr.eval(params["ball.vertex_positions"])
            dr.sync_thread()
            times.append(time.perf_counter() - clock)
        return statistics.median(times[1:])

    plain, with_grad = edit_time(False), edit_time(True)
    target = mi.render(scene, spp=spp, seed=1)
    params["ball.scale"] = mi.Float(0.12)
    dr.enable_grad(params["ball.scale"])
    params.update()
    dr.sync_thread()
    clock = time.perf_counter()
    loss = dr.mean(dr.square(mi.render(scene, params, spp=spp, seed=2) - target), axis=None)
    dr.eval(loss)
    dr.sync_thread()
    forward_s = time.perf_counter() - clock
    clock = time.perf_counter()
    dr.backward(loss)
    grad = dr.grad(params["ball.scale"])
    dr.eval(grad)
    dr.sync_thread()
    return {"faces": scene.shapes()[0].face_count(), "image": sizes.image, "spp": spp,
            "integrator": "direct_projective", "redisplace_s": plain,
            "redisplace_grad_s": with_grad, "forward_s": forward_s,
            "backward_s": time.perf_counter() - clock, "grad_scale": float(grad[0]),
            "peak_rss_gb": _peak_rss_gb()}


def redo_per_load_work(shape) -> None:
    """Recompute what a uniform ``displaced`` shape on a mesh base computes once per load
    (refinement topology, vertex frames, welded directions) and drop its thin-shell rays: the next edit does
    all the work every edit did before they were kept (the baseline of the benches)."""
    surface = shape.surface   # the plugin's DisplacedSurface
    pos, _, _, faces = surface.mesh_data
    surface._topology = tessellate.subdivision_topology(faces, tessellate.weld_classes(pos),
                                                        surface.grid)
    surface._frames = tessellate.vertex_frames(*surface.mesh_data)
    surface._directions = tessellate.welded_normals(pos, surface.mesh_data[1], faces)
    surface._rays = None


def mesh_redisplacement(edits: int = 5) -> dict:
    """A texel edit of the bunny recovery's model (``displaced`` over ``low.obj``,
    ``subdivision`` 2, 64^2 bitmap): the plugin's re-displacement (the thin-shell check's
    rays, the refinement's topology and the vertex frames cast / computed once per load)
    against the same edit redoing that per-load work each time (what every edit did
    before), alternating, median of ``edits`` each, same process (kernels synchronised)."""
    from mi_displace.inverse import bunny

    baked, _, scale = bunny.baked_map(64)
    shape = mi.load_dict(bunny._model(np.full_like(baked, 0.5), scale))
    params = mi.traverse(shape)

    def edit(i: int, per_load_again: bool) -> float:
        params["height.data"] = mi.TensorXf(np.full_like(baked, 0.5 + 0.002 * i)[..., None])
        dr.sync_thread()
        clock = time.perf_counter()
        if per_load_again:
            redo_per_load_work(shape)
        params.update()
        dr.eval(params["vertex_positions"], params["vertex_normals"])
        dr.sync_thread()
        return time.perf_counter() - clock

    cached, again = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the bunny's ears: 2 vertices cross the base
        edit(0, True)
        edit(1, False)   # warm the kernels of both paths
        for i in range(edits):
            again.append(edit(2 * i + 2, True))
            cached.append(edit(2 * i + 3, False))
    cached_s, again_s = statistics.median(cached), statistics.median(again)
    return {"faces": shape.face_count(), "redisplace_s": cached_s,
            "redisplace_per_load_work_again_s": again_s, "speedup": again_s / cached_s}


CHECKS = (("scale", "surface.scale", 0.01), ("midlevel", "surface.midlevel", 0.02),
          ("height", recover.KEY, 0.05))      # (name, key, eps)


def checks(sizes: Sizes = FULL) -> dict:
    """Gradient checks of ``scale``, ``midlevel`` and a texel bump of the height map
    (16^2 texels, 32^2 image, 64 spp; differences at 256 spp; means of 16 seeds each:
    :data:`FULL`) under both projective integrators: {integrator: {name: gradcheck.check
    result}}."""
    n = 16
    truth = recover.load_height_map(size=n)
    out = {}
    for integrator in ("direct_projective", "prb_projective"):
        scene = mi.load_dict(recover.scene_dict(truth, 1, sizes.check_image, 64, integrator))
        target = mi.render(scene, spp=512, seed=99)
        params = mi.traverse(scene)
        params[recover.KEY] = mi.TensorXf((0.25 + 0.5 * truth)[..., None])
        params.update()
        bump = gradcheck.texel_bump((n, n, 1), (n // 2, n // 2), 1.5)
        out[integrator] = {name: gradcheck.check(
            scene, key, target, bump if key == recover.KEY else None, eps=eps,
            repeats=sizes.seeds, fd_repeats=sizes.seeds) for name, key, eps in CHECKS}
    return out


def procedural_checks(sizes: Sizes = FULL) -> list:
    """Every :data:`gradcheck.PROCEDURAL` parameter x both integrators x a side light and a
    light at the eye (3 seeds of AD and of FD each: :data:`FULL`): a list of records."""
    out = []
    for integrator in ("direct_projective", "prb_projective"):
        for light_name, light in (("eye", gradcheck.CAMERA), ("side", gradcheck.SIDE_LIGHT)):
            for texture, name, value, eps in gradcheck.PROCEDURAL[::sizes.procedural_step]:
                r = gradcheck.check_procedural(
                    texture, name, value, eps, integrator, light, repeats=sizes.check_seeds,
                    fd_repeats=sizes.check_seeds, image_size=sizes.check_image)
                out.append({"texture": texture["type"], "parameter": name,
                            "integrator": integrator, "light": light_name, **r})
    return out


def shadow_checks(sizes: Sizes = FULL) -> list:
    """The shadow-boundary bias: the truth branch's four-bump sphere (a 32 x 16 bitmap,
    h = 0.5 + 0.4 sin(4 pi u) sin(2 pi v); a uniform lift of its texels and ``midlevel``)
    under the side light and a light at the eye; and bricks' ``mortar`` under a 0.6 x 0.6
    rectangle area light at the side light's place, ``sppi`` 0 and on (any non-zero
    ``sppi`` is replaced by the render's 64 spp: Mitsuba's indirect-visibility term, which
    finds no samples for point lights)."""
    v, u = np.meshgrid((np.arange(16) + 0.5) / 16, (np.arange(32) + 0.5) / 32, indexing="ij")
    h = (0.5 + 0.4 * np.sin(4 * np.pi * u) * np.sin(2 * np.pi * v)).astype(np.float32)
    out = []
    for light_name, light in (("side", gradcheck.SIDE_LIGHT), ("eye", gradcheck.CAMERA)):
        scene = gradcheck.sphere_scene(recover.bitmap_height(h), light=light,
                                       image_size=sizes.check_image)
        for name, key, edit, eps, direction in (
                ("texel lift", "ball.height.data", mi.TensorXf(np.clip(h - 0.2, 0, 1)[..., None]),
                 0.1, mi.TensorXf(np.ones((16, 32, 1), np.float32))),
                ("midlevel", "ball.midlevel", mi.Float(0.3), 0.05, None)):
            r = gradcheck.check(scene, key, gradcheck.target_at(scene, key, edit), direction,
                                eps=eps, repeats=sizes.check_seeds, fd_repeats=sizes.check_seeds)
            out.append({"scene": "four bumps", "parameter": name, "light": light_name, **r})
    for sppi in (0, 64):
        base = gradcheck.sphere_scene({"type": "bricks"}, image_size=sizes.check_image)
        area = {"type": "rectangle", "to_world": mi.ScalarTransform4f().look_at(
            origin=list(gradcheck.SIDE_LIGHT), target=[0, 0, 0], up=[0, 0, 1]).scale(0.3),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 20 / 0.36}}}
        scene = mi.load_dict({"type": "scene", "sensor": base.sensors()[0],
                              "ball": base.shapes()[0], "light": area,
                              "integrator": {"type": "direct_projective", "sppi": sppi}})
        key = "ball.height.mortar"
        r = gradcheck.check(scene, key, gradcheck.target_at(scene, key, 0.15), eps=0.01,
                            repeats=sizes.check_seeds, fd_repeats=sizes.check_seeds)
        out.append({"scene": "bricks, area light", "parameter": "mortar",
                    "light": f"area, sppi {sppi}", **r})
    return out


def run(out: Path, sizes: Sizes = FULL) -> dict:
    """Every part (module docstring) at ``sizes``; the recovery figures go to ``out/recovery``."""
    truth = recover.load_height_map(size=sizes.map_size)
    big = million(truth, sizes)
    sphere = million_sphere(sizes)
    mesh = mesh_redisplacement(sizes.edits)
    grads = checks(sizes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # Mitsuba's sppi warning for point lights
        procedural = procedural_checks(sizes)
        shadows = shadow_checks(sizes)
    rec = recover.recover(truth, iterations=sizes.iterations, integrator="prb_projective",
                          image_size=sizes.recovery_image)
    write(rec, out / "recovery")
    eye = [r["rel_error"] for r in procedural if r["light"] == "eye"]
    summary = {
        "faces": big["faces"], "forward_s": big["forward_s"], "backward_s": big["backward_s"],
        "peak_rss_after_backward_gb": big["peak_rss_after_backward_gb"],
        "nograd_overhead_ratio": big["nograd_overhead_ratio"],
        "sphere_faces": sphere["faces"], "sphere_backward_s": sphere["backward_s"],
        "mesh_redisplace_s": mesh["redisplace_s"], "mesh_redisplace_speedup": mesh["speedup"],
        "grad_rel_error_scale": grads["prb_projective"]["scale"]["rel_error"],
        "grad_rel_error_height": grads["prb_projective"]["height"]["rel_error"],
        "grad_rel_error_procedural_max": max(eye),
        "recovery_rms": rec.rms[-1], "recovery_rms_start": rec.rms[0],
        "recovery_seconds_per_iteration": rec.summary()["seconds_per_iteration"],
    }
    return {"summary": summary, "million": big, "million_sphere": sphere,
            "mesh_redisplacement": mesh, "checks": grads,
            "procedural": procedural, "shadows": shadows, "recovery": rec.summary()}


def main(json: bool = False, quick: bool = False, out=None) -> int:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``); its JSON and figures go to
    ``out`` (default: :func:`~mi_displace.bench._timing.output_dir`)."""
    figures_dir = output_dir("grad", out)
    result = run(figures_dir, QUICK if quick else FULL)
    (figures_dir / "grad_bench.json").write_text(_json.dumps(result, indent=2))
    print_record(result["summary"], json, width=0)
    return 0
