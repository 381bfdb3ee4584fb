"""Adjoint transport (issue 15 item 2): ptracer and path agree on vdm, horizon and relief
as closely as on true displacement of the same relief (the control)."""
import mitsuba as mi
import numpy as np

MAT = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.6}}


def _height():
    return {"type": "cells", "cells": 2, "radius": 0.45,
            "to_uv": mi.ScalarTransform4f().scale([2, 2, 1])}


def _shape(kind):
    if kind == "control":
        return {"type": "displaced", "base": "plane", "resolution": 256, "scale": 0.1,
                "midlevel": 1.0, "height": _height(), "bsdf": MAT}
    bsdf = {"type": kind, "height": _height(), "depth": 0.1, "tiling": 2, "nested": MAT}
    if kind == "vdm":
        bsdf.update(res=32, phi=16, curvatures=1)
    return {"type": "vdm_mesh", "base": "plane", "resolution": 4, "bsdf": bsdf}


def _render(kind, integrator, spp=128, res=48):
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": integrator, "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 40, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -2.2, 2.0], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
        "sun": {"type": "directional", "direction": [-0.5, 0.6, -0.6],
                "irradiance": {"type": "rgb", "value": 2.0}},
        "shape": _shape(kind)})
    img = np.asarray(mi.render(scene, spp=spp))
    assert np.all(np.isfinite(img))
    return img


def _disagreement(kind):
    """(mean |ptracer - path| over 4 x 4 pixel blocks, ptracer flux / path flux)."""
    p, t = _render(kind, "path"), _render(kind, "ptracer")
    blocks = lambda x: x.reshape(12, 4, 12, 4, 3).mean((1, 3))
    return float(np.abs(blocks(p) - blocks(t)).mean()), float(t.sum() / p.sum())


def test_ptracer_agrees_with_path(variant):
    control, control_flux = _disagreement("control")
    assert abs(control_flux - 1) < 0.01
    for kind in ("vdm", "horizon", "relief"):
        diff, flux = _disagreement(kind)
        # measured: 0.0038-0.0040 for all four (control 0.0040) at 128 spp; before the
        # adjoint eval 3.9-4.1x the control (Mitsuba's own bumpmap: 3.9x)
        assert diff < 1.5 * control, (kind, diff, control)
        assert abs(flux - 1) < 0.01, (kind, flux)
