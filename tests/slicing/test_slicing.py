"""Displacement by slicing (§3) against independent truth: analytic slice-plane
intersections, the true displacement (``displaced``), the paper's α semantics, grazing
see-through, extreme slice counts and bad input."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.evaluate.metrics import flip
from mi_displace.slicing import geometry as geo
from mi_displace.slicing.sliced import SlicedVolume


def uniform(value):
    return mi.load_dict({"type": "uniform", "value": float(value)})


def plane_volume(D, direction, alpha, n=8, scale=0.2):
    bm = geo.make_base_mesh("plane", {}, None, 1, np.eye(4))
    return SlicedVolume(bm, uniform(D), scale, n, direction, alpha)


def rays(count=400, seed=1):
    """Rays from above hitting the square's interior at 25-60 degrees from the normal."""
    rng = np.random.default_rng(seed)
    target = np.c_[rng.uniform(-0.6, 0.6, (count, 2)), np.zeros(count)]
    theta, phi = rng.uniform(np.radians(25), np.radians(60), count), rng.uniform(0, 2 * np.pi, count)
    d = -np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    o = target - 3 * d
    return o, d


def find(vol, o, d):
    O, Dv = mi.Point3f(*o.T.astype(np.float32)), mi.Vector3f(*d.T.astype(np.float32))
    choice = vol.choose(Dv, mi.Vector3f(0, 0, 1), mi.Vector3f(2, 0, 0), mi.Vector3f(0, 2, 0))
    hit = vol.find(O, Dv, choice, mi.Bool(True))
    return np.array(hit.found), np.array(hit.p).T


def test_aligned_hits_are_the_analytic_slice_plane(variant):
    # D = 0.55, 8 slices: the first slice from above that passes D >= k/8 is k = 4 (z = 0.1)
    vol = plane_volume(0.55, "a", "basic")
    o, d = rays()
    found, p = find(vol, o, d)
    t = (0.1 - o[:, 2]) / d[:, 2]
    expect = o + t[:, None] * d
    assert found.all()
    assert np.max(np.abs(p - expect)) < 1e-4


@pytest.mark.parametrize("direction", ["b", "c", "screen"])
def test_orthogonal_and_screen_hits_are_the_first_plane_inside(variant, direction):
    D, scale, n = 0.55, 0.2, 8
    vol = plane_volume(D, direction, "ramp", n, scale)
    o, d = rays()
    found, p = find(vol, o, d)
    if direction == "screen":    # planes p . d = k delta, anchored at the origin
        delta = scale / n
        od = np.einsum("ij,ij->i", o, d)
        k = np.arange(-2000, 2000)[None, :]
        t = k * delta - od[:, None]
    else:                        # planes x (b) or y (c) at the bin centres of [-1, 1]
        axis = 0 if direction == "b" else 1
        m = vol.counts[direction]
        levels = -1 + 2 * (np.arange(m) + 0.5) / m
        t = (levels[None, :] - o[:, axis:axis + 1]) / d[:, axis:axis + 1]
    pts = o[:, None, :] + t[..., None] * d[:, None, :]
    inside = (pts[..., 2] >= 0) & (pts[..., 2] < D * scale) & (np.abs(pts[..., 0]) <= 1) & \
        (np.abs(pts[..., 1]) <= 1) & (t > 0)
    t_first = np.where(inside, t, np.inf).min(1)
    expect = o + t_first[:, None] * d
    assert np.array_equal(found, np.isfinite(t_first))
    assert found.mean() > 0.9
    assert np.max(np.abs(p[found] - expect[found])) < 2e-4


def test_alpha_semantics_zero_heights(variant, helpers):
    """§3.2: the basic test draws zero heights (the base), the ramp test masks them out."""
    sensor = helpers.look([0, -2.5, 2.5], [0, 0, 0])
    zero = {"type": "uniform", "value": 0.0}
    basic, _ = helpers.render(helpers.plane(height=zero, direction="a", alpha="basic",
                                            draw_base=False), sensor)
    ramp, _ = helpers.render(helpers.plane(height=zero, direction="a", alpha="ramp",
                                           draw_base=False), sensor)
    ref, _ = helpers.render({"type": "rectangle", "bsdf": helpers.MATERIAL}, sensor)
    background = np.abs(ref - 0.1).max(-1) < 1e-5
    assert (~background).mean() > 0.2
    assert np.abs(basic - ref).max() < 2e-3                 # the flat base, drawn
    assert np.abs(ramp - 0.1).max() < 1e-6                  # nothing drawn: all pass-through


