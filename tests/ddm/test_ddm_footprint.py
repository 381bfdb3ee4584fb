"""map_resolution="auto" from the base's screen footprint (issue 13), on a mesh base whose
lookups straddle UV charts, and build_stats."""
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.ddm.model import DDMConfig, DDMModel, make_base
from mi_displace.render.scene import load

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "ddm_genus1.xml"
GENUS1 = str(ROOT / "scenes" / "parts" / "ddm_genus1" / "genus1.obj")
#: the camera of scenes/parts/ddm_genus1/camera_lights.xml, read by hand (an independent
#: pinhole model, not Mitsuba's sensor)
ORIGIN, TARGET, UP, FOV_X = np.array([3.4, -3.2, 3.0]), np.array([0, 0, -0.1]), np.array([0, 0, 1.0]), 38.0


def _pixels(points, width):
    """Pixel coordinates (x, y) of world points and whether they lie in the view."""
    fwd = (TARGET - ORIGIN) / np.linalg.norm(TARGET - ORIGIN)
    left = np.cross(UP, fwd)
    left /= np.linalg.norm(left)
    up = np.cross(fwd, left)
    d = points - ORIGIN
    z = d @ fwd
    t = np.tan(np.radians(FOV_X) / 2)
    x, y = (d @ left) / (z * t), (d @ up) / (z * t)
    return np.stack([x, y], 1) * width / 2, (z > 0) & (np.abs(x) <= 1) & (np.abs(y) <= 1)


def _largest_texel_step(model, r, width):
    """Largest screen distance (pixels) between neighbouring texels of the per-chart maps at
    r, over texel pairs that both lie on the chart and in the view (finite differences)."""
    maps = model.maps_at(r)
    g = maps.grid
    p = np.stack([np.asarray(c) for c in maps.position], 1)
    px, seen = _pixels(p, width)
    ok = maps.valid & seen
    worst = 0.0
    for c in range(len(g.offset)):
        w, h = int(g.width[c]), int(g.height[c])
        sl = slice(int(g.offset[c]), int(g.offset[c]) + w * h)
        q, k = px[sl].reshape(h, w, 2), ok[sl].reshape(h, w)
        for a, b, both in ((q[:, 1:], q[:, :-1], k[:, 1:] & k[:, :-1]),
                           (q[1:], q[:-1], k[1:] & k[:-1])):
            if both.any():
                worst = max(worst, float(np.linalg.norm(a - b, axis=-1)[both].max()))
    return worst


def test_auto_follows_the_screen_footprint_on_a_multi_chart_mesh(variant):
    stats = {}
    for res in (32, 64):
        _, timings = load(SCENE, mode="approximation", integrator="raster", res=res,
                          map_resolution="auto")
        st = next(s for s in timings["shapes"] if s["type"] == "DDM")
        assert st["map_resolution_rule"].startswith("auto: screen footprint")
        stats[res] = st
    r32, r64 = stats[32]["map_resolution"], stats[64]["map_resolution"]
    assert r64 == 2 * r32                    # twice the pixels, twice the texels
    # independent check: at R no texel step on screen exceeds ~1 px, at R / 2 some do
    model = DDMModel(DDMConfig(base="mesh", filename=GENUS1, tile="chain", tiles_u=40,
                               tiles_v=40, height=0.05, mode="exact"))
    assert _largest_texel_step(model, r64, 64) <= 1.15
    assert _largest_texel_step(model, r64 // 2, 64) > 1.0
    for key in ("tiles_placed", "tiles_pruned", "tiles_dropped", "tiles_straddling", "bytes",
                "maps_bytes", "build_s", "map_s", "footprint_px_per_uv"):
        assert key in stats[64], key


def test_auto_coarsest_off_screen_and_bad_sensors(variant):
    base = make_base("mesh", GENUS1)
    from mi_displace.ddm import footprint

    away = mi.load_dict({"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
        origin=[0, 0, 5], target=[0, 0, 10], up=[0, 1, 0])})
    r, info = footprint.resolution(base, [away], mi.ScalarTransform4f())
    assert r == footprint.AUTO_MIN_RESOLUTION and info["footprint_visible"] == 0
    ortho = mi.load_dict({"type": "orthographic", "to_world": mi.ScalarTransform4f().look_at(
        origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]).scale([2.0, 2.0, 1.0]),
        "film": {"type": "hdrfilm", "width": 16, "height": 16}})
    r2, _ = footprint.resolution(base, [ortho], mi.ScalarTransform4f())
    r4, _ = footprint.resolution(base, [ortho], mi.ScalarTransform4f().scale(2.0))
    assert r4 == 2 * r2 >= 16                # the base twice as large on screen
    with pytest.raises(ValueError, match="radiancemeter|RadianceMeter"):
        footprint.resolution(base, [mi.load_dict({"type": "radiancemeter", "film": {
            "type": "hdrfilm", "width": 1, "height": 1}})], mi.ScalarTransform4f())
    with pytest.raises(Exception, match="dicing_rate"):
        mi.load_dict({"type": "ddm", "dicing_rate": 0.0})
