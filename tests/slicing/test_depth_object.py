"""Image-based depth objects (§4) and visual hulls (§5) against analytic shapes."""
import json

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.evaluate.metrics import flip
from mi_displace.slicing import assets
from mi_displace.slicing import depth_object as dobj

S0, R = np.array([0.1, -0.05, 0.02]), 0.6
SPHERE = {"type": "sphere", "radius": R, "center": S0.tolist(),
          "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.3]}}}


@pytest.fixture
def sphere_images(variant, built_once):
    """SPHERE captured at 96 x 96 in the cube [-1, 1]^3, once per run (read only)."""
    return built_once("sphere_images", lambda: dobj.capture(SPHERE, 96, center=[0, 0, 0], half=1.0))


def test_capture_is_the_analytic_sphere_depth(sphere_images):
    im = sphere_images
    res, a = im.resolution, im.half
    xs = -a + (np.arange(res) + 0.5) * 2 * a / res
    for face, (axis, sign) in enumerate(dobj.FACES):
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        c1, c2 = np.meshgrid(xs, xs)     # columns along a1, rows along a2
        q = R ** 2 - (c1 - S0[a1]) ** 2 - (c2 - S0[a2]) ** 2
        near = S0[axis] + sign * np.sqrt(np.maximum(q, 0))
        expect = np.where(q > 0, a - sign * near, np.inf)
        rim = np.abs(q) < 0.03               # pixel centres too close to the silhouette
        hit = np.isfinite(im.depth[face])
        assert np.array_equal(hit[~rim], np.isfinite(expect)[~rim]), face
        both = hit & np.isfinite(expect)
        assert np.max(np.abs(im.depth[face][both] - expect[both])) < 1e-4, face
        n = im.normal[face][both]
        assert np.max(np.abs(np.linalg.norm(n, axis=1) - 1)) < 1e-3


def ray_batch(count=300, seed=3):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # impact points over a disc across the sphere, seen from 4 units away
    u = np.cross(d, [0.3, 0.5, 0.8])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    r = 1.2 * R * np.sqrt(rng.uniform(0, 1, count))
    ang = rng.uniform(0, 2 * np.pi, count)
    o = S0 + (r * np.cos(ang))[:, None] * u + (r * np.sin(ang))[:, None] * v - 4 * d
    return o, d, r


def run_find(obj, o, d):
    O = mi.Point3f(*[mi.Float(o[:, k].astype(np.float32)) for k in range(3)])
    D = mi.Vector3f(*[mi.Float(d[:, k].astype(np.float32)) for k in range(3)])
    found, p = obj.find(O, D, mi.Bool(True))
    return np.array(found), np.array(p).T


def test_depth_object_of_a_sphere_is_the_sphere(sphere_images):
    obj = dobj.DepthObject(sphere_images, 200)
    o, d, r = ray_batch()
    found, p = run_find(obj, o, d)
    clear_in, clear_out = r < 0.9 * R, r > 1.1 * R
    assert found[clear_in].all() and not found[clear_out].any()
    dist = np.linalg.norm(p[found] - S0, axis=1)
    tol = 2 * obj.delta + 2 * 2 * sphere_images.half / sphere_images.resolution
    assert np.all(dist <= R + 1e-3) and np.all(dist > R - tol)


def test_visual_hull_of_a_box_is_the_box(variant):
    half = np.array([0.5, 0.3, 0.4])
    box = {"type": "cube", "to_world": mi.ScalarTransform4f().scale(half.tolist())}
    images = dobj.capture(box, 64, center=[0, 0, 0], half=0.6)
    hull = dobj.DepthObject(images, 120, hull=True)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.6, 0.6, (4000, 3))
    inside = np.array(hull.inside(mi.Point3f(*[mi.Float(pts[:, k].astype(np.float32)) for k in range(3)])))
    margin = np.min(np.abs(np.abs(pts) - half), axis=1) > 2 * 1.2 / 64
    truth = np.all(np.abs(pts) < half, axis=1)
    assert np.array_equal(inside[margin], truth[margin])