def test_all_one_heights_are_a_solid_shell(variant):
    for direction in ("a", "best", "screen"):
        vol = plane_volume(1.0, direction, "ramp", n=16)
        o, d = rays(200)
        found, p = find(vol, o, d)
        assert found.all(), direction
        # the top of the solid, within one slice spacing (a: the top slice at 15/16)
        assert np.all(np.abs(p[:, 2] - 0.2) <= 0.2 / 16 + 1e-4), direction


def test_converges_to_true_displacement(variant, helpers):
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=64)
    ref, _ = helpers.render(helpers.plane("displaced"), sensor)
    for direction in ("a", "best"):
        errors = [flip(ref, helpers.render(helpers.plane(slices=n, direction=direction), sensor)[0])[0]
                  for n in (3, 12, 48)]
        assert errors[2] < errors[1] < errors[0], (direction, errors)
        assert errors[2] < 0.6 * errors[0], (direction, errors)


def see_through(helpers, direction, n=16):
    """Fraction of the true surface's pixels that show the background, 89.5 degrees from
    the normal (orthographic: every ray at that angle)."""
    ang = math.radians(89.5)
    d = np.array([0.0, math.sin(ang), -math.cos(ang)])
    target = np.array([0.0, 0.0, 0.1])
    sensor = helpers.look((target - 6 * d).tolist(), target.tolist(), res=64, ortho_size=0.16)
    narrow = mi.ScalarTransform4f().scale([0.15, 1.0, 1.0])
    height = {"type": "bricks", "rows": 8, "columns": 1, "mortar": 0.2, "bevel": 0.01}
    ref, _ = helpers.render({**helpers.plane("displaced", height=height), "to_world": narrow}, sensor)
    img, _ = helpers.render({**helpers.plane(height=height, slices=n, direction=direction),
                             "to_world": narrow}, sensor)
    covered = np.abs(ref - 0.1).max(-1) > 1e-4
    hole = np.abs(img - 0.1).max(-1) < 1e-6
    return (covered & hole).sum() / covered.sum()


def test_grazing_see_through(variant, helpers):
    """Fig. 4: surface-aligned slices can be looked through at grazing angles; the best
    orthogonal direction and screen-space slices cannot."""
    assert see_through(helpers, "a") > 0.1
    assert see_through(helpers, "best") < 0.01
    assert see_through(helpers, "screen") < 0.01


def test_self_shadows_off_only_lights_the_shadowed_fragments(variant, helpers):
    """``self_shadows=false`` (the paper's OpenGL drawing: no walk towards the light) changes
    exactly the self-shadowed fragments, which with shadows are lit by the ambient term only
    (albedo x ambient radiance); everything else is bit-identical."""
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=32)
    on, _ = helpers.render(helpers.plane(slices=32, direction="a"), sensor)
    off, _ = helpers.render(helpers.plane(slices=32, direction="a", self_shadows=False), sensor)
    changed = np.abs(off - on).max(-1) > 0
    assert 5 <= changed.sum() < 0.5 * changed.size
    assert np.all(off[changed] > on[changed])
    ambient = 0.1 * np.array(helpers.MATERIAL["reflectance"]["value"])
    assert np.abs(on[changed] - ambient).max() < 1e-5


def test_one_and_4096_slices(variant, helpers):
    vol = plane_volume(0.7, "a", "basic", n=1)
    o, d = rays(100)
    found, p = find(vol, o, d)
    assert found.all() and np.abs(p[:, 2]).max() < 1e-4     # one slice: the base itself
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=32)
    ref, _ = helpers.render(helpers.plane("displaced"), sensor)
    coarse = flip(ref, helpers.render(helpers.plane(slices=16, direction="a"), sensor)[0])[0]
    fine = flip(ref, helpers.render(helpers.plane(slices=4096, direction="a"), sensor)[0])[0]
    assert fine < coarse


def test_camera_inside_the_volume(variant, helpers):
    sensor = helpers.look([0.05, -0.9, 0.1], [0.05, 1.0, 0.05], fov=60, res=48)
    ref, _ = helpers.render(helpers.plane("displaced"), sensor)
    for direction in ("a", "best", "screen"):
        img, _ = helpers.render(helpers.plane(slices=32, direction=direction), sensor)
        agree = (np.abs(ref - 0.1).max(-1) > 1e-4) == (np.abs(img - 0.1).max(-1) > 1e-4)
        assert agree.mean() > 0.9, direction


