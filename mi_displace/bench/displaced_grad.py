"""`mi-displace bench displaced_grad`: cost of the differentiable `displaced` path (issue 14).

* ``redisplace_s`` / ``redisplace_grad_s``: re-displacing a 1M-triangle sphere after a
  ``scale`` edit (``params.update()``, warm median of 3) without and with a gradient enabled
  on ``scale`` (same process; Mitsuba rebuilds its acceleration structure in both);
* ``forward_s`` / ``backward_s``: one ``direct_projective`` render at 256^2, 16 spp, of
  that shape with the gradient enabled, and ``dr.backward`` of an L2 loss;
* ``peak_rss_gb``: the process's peak resident memory after the backward pass.
"""
from __future__ import annotations

import resource
import statistics
import time

import drjit as dr
import mitsuba as mi

from mi_displace.bench._timing import print_record


def _scene() -> mi.Scene:
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "direct_projective", "sppi": 0},
        "sensor": {"type": "perspective", "fov": 35, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -4, 0.5], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 256, "height": 256, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": 16}},
        "light": {"type": "point", "position": [2, -3, 2], "intensity": {"type": "rgb", "value": 20}},
        "ball": {"type": "displaced", "base": "sphere", "resolution": 1024, "scale": 0.1,
                 "midlevel": 0.5, "height": {"type": "ripples"}}})


def _edit_time(params, grad: bool) -> float:
    times = []
    for i in range(4):
        params["ball.scale"] = mi.Float(0.1 + 0.001 * i)
        if grad:
            dr.enable_grad(params["ball.scale"])
        dr.sync_thread()
        start = time.perf_counter()
        params.update()
        dr.eval(params["ball.vertex_positions"])
        dr.sync_thread()
        times.append(time.perf_counter() - start)
    return statistics.median(times[1:])


def run() -> dict:
    scene = _scene()
    params = mi.traverse(scene)
    faces = scene.shapes()[0].face_count()
    plain = _edit_time(params, grad=False)
    with_grad = _edit_time(params, grad=True)
    target = mi.render(scene, spp=16, seed=1)
    dr.eval(target)
    params["ball.scale"] = mi.Float(0.12)
    dr.enable_grad(params["ball.scale"])
    params.update()
    dr.sync_thread()
    start = time.perf_counter()
    image = mi.render(scene, params, spp=16, seed=2)
    loss = dr.mean(dr.square(image - target), axis=None)
    dr.eval(loss)
    dr.sync_thread()
    forward = time.perf_counter() - start
    start = time.perf_counter()
    dr.backward(loss)
    grad = dr.grad(params["ball.scale"])
    dr.eval(grad)
    dr.sync_thread()
    backward = time.perf_counter() - start
    return {"faces": faces, "redisplace_s": plain, "redisplace_grad_s": with_grad,
            "forward_s": forward, "backward_s": backward, "grad_scale": float(grad[0]),
            "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20}


def main(json: bool = False) -> int:
    print_record(run(), json, width=0)
    return 0
