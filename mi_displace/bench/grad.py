"""`mi-displace bench grad`: differentiable ``displaced`` (issue 14) - cost, accuracy, recovery.

1. **1M triangles**: the recovery's plane (:func:`mi_displace.inverse.recover.scene_dict`,
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
3. **Gradient checks** (:mod:`mi_displace.inverse.gradcheck`) on the 16^2-map plane at
   32^2: ``scale``, ``midlevel`` and a Gaussian bump of texels (``height``) under
   ``direct_projective`` and ``prb_projective``, 64 spp, AD mean of 3 seeds against central
   differences at 256 spp (``grad_rel_error_*``: the ``prb_projective`` ones).
4. **Recovery** (:func:`mi_displace.inverse.recover.recover`): 64^2 map, 3 views x 2 lights,
   64^2 images, 8 spp, 40 Adam steps, ``prb_projective``: ``recovery_rms`` = height RMS /
   range after the last step.

Writes ``docs/figures/grad_bench.json`` (and the recovery figures under
``docs/figures/recovery/``).
"""
from __future__ import annotations

import json as _json
import resource
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bench._timing import print_record
from mi_displace.core import tessellate
from mi_displace.core.texture_height import height_function
from mi_displace.inverse import figures, gradcheck, recover

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION_1M = 708          # 2 * 708^2 = 1,002,528 triangles


def _peak_rss_gb() -> float:
    """Peak resident set size of this process so far [GB] (Linux: ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def million(truth: np.ndarray) -> dict:
    """Forward + backward at 1M triangles, 256^2, and the no-gradient overhead."""
    scene = mi.load_dict(recover.scene_dict(truth, 1, 256, 4, "prb_projective",
                                            resolution=RESOLUTION_1M))
    params = mi.traverse(scene)
    faces = int(params["surface.faces"].shape[0] // 3)
    target = mi.render(scene, spp=4, seed=1)
    shape = [s for s in scene.shapes() if s.id() == "surface"][0]

    # 2. no-gradient overhead: the plugin's path vs plain floats, detached texture
    def plugin_path():
        t, _ = shape._build()
        dr.eval(t.positions, t.normals)
        dr.sync_thread()

    def detached_path():
        height = height_function(shape.height_texture, 0.5 / max(shape.grid))
        t = tessellate.displace_parametric(shape.base, lambda uv: tuple(
            dr.detach(x) for x in height(uv)), float(shape.scale[0]), float(shape.midlevel[0]),
            *shape.grid)
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
    return {"faces": faces, "image": 256, "spp": 4, "integrator": "prb_projective",
            "forward_s": forward_s, "backward_s": backward_s,
            "grad_finite": bool(np.all(np.isfinite(g))), "grad_nonzero_texels": int(np.count_nonzero(g)),
            "peak_rss_before_gb": rss_before, "peak_rss_after_backward_gb": _peak_rss_gb(),
            "redisplace_nograd_plugin_s": plugin_s, "redisplace_detached_s": detached_s,
            "nograd_overhead_ratio": plugin_s / detached_s, "forward_render_nograd_s": render_s}


CHECKS = (("scale", "surface.scale", 0.01), ("midlevel", "surface.midlevel", 0.02),
          ("height", recover.KEY, 0.05))      # (name, key, eps)


def checks() -> dict:
    """Gradient checks of ``scale``, ``midlevel`` and a texel bump of the height map
    (16^2 texels, 32^2 image, 64 spp, AD mean of 3 seeds; differences at 256 spp) under
    both projective integrators: {integrator: {name: gradcheck.check result}}."""
    n = 16
    truth = recover.load_height_map(size=n)
    out = {}
    for integrator in ("direct_projective", "prb_projective"):
        scene = mi.load_dict(recover.scene_dict(truth, 1, 32, 64, integrator))
        target = mi.render(scene, spp=512, seed=99)
        params = mi.traverse(scene)
        params[recover.KEY] = mi.TensorXf((0.25 + 0.5 * truth)[..., None])
        params.update()
        bump = gradcheck.texel_bump((n, n, 1), (n // 2, n // 2), 1.5)
        out[integrator] = {name: gradcheck.check(
            scene, key, target, bump if key == recover.KEY else None, eps=eps, repeats=3)
            for name, key, eps in CHECKS}
    return out


def run() -> dict:
    truth = recover.load_height_map(size=64)
    big = million(truth)
    grads = checks()
    rec = recover.recover(truth, iterations=40, integrator="prb_projective")
    figures.write(rec, ROOT / "docs" / "figures" / "recovery")
    summary = {
        "faces": big["faces"], "forward_s": big["forward_s"], "backward_s": big["backward_s"],
        "peak_rss_after_backward_gb": big["peak_rss_after_backward_gb"],
        "nograd_overhead_ratio": big["nograd_overhead_ratio"],
        "grad_rel_error_scale": grads["prb_projective"]["scale"]["rel_error"],
        "grad_rel_error_height": grads["prb_projective"]["height"]["rel_error"],
        "recovery_rms": rec.rms[-1], "recovery_rms_start": rec.rms[0],
        "recovery_seconds_per_iteration": rec.summary()["seconds_per_iteration"],
    }
    return {"summary": summary, "million": big, "checks": grads, "recovery": rec.summary()}


def main(json: bool = False) -> int:
    result = run()
    figures_dir = ROOT / "docs" / "figures"
    figures_dir.mkdir(parents=True, exist_ok=True)
    (figures_dir / "grad_bench.json").write_text(_json.dumps(result, indent=2))
    print_record(result["summary"], json, width=0)
    return 0