def test_path_agrees_with_raster(variant, helpers):
    """Both renderers see the same slices (Null pass-through under path)."""
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=32)
    shape = helpers.plane(slices=16, direction="best")
    raster, _ = helpers.render(shape, sensor, ambient=0.0)
    path, _ = helpers.render(shape, sensor, integrator="path", spp=256, ambient=0.0)
    assert abs(path.mean() / raster.mean() - 1) < 0.05
    assert flip(raster, path)[0] < 0.12


def test_mesh_base_equals_parametric_plane(variant, helpers, tmp_path):
    obj = tmp_path / "square.obj"
    # Mitsuba's OBJ loader flips v (uv.y = 1 - vt.y): these give the plane's uv = (x + 1) / 2
    obj.write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\n"
                   "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")
    sensor = helpers.look([0.3, -2.6, 2.2], [0, 0, 0], res=48)
    for direction in ("a", "best"):
        a, _ = helpers.render(helpers.plane(slices=12, direction=direction), sensor)
        mesh = {**helpers.plane(slices=12, direction=direction), "base": "mesh", "filename": str(obj)}
        b, _ = helpers.render(mesh, sensor)
        assert flip(a, b)[0] < 0.01, direction


def test_mesh_base_slices_close_over_uv_seams(variant, tmp_path):
    """A UV sphere OBJ with a seam column and per-side loader normals: every copy of a
    position extrudes by the same vector, so the top of the displacement volume (and every
    slice between) welds into a closed surface, as the base does."""
    from tests.plugins.test_displaced_seams import uv_sphere_obj, welded_edges

    bm = geo.make_base_mesh("mesh", {}, uv_sphere_obj(tmp_path / "s.obj"), None, np.eye(4))
    assert welded_edges(bm.positions, bm.faces) == (0, 0)
    top = bm.positions + 0.1 * bm.extrude
    assert np.all(np.isfinite(top))
    assert welded_edges(top, bm.faces) == (0, 0)


@pytest.mark.slow
def test_torus_is_finite_and_close_to_displaced(variant, helpers):
    sensor = helpers.look([0, -3.6, 2.4], [0, 0, 0], fov=35, res=48)
    height = {"type": "cells", "cells": 8, "radius": 0.45}
    base = {"base": "torus", "major_radius": 1.0, "minor_radius": 0.4, "height": height,
            "scale": 0.08, "bsdf": helpers.MATERIAL}
    ref, _ = helpers.render({"type": "displaced", **base, "resolution": 512}, sensor)
    img, scene = helpers.render({"type": "slicing", **base, "resolution": 24, "slices": 8,
                                 "direction": "best", "draw_base": True}, sensor)
    assert flip(ref, img)[0] < 0.2
    stats = scene.shapes()[0].build_stats
    assert stats["slices"] == 8 and stats["bytes"] > 0