def test_visual_hull_of_a_sphere_is_three_cylinders(sphere_images):
    hull = dobj.DepthObject(sphere_images, 100, hull=True)
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1, 1, (5000, 3))
    q = pts - S0
    radii = np.stack([np.hypot(q[:, 1], q[:, 2]), np.hypot(q[:, 0], q[:, 2]), np.hypot(q[:, 0], q[:, 1])], 1)
    truth = np.all(radii < R, axis=1)
    margin = np.min(np.abs(radii - R), axis=1) > 2 * 2 / 96
    inside = np.array(hull.inside(mi.Point3f(*[mi.Float(pts[:, k].astype(np.float32)) for k in range(3)])))
    assert np.array_equal(inside[margin], truth[margin])
    # the hull contains the sphere and more (the depth object does not)
    depth = np.array(dobj.DepthObject(sphere_images, 100).inside(
        mi.Point3f(*[mi.Float(pts[:, k].astype(np.float32)) for k in range(3)])))
    sphere = np.linalg.norm(q, axis=1) < R
    clear = np.abs(np.linalg.norm(q, axis=1) - R) > 0.05
    assert np.array_equal(depth[clear], sphere[clear])
    # volumes: tricylinder 8 (2 - sqrt 2) r^3 vs sphere 4/3 pi r^3 (ratio 1.1213)
    assert inside.sum() / depth.sum() == pytest.approx(8 * (2 - np.sqrt(2)) / (4 / 3 * np.pi), abs=0.06)


def test_depth_object_hollows_the_cup_the_hull_does_not(variant, tmp_path):
    path = tmp_path / "cup.ply"
    assets.cup_mesh().export(path)
    images = dobj.capture({"type": "ply", "filename": str(path)}, 96)
    o = np.array([[0.02, 0.01, 3.0]])
    d = np.array([[0.0, 0.0, -1.0]])
    for hull, z in ((False, 0.06), (True, 0.8)):   # the inner floor vs the rim's plane
        found, p = run_find(dobj.DepthObject(images, 200, hull=hull), o, d)
        assert found[0] and abs(p[0, 2] - z) < 0.02, (hull, p)


def test_alpha_of_background_and_depth_outside_the_cube():
    depth = np.full((6, 2, 2), np.inf, np.float32)
    depth[:, 0, 0], depth[:, 0, 1], depth[:, 1, 0] = -0.3, 2.5, 0.5     # cube half 1
    im = dobj.DepthImages(np.zeros(3), 1.0, depth, np.zeros((6, 2, 2, 3), np.float32))
    alpha = im.alpha()
    assert np.all(alpha[:, 0, 0] == 1) and np.all(alpha[:, 0, 1] == 0)
    assert np.allclose(alpha[:, 1, 0], 0.75) and np.all(alpha[:, 1, 1] == 0)
    assert np.array_equal(im.alpha(hull=True)[:, 1, 1], np.zeros(6))


def test_files_round_trip_and_bad_files(sphere_images, tmp_path):
    path = dobj.write(sphere_images, tmp_path / "sphere")
    back = dobj.read(path)
    assert np.array_equal(np.isinf(back.depth), np.isinf(sphere_images.depth))
    hit = np.isfinite(back.depth)
    assert np.array_equal(back.depth[hit], sphere_images.depth[hit])
    assert np.max(np.abs(back.color - sphere_images.color)) < 0.02     # 8-bit sRGB PNG
    # inconsistent sizes: one colour image smaller than its depth image
    from mi_displace.core.io import write_png
    write_png(tmp_path / "sphere" / "color_pz.png", np.zeros((50, 50, 3), np.float32))
    with pytest.raises(ValueError, match="same size"):
        dobj.read(path)
    meta = json.loads(path.read_text())
    meta["faces"]["pz"]["color"] = "missing.png"
    path.write_text(json.dumps(meta))
    with pytest.raises(FileNotFoundError, match="missing.png"):
        dobj.read(path)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        dobj.read(tmp_path / "nowhere.json")


