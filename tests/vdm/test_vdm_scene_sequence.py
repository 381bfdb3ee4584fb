"""Scenes loaded one after another in one process: a mesostructure BSDF that was never set
up (no vdm_mesh, no tile_size) fails its own scene's render, and only its own.

Dr.Jit traces every live BSDF into each vectorised call, so such a BSDF of a scene that is
still alive (a reference cycle, a notebook's last traceback) used to fail every later render
with its "not set up" error: the order-dependent failure of the full test run.
"""
import mitsuba as mi
import numpy as np
import pytest

SMALL = {"res": 16, "theta": 4, "phi": 8, "curvatures": 2}


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))


def _scene(shape, integrator):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": integrator},
        "sensor": {"type": "perspective", "fov": 40, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -4, 1.5], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}},
        "amb": {"type": "constant"}, "shape": shape})


def _bsdf(plugin, **kw):
    extra = SMALL if plugin == "vdm" else {}
    return dict({"type": plugin, "height": {"type": "cells", "cells": 2}, "depth": 0.05}, **extra, **kw)


def _messages(error):
    chain = []
    while error is not None:
        chain.append(str(error))
        error = error.__cause__ or error.__context__
    return chain


def _fails_not_set_up(scene, plugin):
    with pytest.raises(Exception) as info:
        mi.render(scene, spp=1)
    assert any(m.startswith(f"{plugin}: BSDF") and "not set up" in m
               for m in _messages(info.value)), _messages(info.value)


@pytest.mark.parametrize("integrator", ["path", "raster"])
@pytest.mark.parametrize("plugin", ["vdm", "horizon", "relief"])
def test_an_unset_bsdf_fails_only_its_own_scene(variant, plugin, integrator):
    broken = _scene({"type": "sphere", "bsdf": _bsdf(plugin)}, integrator)   # kept alive
    _fails_not_set_up(broken, plugin)
    # later scenes in the same process render, with the broken one still alive: a plain
    # material, and the same plugin set up properly on a vdm_mesh
    plain = _scene({"type": "sphere", "bsdf": {"type": "diffuse"}}, integrator)
    good = _scene({"type": "vdm_mesh", "base": "sphere", "resolution": 8,
                   "bsdf": _bsdf(plugin)}, integrator)
    for scene in (plain, good):
        img = np.asarray(mi.render(scene, spp=1))
        assert np.all(np.isfinite(img)) and img.mean() > 0.05
    # ... and the broken scene still says what is wrong with it
    _fails_not_set_up(broken, plugin)
