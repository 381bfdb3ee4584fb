"""Shadow maps (shadows="map") against shadow rays on the same visible points: the shadow
decisions agree on all but a small fraction that falls with the map resolution, for spot,
point (cube map) and directional lights; bad light types are refused."""
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.render import raster
from test_zbuffer import camera, displaced_sphere


def scene(light):
    lights = {
        "point": {"type": "point", "position": [3, -3, 1], "intensity": {"type": "rgb", "value": 40}},
        "spot": {"type": "spot", "cutoff_angle": 25, "intensity": {"type": "rgb", "value": 60},
                 "to_world": mi.ScalarTransform4f().look_at(origin=[2, -3, 2], target=[0, 0, 0],
                                                            up=[0, 0, 1])},
        "sun": {"type": "directional", "direction": [-1, 1, -0.4],
                "irradiance": {"type": "rgb", "value": 0.5}},
    }
    return mi.load_dict({"type": "scene", "integrator": {"type": "raster"},
                         "sensor": camera(res=(96, 96)), "s": displaced_sphere(),
                         "light": lights[light]})


def disagreement(sc, resolution):
    hit, (ray,) = raster.light_masks(sc, sc.sensors()[0], raster.Options(shadows="ray"))
    _, (smap,) = raster.light_masks(sc, sc.sensors()[0], raster.Options(
        shadows="map", shadow_resolution=resolution))
    hit, ray, smap = np.array(hit), np.array(ray), np.array(smap)
    assert 0.05 < ray[hit].mean() < 0.95  # lit and shadowed points both exist
    return np.mean(ray[hit] != smap[hit])


@pytest.mark.parametrize("light", ["point", "spot", "sun"])
def test_shadow_map_converges_to_shadow_rays(variant, light):
    sc = scene(light)
    coarse, fine = disagreement(sc, 128), disagreement(sc, 2048)
    assert fine < 0.012
    assert fine < 0.5 * coarse


def test_shadow_map_image_close_to_shadow_rays(variant):
    sc = scene("point")
    sensor = sc.sensors()[0]
    ray = np.array(raster.render(sc, sensor))
    smap = np.array(raster.render(sc, sensor, options=raster.Options(
        visibility="zbuffer", shadows="map")))
    none = np.array(raster.render(sc, sensor, options=raster.Options(shadows="none")))
    assert np.all(np.isfinite(smap)) and np.all(np.isfinite(none))
    assert np.mean(np.abs(smap - ray).max(axis=2) > 1e-3) < 0.02
    assert np.all(none >= ray - 1e-6) and none.mean() > ray.mean()


def test_unsupported_delta_light(variant):
    sc = mi.load_dict({"type": "scene", "sensor": camera(), "s": displaced_sphere(),
                       "light": {"type": "projector", "irradiance": 1.0,
                                 "to_world": mi.ScalarTransform4f().look_at(
                                     origin=[0, -3, 2], target=[0, 0, 0], up=[0, 0, 1])}})
    with pytest.raises(ValueError, match="shadows='map' supports"):
        raster.render(sc, sc.sensors()[0], options=raster.Options(shadows="map"))