@pytest.mark.parametrize("value", [np.nan, -np.inf])
def test_non_finite_depth_is_refused(value):
    depth = np.ones((6, 4, 4), np.float32)
    depth[2, 1, 1] = value
    with pytest.raises(ValueError, match="NaN or -inf"):
        dobj.DepthImages(np.zeros(3), 1.0, depth, np.zeros((6, 4, 4, 3), np.float32)).check()


def test_inconsistent_image_sizes_are_refused():
    with pytest.raises(ValueError, match="same size"):
        dobj.DepthImages(np.zeros(3), 1.0, np.ones((6, 4, 4), np.float32),
                         np.zeros((6, 5, 5, 3), np.float32)).check()
    with pytest.raises(ValueError, match="six square"):
        dobj.DepthImages(np.zeros(3), 1.0, np.ones((5, 4, 4), np.float32),
                         np.zeros((5, 4, 4, 3), np.float32)).check()


def test_plugin_renders_the_sphere(sphere_images, tmp_path, helpers):
    path = dobj.write(sphere_images, tmp_path / "sphere")
    sensor = helpers.look([1.4, -2.8, 1.6], [0, 0, 0], fov=35, res=40)
    ref, _ = helpers.render(SPHERE, sensor)
    img, scene = helpers.render({"type": "depth_object", "filename": str(path), "slices": 120}, sensor)
    assert flip(ref, img)[0] < 0.08
    assert scene.shapes()[0].build_stats["slices"] == 120


@pytest.mark.slow
def test_plugin_hull_and_nested_source(sphere_images, tmp_path, helpers):
    path = dobj.write(sphere_images, tmp_path / "sphere")
    sensor = helpers.look([1.4, -2.8, 1.6], [0, 0, 0], fov=35, res=48)
    ref, _ = helpers.render(SPHERE, sensor)
    hull, _ = helpers.render({"type": "visual_hull", "filename": str(path), "slices": 120}, sensor)
    depth, _ = helpers.render({"type": "depth_object", "source": SPHERE, "resolution": 64,
                               "slices": 80}, sensor)   # nested source captured at load
    assert flip(ref, depth)[0] < 0.1 < flip(ref, hull)[0]


def test_plugin_bad_input(variant, tmp_path):
    with pytest.raises(Exception, match="filename"):
        mi.load_dict({"type": "depth_object"})
    with pytest.raises(Exception, match="does not exist"):
        mi.load_dict({"type": "depth_object", "filename": str(tmp_path / "none.json")})
    with pytest.raises(Exception, match="slices"):
        mi.load_dict({"type": "depth_object", "source": SPHERE, "slices": 0})


@pytest.mark.parametrize("hull", [False, True])
def test_empty_space_skipping_changes_nothing(sphere_images, hull):
    """The occupancy grid is conservative (every point the §4.1 test finds inside lies in
    an occupied cell) and skipping finds the same points as testing every plane."""
    obj = dobj.DepthObject(sphere_images, 150, hull=hull)
    rng = np.random.default_rng(5)
    q = rng.uniform(-1, 1, (20000, 3))
    inside = np.array(obj.inside(mi.Point3f(*[mi.Float(q[:, k].astype(np.float32)) for k in range(3)])))
    cell = np.clip(np.floor((q + 1) / 2 * dobj.GRID).astype(int), 0, dobj.GRID - 1)
    occ = np.array(obj.occupancy).reshape((dobj.GRID,) * 3)
    assert inside.sum() > 1000 and occ[tuple(cell[inside].T)].all()
    assert occ.mean() < 0.5                      # and it does skip: most cells are empty
    o, d, _ = ray_batch(600, seed=9)
    found, p = run_find(obj, o, d)
    obj.skip_empty = False                       # test every plane
    found_all, p_all = run_find(obj, o, d)
    assert found.sum() > 100 and np.array_equal(found, found_all)
    assert np.array_equal(p[found], p_all[found])


