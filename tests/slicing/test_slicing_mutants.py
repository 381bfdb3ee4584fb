"""Tests written for mutants of slicing/ that survived the suite (issue 19; docs/testing.md,
"Bake, volume and slicing modules").  Each asserts numbers against an independent truth."""
import numpy as np
import pytest


@pytest.mark.parametrize("n", [1, 5])
def test_a_plane_base_is_boxed_by_twelve_wall_triangles(variant, n):
    # the unit-square base (two triangles): its displacement volume is a box, top and bottom
    # two triangles each and a quad on each of the four open edges; n aligned slices are n
    # copies of the base
    import mitsuba as mi

    from mi_displace.slicing import geometry as geo
    from mi_displace.slicing.sliced import SlicedVolume

    bm = geo.make_base_mesh("plane", {}, None, 1, np.eye(4))
    assert len(bm.faces) == 2 and len(geo.boundary_edges(bm)) == 4
    vol = SlicedVolume(bm, mi.load_dict({"type": "uniform", "value": 0.5}), 0.2, n, "a", "basic")
    assert vol.stats["wall_triangles"] == 12 and vol.walls_scene.triangles == 12
    assert vol.stats["slice_triangles"] == 2 * n and vol.stats["base_faces"] == 2
    walls = geo.volume_walls(bm, 0.2)
    z = walls.positions[:, 2]
    assert z.min() < 0 < 0.2 < z.max() < 0.2 * 1.01     # -eps below, 1 + eps above (h x scale)


def _sphere_images():
    from mi_displace.slicing import depth_object as dobj

    sphere = {"type": "sphere", "radius": 0.6, "center": [0.1, -0.05, 0.02]}
    return dobj.capture(sphere, 32, center=[0, 0, 0], half=1.0)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_skip_leaves_an_empty_cell_a_hair_before_its_far_face(variant, sign):
    # DepthObject.skip: from a point in an empty grid cell (the cube's corner, far from the
    # sphere), skip(t) is where the ray leaves that cell, a hair short of it
    import mitsuba as mi

    from mi_displace.slicing import depth_object as dobj

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
    from mi_displace.slicing import depth_object as dobj

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
    from mi_displace.slicing import depth_object as dobj

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
    meta = __import__("json").loads(dobj.write(img, tmp_path / "s").read_text())
    assert meta["resolution"] == 48 and meta["half_size"] == img.half


def test_without_normal_images_the_best_facing_cube_face_is_the_normal(variant):
    import mitsuba as mi

    from mi_displace.slicing import depth_object as dobj

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


@pytest.mark.parametrize("name,params", [("plane", {}), ("sphere", {"radius": 0.8}),
                                         ("cylinder", {"radius": 0.5, "length": 1.5}),
                                         ("torus", {"major_radius": 1.0, "minor_radius": 0.3})])
def test_base_coordinates_invert_the_parametrisation(variant, name, params):
    # p = S(u, v) + h n(u, v): base_coordinates gives back (u, v, h), inside the domain;
    # beyond a bounded domain's edge it says so
    import drjit as dr
    import mitsuba as mi

    from mi_displace.core import surfaces
    from mi_displace.slicing.geometry import base_coordinates

    base = surfaces.make_base(name, **params)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0.05, 0.95, 500), rng.uniform(0.05, 0.95, 500)
    h = rng.uniform(-0.1, 0.1, 500)
    s = base.sample(mi.Float(u), mi.Float(v))
    p = s.p + dr.normalize(s.n) * mi.Float(h)
    bu, bv, bh, ok = base_coordinates(base, mi.Point3f(p))
    assert np.array(ok).all()
    for got, want in ((bu, u), (bv, v), (bh, h)):
        np.testing.assert_allclose(np.array(got), want, atol=2e-5)
    if name in ("plane", "cylinder"):
        out = base.sample(mi.Float([0.5, 0.5]), mi.Float([1.4, -0.4])).p   # v beyond [0, 1]
        assert not np.array(base_coordinates(base, mi.Point3f(out))[3]).any()
    if name == "plane":
        out = base.sample(mi.Float([1.3, -0.3]), mi.Float([0.5, 0.5])).p   # u beyond [0, 1]
        assert not np.array(base_coordinates(base, mi.Point3f(out))[3]).any()


def test_base_tangents_are_dS_du_and_dS_dv(variant):
    # the plane base S(u, v) = (2u - 1, 2v - 1, 0), placed by diag(2, 3, 1): dS/du = (4, 0, 0)
    # and dS/dv = (0, 6, 0) at every vertex (the per-face values are exact on an affine map)
    from mi_displace.slicing import geometry as geo

    bm = geo.make_base_mesh("plane", {}, None, 4, np.diag([2.0, 3.0, 1.0, 1.0]))
    assert len(bm.positions) > 9
    assert np.allclose(bm.su, [4, 0, 0], atol=1e-9) and np.allclose(bm.sv, [0, 6, 0], atol=1e-9)
    assert np.allclose(bm.normals, [0, 0, 1])


def test_projected_size_through_a_thin_lens_is_the_pinhole_one(variant):
    # a thin-lens camera focused on the object projects a point like the pinhole at the lens
    # centre: 0.1 world units at distance 3, 64 pixels over 40 degrees: 0.1 / (2 * 3 tan 20) * 64
    import mitsuba as mi

    from mi_displace.slicing.geometry import projected_size

    to_world = mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0])
    film = {"type": "hdrfilm", "width": 64, "height": 64}
    bbox = (np.array([-0.1, -0.1, -0.1]), np.array([0.1, 0.1, 0.1]))
    want = 0.1 / (2 * 2.9 * np.tan(np.radians(20))) * 64          # the box's nearest point: z = 0.1
    for extra in ({"type": "perspective"}, {"type": "thinlens", "aperture_radius": 0.2, "focus_distance": 2.9}):
        cam = mi.load_dict({**extra, "fov": 40, "film": film, "to_world": to_world})
        assert projected_size(cam, bbox, 0.1) == pytest.approx(want, rel=1e-3), extra["type"]