def test_auto_slices_follow_the_sensor(variant):
    sensor = mi.load_dict({"type": "perspective", "fov": 30, "fov_axis": "x",
                           "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 400, "height": 400}})
    bbox = (np.array([-1.0, -1.0, -0.1]), np.array([1.0, 1.0, 0.1]))
    # nearest point of the box at distance 4.9: 0.1 world units span 400 * 0.1 / (2 * 4.9 tan 15)
    expect = 400 * 0.1 / (2 * 4.9 * math.tan(math.radians(15)))
    assert geo.projected_size(sensor, bbox, 0.1) == pytest.approx(expect, rel=2e-3)
    assert geo.auto_slices(sensor, bbox, 0.1) == math.ceil(geo.SLICES_PER_PIXEL * expect)
    assert expect / geo.auto_slices(sensor, bbox, 0.1) <= 0.5   # slices <= half a pixel apart
    scene = mi.load_dict({"type": "scene", "cam": sensor,
                          "obj": {"type": "slicing", "base": "plane", "scale": 0.1, "slices": "auto",
                                  "sensor": sensor, "height": {"type": "uniform", "value": 0.5}}})
    stats = scene.shapes()[0].build_stats
    assert stats["slices_auto"] and stats["slices"] == geo.auto_slices(
        sensor, geo.make_base_mesh("plane", {}, None, 1, np.eye(4)).bbox(0.1), 0.1)


def test_ratio_scaling_of_the_orthogonal_count(variant):
    """§3.4: edge 2, displacement 0.5 -> 4x the slices."""
    bm = geo.make_base_mesh("plane", {}, None, 1, np.eye(4))
    assert geo.orthogonal_counts(bm, 0.5, 10, True) == (40, 40)
    assert geo.orthogonal_counts(bm, 0.5, 10, False) == (10, 10)


@pytest.mark.parametrize("bad, message", [
    ({"slices": 0}, "slices"), ({"slices": 5000}, "slices"), ({"slices": "many"}, "slices"),
    ({"slices": 2.5}, "slices"), ({"direction": "diagonal"}, "direction"),
    ({"alpha": "soft"}, "alpha"), ({"scale": 0.0}, "scale"), ({"scale": float("nan")}, "scale"),
    ({"slices": "auto"}, "sensor"), ({"height": None}, "height"),
    ({"base": "mesh"}, "filename"), ({"base": "cone"}, "cone"),
])
def test_bad_input(variant, bad, message):
    d = {"type": "slicing", "base": "plane", "scale": 0.1, "height": {"type": "uniform", "value": 0.5}}
    d.update(bad)
    d = {k: v for k, v in d.items() if v is not None}
    with pytest.raises(Exception, match=message):
        mi.load_dict(d)


def test_colour_texture_is_extruded_with_the_slices(variant, helpers):
    """The nested material's textures are read at the slice fragment's uv (the RGB of the
    paper's RGBα displacement texture): a checkerboard matches true displacement."""
    colour = {"type": "diffuse", "reflectance": {
        "type": "checkerboard", "color0": {"type": "rgb", "value": [0.8, 0.2, 0.1]},
        "color1": {"type": "rgb", "value": [0.1, 0.3, 0.8]},
        "to_uv": mi.ScalarTransform4f().scale([4, 4, 1])}}
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=48)
    ref, _ = helpers.render({**helpers.plane("displaced"), "bsdf": colour}, sensor)
    img, _ = helpers.render({**helpers.plane(slices=32, direction="best"), "bsdf": colour}, sensor)
    plain, _ = helpers.render(helpers.plane(slices=32, direction="best"), sensor)
    assert flip(ref, img)[0] < 0.6 * flip(ref, plain)[0]
    assert flip(ref, img)[0] < 0.1


def test_traverse_edits_rebuild_the_slices(variant, helpers):
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=32)
    fresh, _ = helpers.render(helpers.plane(slices=24, scale=0.3, direction="best"), sensor)
    img, scene = helpers.render(helpers.plane(slices=6, scale=0.2, direction="best"), sensor)
    params = mi.traverse(scene)
    params["obj.slices"] = 24
    params["obj.scale"] = 0.3
    params.update()
    edited = np.array(mi.render(scene))[..., :3]
    assert scene.shapes()[0].build_stats["slices"] == 24
    assert np.abs(edited - fresh).max() < 1e-5
    assert np.abs(img - fresh).max() > 0.05
    params["obj.slices"] = 2.5
    with pytest.raises(Exception, match="integer"):
        params.update()


@pytest.mark.parametrize("visibility", ["raytrace", "zbuffer"])
def test_raster_sees_through_stacked_volumes(variant, helpers, visibility):
    """Five stacked slicing volumes that draw nothing (zero heights, ramp α-test) over a
    floor: a ray crosses ten volume walls, more than the old fixed limit of 8 layers.  Under
    `raster` (ambient light: walls cast no shadow) the floor is what the floor alone gives."""
    def floor_scene(count):
        shapes = {f"s{k}": {**helpers.plane(height={"type": "uniform", "value": 0.0}, alpha="ramp",
                                            slices=4, scale=0.05, direction="a", draw_base=False),
                            "to_world": mi.ScalarTransform4f().translate([0, 0, 0.2 * k])}
                  for k in range(count)}
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "raster", "visibility": visibility}, **shapes,
            "floor": {"type": "rectangle", "bsdf": helpers.MATERIAL,
                      "to_world": mi.ScalarTransform4f().translate([0, 0, -0.5]).scale(3)},
            "amb": {"type": "constant", "radiance": 1.0},
            "sensor": helpers.look([0.3, -0.5, 4], [0, 0, 0], res=48)})
    bare = np.array(mi.render(floor_scene(0)))
    img = np.array(mi.render(floor_scene(5)))
    assert np.all(np.isfinite(img))
    assert np.abs(img - bare).max() < 1e-4