def _sphere_images():
    """The sphere of ``sphere_images`` captured at 32 x 32."""
    return dobj.capture(SPHERE, 32, center=[0, 0, 0], half=1.0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_skip_leaves_an_empty_cell_a_hair_before_its_far_face(variant, sign):
    # DepthObject.skip: from a point in an empty grid cell (the cube's corner, far from the
    # sphere), skip(t) is where the ray leaves that cell, a hair short of it
    obj = dobj.DepthObject(_sphere_images(), 40)
    size = 2.0 / dobj.GRID
    o = np.float32([-0.97, -0.97, -0.97]) * -sign          # inside corner cell (0, 0, 0) or the last
    d = np.float32([1.0, 0.3, 0.2]) * sign
    d /= np.linalg.norm(d)
    cell = np.floor((o + 1) / size)
    assert not np.array(obj.occupancy).reshape((dobj.GRID,) * 3)[tuple(cell.astype(int))]
    skip = obj.skip(mi.Point3f(*map(float, o)), mi.Vector3f(*map(float, d)))
    t = float(np.array(skip(mi.Float(0.0)))[0])
    assert t > 0
    assert np.array_equal(np.floor((o + t * d + 1) / size), cell)                  # still inside
    assert not np.array_equal(np.floor((o + (t + 2e-4 * size) * d + 1) / size), cell)  # then out


def test_images_of_different_sizes_are_named_in_the_message(variant, tmp_path):
    from mi_displace.core.io import write_exr, write_png

    path = dobj.write(_sphere_images(), tmp_path / "s")
    write_exr(tmp_path / "s" / "depth_pz.exr", np.ones((16, 16, 3), np.float32))
    write_png(tmp_path / "s" / "color_pz.png", np.zeros((16, 16, 3), np.float32))
    with pytest.raises(ValueError) as e:
        dobj.read(path)
    sizes = ", ".join(f"{n}: {16 if n == 'pz' else 32}x{16 if n == 'pz' else 32}" for n in dobj.FACE_NAMES)
    assert str(e.value) == f"depth object: the six images of {str(path)!r} differ in size ({sizes})"


def test_default_cube_holds_the_object_with_its_margin(variant, tmp_path):
    # capture(): without center/half the cube is the bounding box, `margin` x larger: a
    # sphere of radius 0.3 at c gets half = 0.306 and its nearest point lies 0.006 deep
    c = np.array([0.2, -0.1, 0.4])
    img = dobj.capture({"type": "sphere", "radius": 0.3, "center": c.tolist()}, 48)
    assert np.allclose(img.center, c, atol=1e-5) and img.half == pytest.approx(0.306, rel=1e-4)
    hit = np.isfinite(img.depth)
    assert img.depth[hit].min() == pytest.approx(0.006, abs=2e-3) and img.depth[hit].min() > 0
    # alpha: 1 at the nearest point, 0 where nothing was hit (whatever the cube size)
    a = img.alpha()
    assert a[~hit].max() == 0 and a[hit].max() == pytest.approx(1 - 0.006 / 0.612, abs=3e-3)
    big = dobj.capture({"type": "sphere", "radius": 0.3, "center": c.tolist()}, 16, center=c, half=2.0)
    assert big.alpha()[~np.isfinite(big.depth)].max() == 0 and big.alpha().max() > 0.5
    meta = json.loads(dobj.write(img, tmp_path / "s").read_text())
    assert meta["resolution"] == 48 and meta["half_size"] == img.half


def test_without_normal_images_the_best_facing_cube_face_is_the_normal(variant):
    img = _sphere_images()
    img = dobj.DepthImages(img.center, img.half, img.depth, img.color, None)
    obj = dobj.DepthObject(img, 20)
    d = np.float32([[0.2, 0.3, -0.9], [0.9, 0.3, 0.2], [0.3, -0.9, 0.2], [0.5, 0.2, 0.9], [-0.2, 0.6, 0.5]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = obj.normal(mi.Point3f(0.0, 0.0, 0.0), mi.Vector3f(*(mi.Float(d[:, k]) for k in range(3))))
    got = np.stack([np.array(c) for c in n], 1)
    k = np.abs(d).argmax(1)
    want = np.zeros_like(d)
    want[np.arange(len(d)), k] = -np.sign(d[np.arange(len(d)), k])
    assert np.array_equal(got, want)
