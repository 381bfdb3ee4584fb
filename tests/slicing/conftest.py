"""Shared helpers of the slicing tests: small scenes rendered with ``raster``."""
import mitsuba as mi
import numpy as np
import pytest

from slicing_scenes import MATERIAL


def look(origin, target, fov=40, res=48, ortho_size=None):
    """A perspective (or orthographic of half width ``ortho_size``) sensor dict."""
    to_world = mi.ScalarTransform4f().look_at(origin=origin, target=target, up=[0, 0, 1])
    film = {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}
    if ortho_size is not None:
        return {"type": "orthographic", "film": film,
                "to_world": to_world @ mi.ScalarTransform4f().scale([ortho_size, ortho_size, 1])}
    return {"type": "perspective", "fov": fov, "to_world": to_world, "film": film}


def render(shape, sensor, integrator="raster", spp=1, ambient=0.1, sun=2.0, seed=0):
    """(image, scene): ``shape`` under a directional light + constant ambient."""
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": integrator, **({"max_depth": 2} if integrator == "path" else {})},
        "obj": shape,
        "sun": {"type": "directional", "direction": [-0.4, 0.5, -0.75], "irradiance": sun},
        "amb": {"type": "constant", "radiance": ambient},
        "sensor": sensor,
    })
    img = np.array(mi.render(scene, spp=spp, seed=seed))[..., :3]
    assert np.all(np.isfinite(img)), "non-finite pixels"
    return img, scene


def plane(kind="slicing", height=None, scale=0.2, **kw):
    """A plane base of either plugin with a brick height field."""
    height = height or {"type": "bricks", "rows": 4, "columns": 2, "mortar": 0.15, "bevel": 0.2}
    d = {"type": kind, "base": "plane", "height": height, "scale": scale, "bsdf": MATERIAL}
    if kind == "displaced":
        d["resolution"] = 512
    else:
        d.update({"draw_base": True, **kw})
    return d


@pytest.fixture
def helpers():
    import types
    return types.SimpleNamespace(look=look, render=render, plane=plane, MATERIAL=MATERIAL)
