"""Gradient checks of an image loss against central finite differences (issue 14).

L(theta) = mean over pixels of (render(theta) - target)^2, one sensor.  The AD value is
dL/dtheta . direction from one ``mi.render`` + ``dr.backward`` (seed ``seed``); the finite
difference is (L(theta + eps d) - L(theta - eps d)) / (2 eps) with both renders at
``fd_spp`` samples and the *same* seed (correlated samples: the noise of the two renders
largely cancels).  ``ad_noise``: the standard deviation of the AD value over ``repeats``
seeds, the yardstick of the error.
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
          fd_spp: int = 256, seed: int = 3, repeats: int = 1) -> dict:
    """AD against central differences for parameter ``key`` of ``scene`` along ``direction``
    (same type as the parameter; default 1), L2 loss against the image ``target``.

    Returns {ad, fd, rel_error (|ad - fd| / |fd|), ad_noise (std over ``repeats`` seeds,
    0 for one), grad_finite (every entry of dL/dkey finite)}; the parameter is restored."""
    params = mi.traverse(scene)
    if key not in params:
        raise KeyError(f"gradcheck: {key!r} is not a parameter of the scene")
    v0 = type(params[key])(params[key])
    direction = type(v0)(1.0) if direction is None else direction
    ads, finite = [], True
    for r in range(repeats):
        loss = _loss(scene, params, key, type(v0)(v0), target, spp, seed + 1009 * r, grad=True)
        dr.backward(loss)
        g = dr.grad(params[key])
        finite &= bool(np.all(np.isfinite(np.asarray(g))))
        ads.append(float(dr.sum(g * direction, axis=None).array[0]))
    plus = _loss(scene, params, key, type(v0)(v0 + eps * direction), target, fd_spp, seed + 1)
    minus = _loss(scene, params, key, type(v0)(v0 - eps * direction), target, fd_spp, seed + 1)
    fd = float((plus - minus).array[0]) / (2 * eps)
    params[key] = v0
    params.update()
    ad = float(np.mean(ads))
    return {"ad": ad, "fd": fd, "rel_error": abs(ad - fd) / max(abs(fd), 1e-30),
            "ad_noise": float(np.std(ads, ddof=1)) if repeats > 1 else 0.0,
            "grad_finite": finite}


def texel_bump(shape, center, radius: float) -> mi.TensorXf:
    """A smooth bump of texels (Gaussian, peak 1, std ``radius`` texels) at ``center``
    (row, col): a perturbation direction touching a few texels of an (n, m, 1) map."""
    rows, cols = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    d2 = (rows - center[0]) ** 2 + (cols - center[1]) ** 2
    bump = np.exp(-d2 / (2 * radius ** 2)).astype(np.float32)
    bump[bump < 1e-3] = 0
    return mi.TensorXf(bump[..., None])