@pytest.mark.parametrize("n", [1, 5])
def test_a_plane_base_is_boxed_by_twelve_wall_triangles(variant, n):
    # the unit-square base (two triangles): its displacement volume is a box, top and bottom
    # two triangles each and a quad on each of the four open edges; n aligned slices are n
    # copies of the base
    bm = geo.make_base_mesh("plane", {}, None, 1, np.eye(4))
    assert len(bm.faces) == 2 and len(geo.boundary_edges(bm)) == 4
    vol = SlicedVolume(bm, mi.load_dict({"type": "uniform", "value": 0.5}), 0.2, n, "a", "basic")
    assert vol.stats["wall_triangles"] == 12 and vol.walls_scene.triangles == 12
    assert vol.stats["slice_triangles"] == 2 * n and vol.stats["base_faces"] == 2
    walls = geo.volume_walls(bm, 0.2)
    z = walls.positions[:, 2]
    assert z.min() < 0 < 0.2 < z.max() < 0.2 * 1.01     # -eps below, 1 + eps above (h x scale)


@pytest.mark.parametrize("name,params", [("plane", {}), ("sphere", {"radius": 0.8}),
                                         ("cylinder", {"radius": 0.5, "length": 1.5}),
                                         ("torus", {"major_radius": 1.0, "minor_radius": 0.3})])
def test_base_coordinates_invert_the_parametrisation(variant, name, params):
    # p = S(u, v) + h n(u, v): base_coordinates gives back (u, v, h), inside the domain;
    # beyond a bounded domain's edge it says so
    from mi_displace.core import surfaces

    base = surfaces.make_base(name, **params)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0.05, 0.95, 500), rng.uniform(0.05, 0.95, 500)
    h = rng.uniform(-0.1, 0.1, 500)
    s = base.sample(mi.Float(u), mi.Float(v))
    p = s.p + dr.normalize(s.n) * mi.Float(h)
    bu, bv, bh, ok = geo.base_coordinates(base, mi.Point3f(p))
    assert np.array(ok).all()
    for got, want in ((bu, u), (bv, v), (bh, h)):
        np.testing.assert_allclose(np.array(got), want, atol=2e-5)
    if name in ("plane", "cylinder"):
        out = base.sample(mi.Float([0.5, 0.5]), mi.Float([1.4, -0.4])).p   # v beyond [0, 1]
        assert not np.array(geo.base_coordinates(base, mi.Point3f(out))[3]).any()
    if name == "plane":
        out = base.sample(mi.Float([1.3, -0.3]), mi.Float([0.5, 0.5])).p   # u beyond [0, 1]
        assert not np.array(geo.base_coordinates(base, mi.Point3f(out))[3]).any()


def test_base_tangents_are_dS_du_and_dS_dv(variant):
    # the plane base S(u, v) = (2u - 1, 2v - 1, 0), placed by diag(2, 3, 1): dS/du = (4, 0, 0)
    # and dS/dv = (0, 6, 0) at every vertex (the per-face values are exact on an affine map)
    bm = geo.make_base_mesh("plane", {}, None, 4, np.diag([2.0, 3.0, 1.0, 1.0]))
    assert len(bm.positions) > 9
    assert np.allclose(bm.su, [4, 0, 0], atol=1e-9) and np.allclose(bm.sv, [0, 6, 0], atol=1e-9)
    assert np.allclose(bm.normals, [0, 0, 1])


def test_projected_size_through_a_thin_lens_is_the_pinhole_one(variant):
    # a thin-lens camera focused on the object projects a point like the pinhole at the lens
    # centre: 0.1 world units at distance 3, 64 pixels over 40 degrees: 0.1 / (2 * 3 tan 20) * 64
    to_world = mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0])
    film = {"type": "hdrfilm", "width": 64, "height": 64}
    bbox = (np.array([-0.1, -0.1, -0.1]), np.array([0.1, 0.1, 0.1]))
    want = 0.1 / (2 * 2.9 * np.tan(np.radians(20))) * 64          # the box's nearest point: z = 0.1
    for extra in ({"type": "perspective"}, {"type": "thinlens", "aperture_radius": 0.2, "focus_distance": 2.9}):
        cam = mi.load_dict({**extra, "fov": 40, "film": film, "to_world": to_world})
        assert geo.projected_size(cam, bbox, 0.1) == pytest.approx(want, rel=1e-3), extra["type"]
