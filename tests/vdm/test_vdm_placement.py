"""VDM and its baselines placed by to_world or by an instance (issue 15 items 8, 10)."""
import mitsuba as mi
import numpy as np
import pytest



def T4():
    return mi.ScalarTransform4f()


def _place():
    """A rigid motion with a uniform scale."""
    return T4().translate([0.3, -0.2, 0.1]).rotate([0.6, 0.8, 0], 40).scale(1.5)


def _torus(kind, **kw):
    height = {"type": "cells", "cells": 2, "radius": 0.45, "to_uv": T4().scale([6, 2, 1])}
    bsdf = {"type": kind, "height": height, "depth": 0.06, "tiling_u": 6, "tiling_v": 2}
    if kind == "vdm":
        bsdf.update(res=32, phi=16, curvatures=4)
    return dict({"type": "vdm_mesh", "base": "torus", "major_radius": 1.0,
                 "minor_radius": 0.4, "resolution": 32, "bsdf": bsdf}, **kw)


def _render(shapes, scale=1.0):
    """Raster image; ``scale`` scales the camera and light positions (and the light's
    intensity by scale^2, so that a scene scaled as a whole renders the same image)."""
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "raster"},
        "sensor": {"type": "perspective", "fov": 35, "to_world": T4().look_at(
            origin=[0, -6 * scale, 3 * scale], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"}}},
        "key": {"type": "point", "position": [3 * scale, -2 * scale, 3 * scale],
                "intensity": {"type": "rgb", "value": 60 * scale ** 2}},
        "amb": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}}, **shapes})
    img = np.asarray(mi.render(scene))
    assert np.all(np.isfinite(img))
    return img


@pytest.mark.parametrize("kind", ["vdm", "horizon", "relief"])
def test_instance_equals_to_world(variant, kind):
    placed = _render({"s": _torus(kind, to_world=_place())})
    instanced = _render({"g": {"type": "shapegroup", "s": _torus(kind)},
                         "i": {"type": "instance", "shapegroup": {"type": "ref", "id": "g"},
                               "to_world": _place()}})
    # measured 7e-5 (vdm) and 2e-6 (plain material); before: 76 pixels off by > 0.05
    assert np.abs(placed - instanced).max() < 1e-3


@pytest.mark.parametrize("kind", ["vdm", "horizon", "relief"])
def test_depth_follows_to_world_like_displaced_scale(variant, kind):
    """A scene scaled as a whole (mesh by to_world, camera and light positions) renders
    the same image: the relief scales with the mesh, as `displaced`'s scale does."""
    base = _render({"s": _torus(kind)})
    scaled = _render({"s": _torus(kind, to_world=T4().scale(2.0))}, scale=2.0)
    assert np.abs(base - scaled).max() < 2e-3, np.abs(base - scaled).max()
    shape = mi.load_dict(_torus(kind, to_world=T4().scale(2.0)))
    ref = mi.load_dict(_torus(kind))
    assert shape.bsdf().stats["tile_size"] == pytest.approx(ref.bsdf().stats["tile_size"])
