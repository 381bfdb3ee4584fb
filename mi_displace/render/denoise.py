"""Path tracing plus a denoiser: Intel Open Image Denoise fed the noisy render and its AOVs.

The competitor a user actually runs when a picture is wanted fast is a low-spp path trace
cleaned by a denoiser (Blender's Cycles with Open Image Denoise).  :func:`render_denoised`
renders the scene's own integrator wrapped in Mitsuba's ``aov`` integrator, so the noisy
colour, the albedo (``albedo``) and the shading normal (``sh_normal``) come from the same
pass (the colour is bit-identical to a plain render with the same seed), and denoises the
colour with OIDN's ``RT`` filter (HDR input, albedo and normal as auxiliary images, not
assumed clean so OIDN prefilters them).  The denoiser runs on OIDN's CPU device; on the
same machine the same input gives the same output (checked in
``tests/render/test_denoise.py``).

OIDN comes from the ``pyoidn`` package (it ships the library): the ``denoise`` extra,
``pip install 'mi-displace[denoise]'``.
"""
from __future__ import annotations

import time

import mitsuba as mi
import numpy as np

from mi_displace.core.extras import require
from mi_displace.render import scene as scenes

#: OIDN's quality settings (``OIDN_QUALITY_*``), fastest first: the denoiser's knob.
QUALITIES = ("fast", "balanced", "high")
#: The ``aov`` integrator's outputs after the colour: albedo RGB, then shading normal XYZ.
AOVS = "albedo:albedo,nn:sh_normal"


def check_quality(quality: str) -> str:
    """``quality`` if it is one of :data:`QUALITIES`, and ``pyoidn`` importable.

    Raises:
        ValueError: another quality (the message names the parameter and the choices).
        mi_displace.core.extras.MissingExtraError: ``pyoidn`` is not installed.
    """
    if quality not in QUALITIES:
        raise ValueError(f"denoise: quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
    require("pyoidn", "denoise", "the denoiser")
    return quality


def denoise(color: np.ndarray, albedo: np.ndarray, normal: np.ndarray,
            quality: str = "high") -> np.ndarray:
    """Denoise a linear HDR render with OIDN's ``RT`` filter.

    Args:
        color: noisy linear RGB radiance, ``(H, W, 3)`` float32, non-negative.
        albedo: first-hit albedo in [0, 1], ``(H, W, 3)`` (noisy: OIDN prefilters it).
        normal: first-hit shading normal in world space, ``(H, W, 3)`` in [-1, 1].
        quality: one of :data:`QUALITIES`.

    Returns:
        The denoised linear RGB image, ``(H, W, 3)`` float32.
    """
    check_quality(quality)
    pyoidn = require("pyoidn", "denoise", "the denoiser")
    images = [np.ascontiguousarray(a, dtype=np.float32) for a in (color, albedo, normal)]
    return pyoidn.denoise(*images, hdr=True, clean_aux=False, quality=quality)


def render_denoised(scene, spp: int, seed: int = 0,
                    quality: str = "high") -> tuple[np.ndarray, np.ndarray, dict]:
    """Render ``scene`` with its integrator and AOVs in one pass, then denoise the colour.

    Args:
        scene: a loaded ``mi.Scene`` (its integrator is wrapped, not replaced).
        spp: samples per pixel.
        seed: sampler seed (the colour equals ``scenes.render(scene, spp, seed)``).
        quality: OIDN's quality, one of :data:`QUALITIES`.

    Returns:
        ``(denoised, noisy, times)``: linear RGB ``(H, W, 3)`` float32 images, and
        ``{"render_s": the AOV render, "denoise_s": the denoiser}`` (wall seconds).
    """
    check_quality(quality)
    aov = mi.load_dict({"type": "aov", "aovs": AOVS, "integrator": scene.integrator()})
    image, render_s = scenes.render(scene, spp=spp, seed=seed, integrator=aov)
    # RGB first; the six AOV channels last (an alpha channel, if the film keeps one, between)
    color, albedo, normal = image[..., :3], image[..., -6:-3], image[..., -3:]
    start = time.perf_counter()
    denoised = denoise(color, albedo, normal, quality)
    return denoised, np.ascontiguousarray(color), {"render_s": render_s,
                                                   "denoise_s": time.perf_counter() - start}
