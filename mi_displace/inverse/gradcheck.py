"""Gradient checks of an image loss against central finite differences (issue 14).

L(theta) = mean over pixels of (render(theta) - target)^2, one sensor.  The AD value is
dL/dtheta . direction from ``mi.render`` + ``dr.backward``, the mean over ``repeats`` seeds;
the finite difference is (L(theta + eps d) - L(theta - eps d)) / (2 eps) with both renders
at ``fd_spp`` samples and the *same* seed (correlated samples: the noise of the two renders
largely cancels), the mean over ``fd_repeats`` seeds.  ``ad_noise`` / ``fd_noise``: the
standard deviation of one AD value / one difference over the seeds, the yardsticks of the
error (on the recovery plane one 256-spp difference of a texel bump scatters by 14 % of its
value: a single difference cannot check a gradient to 10 %).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def _loss(scene, params, key, value, target, spp, seed, grad=False):
    params[key] = value
    if grad:
        dr.enable_grad(params[key])
    params.update()
    image = mi.render(scene, params, spp=spp, seed=seed)
    if not np.all(np.isfinite(np.asarray(image))):
        raise FloatingPointError(f"gradcheck: render with {key!r} edited holds NaN/Inf")
    return dr.mean(dr.square(image - target), axis=None)


def check(scene, key: str, target, direction=None, eps: float = 1e-2, spp: int = 64,
          fd_spp: int = 256, seed: int = 3, repeats: int = 1, fd_repeats: int = 1) -> dict:
    """AD against central differences for parameter ``key`` of ``scene`` along ``direction``
    (same type as the parameter; default 1), L2 loss against the image ``target``.

    Returns {ad, fd (means over the seeds), rel_error (|ad - fd| / |fd|), ad_noise, fd_noise
    (std of one value over the seeds, 0 for one seed), stderr (the standard error of
    ad - fd), grad_finite (every entry of dL/dkey finite)}; the parameter is restored."""
    params = mi.traverse(scene)
    if key not in params:
        raise KeyError(f"gradcheck: {key!r} is not a parameter of the scene")
    v0 = type(params[key])(params[key])
    direction = type(v0)(1.0) if direction is None else direction
    ads, fds, finite = [], [], True
    for r in range(repeats):
        loss = _loss(scene, params, key, type(v0)(v0), target, spp, seed + 1009 * r, grad=True)
        dr.backward(loss)
        g = dr.grad(params[key])
        finite &= bool(np.all(np.isfinite(np.asarray(g))))
        ads.append(float(dr.sum(g * direction, axis=None).array[0]))
    for r in range(fd_repeats):
        fd_seed = seed + 1 + 2003 * r
        plus = _loss(scene, params, key, type(v0)(v0 + eps * direction), target, fd_spp, fd_seed)
        minus = _loss(scene, params, key, type(v0)(v0 - eps * direction), target, fd_spp, fd_seed)
        fds.append(float((plus - minus).array[0]) / (2 * eps))
    params[key] = v0
    params.update()
    ad, fd = float(np.mean(ads)), float(np.mean(fds))
    ad_noise, fd_noise = (float(np.std(x, ddof=1)) if len(x) > 1 else 0.0 for x in (ads, fds))
    return {"ad": ad, "fd": fd, "rel_error": abs(ad - fd) / max(abs(fd), 1e-30),
            "ad_noise": ad_noise, "fd_noise": fd_noise,
            "stderr": float(np.hypot(ad_noise / np.sqrt(repeats), fd_noise / np.sqrt(fd_repeats))),
            "spp": spp, "fd_spp": fd_spp, "repeats": repeats, "fd_repeats": fd_repeats,
            "eps": eps, "grad_finite": finite}


def agrees(r: dict, rel: float = 0.1) -> bool:
    """Whether a :func:`check` result passes: finite, the sign right, and |AD - FD| within
    ``rel`` |FD| plus 3 standard errors of AD - FD (the part the samples explain)."""
    return bool(r["grad_finite"] and abs(r["fd"]) > 0 and np.sign(r["ad"]) == np.sign(r["fd"])
                and abs(r["ad"] - r["fd"]) <= rel * abs(r["fd"]) + 3 * r["stderr"])


def texel_bump(shape, center, radius: float) -> mi.TensorXf:
    """A smooth bump of texels (Gaussian, peak 1, std ``radius`` texels) at ``center``
    (row, col): a perturbation direction touching a few texels of an (n, m, 1) map."""
    rows, cols = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    d2 = (rows - center[0]) ** 2 + (cols - center[1]) ** 2
    bump = np.exp(-d2 / (2 * radius ** 2)).astype(np.float32)
    bump[bump < 1e-3] = 0
    return mi.TensorXf(bump[..., None])


CAMERA = (0.0, -4.0, 0.5)          # the sphere scenes' camera, looking at the origin
SIDE_LIGHT = (2.0, -3.0, 2.0)      # a point light off the camera: self-shadows in view


def sphere_scene(height: dict, integrator: str = "direct_projective", light=SIDE_LIGHT,
                 camera=CAMERA, up=(0, 0, 1), image_size: int = 32, spp: int = 64,
                 **shape) -> mi.Scene:
    """A ``displaced`` shape (key ``ball``; default: unit sphere, ``resolution`` 48,
    ``scale`` 0.1, ``midlevel`` 0.5; ``shape`` overrides, a ``base`` or ``dicing_rate`` with
    its own settings; the camera's id is ``sensor``) over the texture dict ``height``,
    one point light (intensity 20) at ``light``, one 35-degree camera at ``camera`` looking
    at the origin, ``image_size``^2 box-filtered pixels.

    ``light=camera`` puts the light at the eye: every shadow the light casts is hidden behind
    what casts it, so the image has no shadow boundaries.  (Mitsuba's projective integrators
    do not differentiate the shadow boundaries of a point or directional light: their
    indirect-visibility sampling finds no silhouette samples for delta emitters.)"""
    integ = {"type": integrator, "sppi": 0}
    if integrator != "direct_projective":
        integ["max_depth"] = 2
    return mi.load_dict({
        "type": "scene", "integrator": integ,
        "sensor": {"type": "perspective", "fov": 35, "to_world": mi.ScalarTransform4f().look_at(
            origin=list(camera), target=[0, 0, 0], up=list(up)),
            "film": {"type": "hdrfilm", "width": image_size, "height": image_size,
                     "rfilter": {"type": "box"}, "sample_border": True},
            "sampler": {"type": "independent", "sample_count": spp}},
        "light": {"type": "point", "position": list(light),
                  "intensity": {"type": "rgb", "value": 20}},
        "ball": {"type": "displaced", "height": height, "scale": 0.1, "midlevel": 0.5,
                 **({} if "base" in shape else {"base": "sphere"}),
                 **({} if {"base", "dicing_rate"} & set(shape) else {"resolution": 48}),
                 **shape}})


PROCEDURAL = (   # (texture, parameter, target value, eps): one continuous parameter each
    ({"type": "ripples", "frequency": 4.0}, "frequency_u", 4.3, 0.05),
    ({"type": "ripples", "frequency": 4.0}, "phase", 0.5, 0.05),
    ({"type": "bricks"}, "mortar", 0.15, 0.01),
    ({"type": "bricks"}, "bevel", 0.2, 0.01),
    ({"type": "cells", "jitter": 0.5}, "radius", 0.6, 0.02),
    ({"type": "cells", "jitter": 0.5}, "jitter", 0.6, 0.02),
)
"""The procedural height parameters checked (tests and ``bench grad``)."""


def check_procedural(texture: dict, name: str, target_value: float, eps: float,
                     integrator: str = "direct_projective", light=SIDE_LIGHT,
                     repeats: int = 3, fd_repeats: int = 3, **scene) -> dict:
    """:func:`check` of the texture parameter ``ball.height.<name>`` on
    :func:`sphere_scene`, the target rendered (512 spp) at ``target_value``."""
    sc = sphere_scene(texture, integrator, light, **scene)
    key = f"ball.height.{name}"
    return check(sc, key, target_at(sc, key, target_value), eps=eps, repeats=repeats,
                 fd_repeats=fd_repeats)


def target_at(scene, key: str, value, spp: int = 512, seed: int = 99):
    """The target image: ``scene`` rendered (``spp``, ``seed``) with parameter ``key`` set
    to ``value``; the parameter is restored."""
    params = mi.traverse(scene)
    v0 = type(params[key])(params[key])
    params[key] = value
    params.update()
    target = mi.render(scene, spp=spp, seed=seed)
    params[key] = v0
    params.update()
    return target
