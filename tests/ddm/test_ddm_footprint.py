"""map_resolution="auto" from the base's screen footprint (issue 13), on a mesh base whose
lookups straddle UV charts, and build_stats."""
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest
from ddm_helpers import spherical_cap, to_numpy as _np

from mi_displace.ddm import base_maps, footprint
from mi_displace.ddm.model import DDMConfig, DDMModel, make_base
from mi_displace import fit_to_sensors
from mi_displace.render.scene import load, shape_stats

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
    scene, timings = load(SCENE, mode="approximation", integrator="raster", res=32,
                          map_resolution="auto")
    stats = {32: next(s for s in timings["shapes"] if s["type"] == "DDM")}
    # the film doubled, then the scene fitted again (what a user does after a resize)
    sensor = mi.traverse(scene.sensors()[0])
    sensor["film.size"] = mi.ScalarVector2u(64, 64)
    sensor.update()
    fit_to_sensors(scene)
    stats[64] = next(s for s in shape_stats(scene) if s["type"] == "DDM")
    for st in stats.values():
        assert st["map_resolution_rule"].startswith("auto: screen footprint")
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


def test_pixels_per_uv_is_the_projected_step_of_a_pinhole(variant):
    """A perspective sensor at the origin looking along +z (camera space = world space):
    pixels per unit u / v = |d(pixel)/du| of the pinhole x / z, y / z scaled by
    width / (2 tan(fov / 2)), against central differences of that projection."""
    width, height, fov = 64, 48, 40.0
    sensor = mi.load_dict({"type": "perspective", "fov": fov, "fov_axis": "x",
                           "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0],
                                                                      target=[0, 0, 1], up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": width, "height": height}})
    rng = np.random.default_rng(3)
    p = np.stack([rng.uniform(-0.3, 0.3, 50), rng.uniform(-0.2, 0.2, 50), rng.uniform(1, 3, 50)], 1)
    du, dv = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    px, visible = footprint.pixels_per_uv(sensor, p, du, dv)
    scale = width / (2 * np.tan(np.radians(fov) / 2))

    def pixel(x):
        return x[:, :2] / x[:, 2:] * scale

    h = 1e-5
    fd = [np.linalg.norm(pixel(p + h * d) - pixel(p - h * d), axis=1) / (2 * h) for d in (du, dv)]
    assert visible.all()
    assert np.allclose(px, np.maximum(*fd), rtol=1e-5)


def test_orthographic_visibility_needs_front_and_frustum(variant):
    """An orthographic sensor (camera space [-1, 1] across the film width, MARGIN 1.1): a
    point is seen when it is in front of the near plane *and* inside the frame."""
    sensor = mi.load_dict({"type": "orthographic",
                           "film": {"type": "hdrfilm", "width": 40, "height": 20}})
    p = np.array([[0.5, 0.2, 2.0],      # seen
                  [0.5, 0.2, -2.0],     # behind the sensor
                  [1.5, 0.2, 2.0],      # beyond the frame along x
                  [0.5, 0.6, 2.0]])     # beyond it along y (0.55 = 1.1 x 20 / 40)
    d = np.tile([[1.0, 0.0, 0.0]], (4, 1))
    px, visible = footprint.pixels_per_uv(sensor, p, d, 2 * d)
    assert visible.tolist() == [True, False, False, False]
    assert np.allclose(px, 40 / 2 * 2)


def test_auto_resolution_on_the_plane(variant):
    """Found by a mutant's test: base_sample_diagonal stacked the plane's constant z (a
    width-1 array) with n^2-wide x, y, so map_resolution="auto" failed on the plane.  The
    plane [-1, 1]^2 has diagonal 2 sqrt 2, and its bilinear maps are exact: the coarsest R allowed (choose_resolution halved down to
    R = 2, which check_resolution refuses: the plane failed there too)."""
    import warnings

    from mi_displace.ddm.model import DDMConfig, DDMModel

    assert base_maps.base_sample_diagonal(make_base("plane")) == pytest.approx(2 * np.sqrt(2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="plane", tile="stone:1", tiles_u=4, tiles_v=4,
                               map_resolution="auto"))
    assert m.maps.ru == base_maps.MIN_MAP_RESOLUTION and m.resolution_rule.startswith("auto: tolerance")


def test_weighted_quantile_ends():
    """_weighted_quantile: the smallest x whose cumulative weight reaches q of the total;
    all the weight on the largest x gives it, and zero total weight gives the largest x."""
    x = np.array([3.0, 1.0, 2.0])
    assert footprint._weighted_quantile(x, np.array([1.0, 0.0, 0.0]), 0.99) == 3.0
    assert footprint._weighted_quantile(x, np.array([0.0, 1.0, 1.0]), 0.99) == 2.0
    assert footprint._weighted_quantile(x, np.array([0.0, 1.0, 1.0]), 0.4) == 1.0
    assert footprint._weighted_quantile(x, np.zeros(3), 0.99) == 3.0


def test_footprint_samples_of_mesh_and_analytic_bases(variant):
    """base_samples: a mesh base gives its face centroids with their UV areas as weights
    (Heron's formula here), an analytic base an n x n grid of equal weights with S and its
    derivatives at the grid points; the quantile ignores zero-weight samples below it."""
    from mi_displace.ddm.mesh_base import MeshBase

    pos, nrm, uvs, faces = spherical_cap(2.0)
    base = MeshBase(pos, nrm, uvs, faces)
    p, du, dv, w = footprint.base_samples(base)
    t = uvs[faces]
    a, b, c = (np.linalg.norm(t[:, i] - t[:, j], axis=1) for i, j in ((0, 1), (1, 2), (2, 0)))
    s = (a + b + c) / 2
    assert np.allclose(w, np.sqrt(np.maximum(s * (s - a) * (s - b) * (s - c), 0)), atol=1e-9)
    assert np.allclose(p, pos[faces].mean(1))
    sphere = make_base("sphere")
    p, du, dv, w = footprint.base_samples(sphere, 9)
    assert p.shape == du.shape == dv.shape == (81, 3) and np.array_equal(w, np.ones(81))
    u, v = base_maps.texel_coordinates(9, 9, False, False)
    ref = sphere.sample(u, v)
    assert np.allclose(p, _np(ref.p), atol=1e-6) and np.allclose(dv, _np(ref.dp_dv), atol=1e-5)
    assert np.allclose(np.linalg.norm(p, axis=1), 1, atol=1e-6)
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert footprint._weighted_quantile(x, np.array([0.0, 0.0, 1.0, 1.0]), 0.4) == 3.0


def test_perspective_visibility_needs_front_and_both_frame_axes(variant):
    """Perspective (64 x 48, x_fov 40 degrees, MARGIN 1.1): seen when in front of the near
    plane and |x / z| <= 1.1 t and |y / z| <= 1.1 t (48 / 64), t = tan(20 degrees)."""
    sensor = mi.load_dict({"type": "perspective", "fov": 40.0, "fov_axis": "x",
                           "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0],
                                                                      target=[0, 0, 1], up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 64, "height": 48}})
    t = np.tan(np.radians(20.0))
    p = np.array([[0.1, 0.1, 1.0],                      # seen
                  [0.1, 0.1, -1.0],                     # behind
                  [1.2 * t, 0.0, 1.0],                  # beyond the frame along x
                  [0.0, 0.9 * t, 1.0],                  # beyond it along y (> 1.1 t 0.75)
                  [0.0, 0.8 * t, 1.0]])                 # inside (< 0.825 t)
    d = np.tile([[1.0, 0.0, 0.0]], (5, 1))
    _, visible = footprint.pixels_per_uv(sensor, p, d, d)
    assert visible.tolist() == [True, False, False, False, True]
