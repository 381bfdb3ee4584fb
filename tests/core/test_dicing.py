"""Screen-adaptive dicing (issue 13): crack-free stitching of patches with different edge
rates, watertight closed bases, Cycles' rate through the sensor, extremes and bad input."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import trimesh

from mi_displace.core import dicing, surfaces


CYCLES_FACES = 821_760   # Cycles, 5,120-triangle sphere, 256^2, 50 mm, rate 1 px (issue 13)


def random_edges(base, nu, nv, rng):
    edges = {"h": rng.integers(1, 9, (nv + 1, nu)), "v": rng.integers(1, 9, (nv, nu + 1)),
             "mid_u": rng.integers(1, 9, (nv, nu)), "mid_v": rng.integers(1, 9, (nv, nu))}
    if base.periodic_u:
        edges["v"][:, -1] = edges["v"][:, 0]
    if base.periodic_v:
        edges["h"][-1] = edges["h"][0]
    if base.poles:
        edges["h"][[0, -1]] = 1
    return edges


def merged(positions, faces):
    v = np.asarray(positions, np.float64)
    assert np.all(np.isfinite(v))
    return trimesh.Trimesh(v, np.asarray(faces), process=True)


@pytest.mark.parametrize("name,kw,euler,closed", [
    ("sphere", {"radius": 1.0}, 2, True), ("torus", {"major_radius": 1.0, "minor_radius": 0.4}, 0, True),
    ("cylinder", {}, 0, False), ("plane", {}, 1, False)])
def test_random_edge_rates_stitch_without_cracks(variant, name, kw, euler, closed):
    base = surfaces.make_base(name, **kw)
    rng = np.random.default_rng(7)
    d = dicing.dice_parametric(base, (7, 5), random_edges(base, 7, 5, rng), 1.0)
    t = dicing.displace_diced_parametric(base, d, None, 0.0, 0.0)
    m = merged(np.asarray(t.positions).T, np.asarray(t.faces).T)
    assert m.is_winding_consistent and m.euler_number == euler
    assert m.is_watertight == closed
    if closed:
        assert m.volume > 0            # wound outwards
    if name == "plane":  # the uv square is covered exactly once, every triangle counter-clockwise
        uv = d.uv[d.faces]
        area = 0.5 * np.cross(uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0])
        assert area.min() > 0 and area.sum() == pytest.approx(1.0, abs=1e-9)


def test_mesh_patches_with_random_edge_rates_are_watertight():
    ico = trimesh.creation.icosphere(2)
    weld = np.arange(len(ico.vertices))
    uniq, side = dicing.mesh_edges(ico.faces, weld)
    seg = np.random.default_rng(3).integers(1, 12, len(uniq))
    md = dicing.dice_mesh(ico.faces, weld, seg, side, 1.0)
    pos = np.einsum("nk,nkd->nd", md.bary, ico.vertices[md.src])
    m = merged(pos, md.faces)
    assert m.is_watertight and m.is_winding_consistent and m.euler_number == 2
    # every base edge carries exactly its own segment count: E' = sum over edges + interior
    assert len(np.unique(md.groups)) == len(md.src)
    # every vertex is used (trimesh's merge hides unused ones from the Euler number), at
    # barycentric coordinates on its source triangle
    np.testing.assert_array_equal(np.unique(md.faces), np.arange(len(md.src)))
    assert md.bary.min() >= 0 and np.allclose(md.bary.sum(1), 1)


@pytest.mark.parametrize("e,m", [(1, 0), (5, 0), (3, 7), (8, 2), (4, 4)])
def test_stitch_strip_covers_the_trapezoid(e, m):
    """Strip between y=0 (e segments) and y=1 (m segments, or a point): e + m triangles,
    counter-clockwise, total area = the trapezoid's."""
    outer_x = np.arange(e + 1) / e
    inner_x = 0.25 + 0.5 * (np.arange(m + 1) / m if m else np.array([0.5]))
    tris = dicing.stitch(np.array([e]), np.array([m]), lambda st, s: s, lambda st, q: e + 1 + q)
    pts = np.concatenate([np.stack([outer_x, 0 * outer_x], 1), np.stack([inner_x, 0 * inner_x + 1], 1)])
    assert len(tris) == e + m
    p = pts[tris]
    area = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert area.min() > 0
    assert area.sum() == pytest.approx(0.5 * (1 + (inner_x[-1] - inner_x[0])))


def camera(origin, target=(0, 0, 0), up=(0, 0, 1), fov=39.6, res=256, kind="perspective"):
    d = {"type": kind, "to_world": mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target), up=list(up)),
         "film": {"type": "hdrfilm", "width": res, "height": res}}
    if kind == "perspective":
        d["fov"] = fov
    return d


def test_sensor_view_measures_pixels_and_frustum(variant):
    v = dicing.sensor_view(mi.load_dict(camera([0, -3.2, 0], res=256)))
    assert not v.orthographic
    assert v.pixel == pytest.approx(2 * math.tan(math.radians(19.8)) / 256, rel=1e-4)
    assert v.half[0] == pytest.approx(math.tan(math.radians(19.8)), rel=1e-4)
    pts = np.array([[0, -1, 0], [0, 5, 0], [20, -3.2, 0], [0, -6, 0]], float)
    px = dicing.pixel_size([v], pts, 0.0, 4.0)
    assert px[0] == pytest.approx(2.2 * v.pixel, rel=1e-6)           # in view
    assert px[1] == pytest.approx(8.2 * v.pixel, rel=1e-6)
    assert px[2] == pytest.approx(4 * 20 * v.pixel, rel=1e-6)        # far off to the side
    assert px[3] == pytest.approx(4 * 2.8 * v.pixel, rel=1e-6)       # behind the camera
    ortho = dicing.sensor_view(mi.load_dict(camera([0, -3, 0], kind="orthographic", res=100)))
    assert ortho.orthographic and ortho.pixel == pytest.approx(2 / 100, rel=1e-4)


def sphere_scene(*sensors, rate=1.0, scale=0.05, **extra):
    refs = {f"ref{i}": {"type": "ref", "id": f"cam{i}"} for i in range(len(sensors))}
    d = {"type": "scene", **{f"cam{i}": s for i, s in enumerate(sensors)},
         "ball": {"type": "displaced", "base": "sphere", "dicing_rate": rate, "scale": scale,
                  "height": {"type": "ripples"}, **refs, **extra}}
    return mi.load_dict(d)


def shape_mesh(shape):
    p = mi.traverse(shape)
    return merged(np.asarray(p["vertex_positions"]).reshape(-1, 3),
                  np.asarray(p["faces"]).reshape(-1, 3))


def test_cycles_sphere_needs_fewer_faces_than_cycles(variant):
    scene = sphere_scene(camera([0, -3.2, 0]))
    shape = scene.shapes()[0]
    s = shape.build_stats
    assert s["mode"] == "dicing" and s["faces"] == shape.face_count()
    # 1 px micro-edges over the whole sphere (4 pi / (0.5 (2.2 * 0.0027)^2) ~ 0.7M would be
    # the front's density everywhere); the back and off-screen parts are coarser
    assert 150_000 < s["faces"] < CYCLES_FACES
    m = shape_mesh(shape)
    assert m.is_watertight and m.euler_number == 2


def test_finest_need_over_several_sensors(variant):
    """Two cameras on opposite sides: each dices its own side finely; both dice both."""
    front, back = camera([0, -3.2, 0], res=96), camera([0, 3.2, 0], fov=30, res=96)
    f_front = sphere_scene(front).shapes()[0].face_count()
    f_back = sphere_scene(back).shapes()[0].face_count()
    f_both = sphere_scene(front, back).shapes()[0].face_count()
    assert max(f_front, f_back) < f_both < f_front + f_back


@pytest.mark.parametrize("where", ["behind", "inside_bound", "orthographic", "edge_on_plane"])
def test_extreme_views_stay_finite_and_watertight(variant, where):
    if where == "edge_on_plane":
        scene = mi.load_dict({"type": "scene", "cam0": camera([0, -5, 0], target=[0, 0, 0], res=64),
                              "p": {"type": "displaced", "base": "plane", "dicing_rate": 1.0,
                                    "scale": 0.05, "height": {"type": "ripples"},
                                    "r": {"type": "ref", "id": "cam0"}}})
    else:
        sensor = {"behind": camera([0, -3.2, 0], target=[0, -10, 0], res=64),
                  "inside_bound": camera([0, -1.02, 0], res=32),
                  "orthographic": camera([0, -3.2, 0], kind="orthographic", res=64)}[where]
        scene = sphere_scene(sensor)
    shape = scene.shapes()[0]
    faces = shape.face_count()
    m = shape_mesh(shape)
    assert faces > 0 and np.all(np.isfinite(np.asarray(mi.traverse(shape)["vertex_normals"])))
    if where != "edge_on_plane":
        assert m.is_watertight and m.euler_number == 2
    if where == "behind":  # the off-screen rate (4x coarser): ~16x fewer faces, not none
        in_view = sphere_scene(camera([0, -3.2, 0], res=64)).shapes()[0].face_count()
        assert in_view / 30 < faces < in_view / 8
    if where == "inside_bound":
        assert faces <= dicing.MAX_FACES


@pytest.mark.parametrize("props,match", [
    ({"dicing_rate": 1e-4}, r"dicing_rate 0.0001 px would dice [\d,]+ triangles"),
    ({"dicing_rate": float("nan")}, "dicing_rate"),
    ({"dicing_rate": float("inf")}, "dicing_rate"),
    ({"dicing_rate": 0.0}, "dicing_rate"),
    ({"dicing_rate": 1.0, "offscreen_dicing_scale": 0.5}, "offscreen_dicing_scale"),
    ({"dicing_rate": 1.0, "resolution": 64}, "replaces 'resolution'"),
    ({"offscreen_dicing_scale": 2.0}, "needs 'dicing_rate'"),
])
def test_bad_rates_are_refused_before_allocating(variant, props, match):
    sensor = camera([0, -3.2, 0])
    rate = props.pop("dicing_rate", None)
    extra = {} if rate is None else {"dicing_rate": rate}
    with pytest.raises(Exception, match=match):
        if rate is None:
            mi.load_dict({"type": "displaced", **props})
        else:
            sphere_scene(sensor, **{**extra, "rate": rate, **props})


def test_traverse_edits_redice_only_what_changed(variant):
    scene = sphere_scene(camera([0, -3.2, 0]), rate=2.0)
    shape = scene.shapes()[0]
    params = mi.traverse(scene)
    f2 = shape.face_count()
    params["ball.dicing_rate"] = 4.0
    params.update()
    assert shape.face_count() < f2 / 2.5 and "topology" in shape.build_stats["rebuilt"]
    params["ball.scale"] = 0.0
    params.update()
    r = np.linalg.norm(np.asarray(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3), axis=1)
    assert np.allclose(r, 1, atol=1e-6)
    # a camera edit reaches the shape through fit_to_sensors (Mitsuba tells only the scene)
    params["cam0.to_world"] = mi.ScalarTransform4f().look_at(origin=[0, -12, 0], target=[0, 0, 0], up=[0, 0, 1])
    params.update()
    f4 = shape.face_count()
    assert dicing.fit_to_sensors(scene) == ["ball"] and shape.face_count() < f4 / 3
    assert dicing.fit_to_sensors(scene) == []               # nothing changed: nothing rebuilt
    # the scene's acceleration structure follows: a ray hits the new surface
    ray = mi.Ray3f(mi.Point3f(0, -5, 0), mi.Vector3f(0, 1, 0))
    assert scene.ray_intersect(ray).t[0] == pytest.approx(5 - r[np.argmin(np.abs(
        np.asarray(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)[:, 1] + 1))], abs=0.05)


def test_scale_edit_keeps_the_topology_when_no_rate_moves(variant):
    """A plane seen from above by an orthographic camera that frames all of it: the pixel size
    does not depend on distance, so a new scale re-displaces the vertices only."""
    cam = camera([0, 0, 5], up=[0, 1, 0], kind="orthographic")
    cam["to_world"] = cam["to_world"] @ mi.ScalarTransform4f().scale([1.5, 1.5, 1])
    scene = mi.load_dict({"type": "scene", "cam0": cam,
                          "p": {"type": "displaced", "base": "plane", "dicing_rate": 2.0,
                                "scale": 0.05, "height": {"type": "ripples"},
                                "r": {"type": "ref", "id": "cam0"}}})
    shape = scene.shapes()[0]
    faces = np.asarray(mi.traverse(shape)["faces"]).copy()
    params = mi.traverse(scene)
    params["p.scale"] = 0.2
    params.update()
    assert shape.build_stats["rebuilt"] == ["vertices"]
    assert np.array_equal(np.asarray(mi.traverse(shape)["faces"]), faces)
    z = np.asarray(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)[:, 2]
    assert z.max() > 0.15


def test_scene_without_sensor_refs_waits_for_fit_to_sensors(variant):
    with pytest.warns(UserWarning, match="needs a sensor"):
        scene = mi.load_dict({"type": "scene", "cam": camera([0, -3.2, 0]),
                              "ball": {"type": "displaced", "base": "sphere", "dicing_rate": 1.0,
                                       "scale": 0.05, "height": {"type": "ripples"}}})
    shape = scene.shapes()[0]
    coarse = shape.face_count()
    assert dicing.fit_to_sensors(scene) == [shape.id()]
    assert shape.face_count() > 10 * coarse and shape.build_stats["sensors"] == 1


def test_zero_height_dices_the_base(variant):
    scene = sphere_scene(camera([0, -3.2, 0]), scale=0.0)
    r = np.linalg.norm(np.asarray(mi.traverse(scene.shapes()[0])["vertex_positions"]).reshape(-1, 3), axis=1)
    assert np.allclose(r, 1.0, atol=1e-6) and scene.shapes()[0].build_stats["bound"] == 0


def test_mesh_base_dices_finer_near_the_camera_and_stays_watertight(variant, tmp_path):
    ico = trimesh.creation.icosphere(2)
    v = ico.vertices
    uv = np.stack([np.arctan2(v[:, 1], v[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(v[:, 2], -1, 1)) / np.pi], 1)
    ico.visual = trimesh.visual.TextureVisuals(uv=uv)
    ico.export(tmp_path / "ico.ply")
    scene = mi.load_dict({"type": "scene", "cam0": camera([0, -2.5, 0], res=64),
                          "s": {"type": "displaced", "filename": str(tmp_path / "ico.ply"),
                                "dicing_rate": 1.0, "scale": 0.03, "height": {"type": "ripples"},
                                "r": {"type": "ref", "id": "cam0"}}})
    shape = scene.shapes()[0]
    assert shape.build_stats["patches"] == len(ico.faces)
    m = shape_mesh(shape)
    assert m.is_watertight and m.is_winding_consistent and m.euler_number == 2
    edges = m.edges_unique_length
    mid_y = m.vertices[m.edges_unique].mean(1)[:, 1]
    front, back = np.median(edges[mid_y < -0.5]), np.median(edges[mid_y > 0.5])
    assert front < back / 1.5          # the camera side is diced finer
    n = np.asarray(mi.traverse(shape)["vertex_normals"])
    assert np.all(np.isfinite(n))


# --- mutants that survived the tests above (scripts/mutation.sh, docs/testing.md) ---------

@pytest.mark.parametrize("name", ["plane", "sphere", "torus"])
def test_diced_vertices_are_all_used_and_inside_the_domain(variant, name):
    """No vertex without a face (trimesh's merge hides those from the Euler number), every
    uv in the unit square, and on the plane V - E + F = 1 (a disk) with V = all vertices."""
    base = surfaces.make_base(name)
    d = dicing.dice_parametric(base, (7, 5), random_edges(base, 7, 5, np.random.default_rng(4)), 1.0)
    np.testing.assert_array_equal(np.unique(d.faces), np.arange(len(d.uv)))
    assert d.uv.min() >= 0 and d.uv.max() <= 1
    if name == "plane":
        edges = np.unique(np.sort(d.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), 1), axis=0)
        assert len(d.uv) - len(edges) + len(d.faces) == 1


def test_face_estimate_is_the_face_count():
    """The face budget is checked on estimate_quad_faces before any face is built: it
    must count exactly what quad_faces makes (simple patches, thin ones, any side rates)."""
    rng = np.random.default_rng(6)
    e = rng.integers(1, 7, (200, 4))
    nu, nv = rng.integers(0, 8, 200), rng.integers(0, 8, 200)
    e[:20], nu[:20], nv[:20] = 1, 1, 1                     # simple two-triangle patches
    assert dicing.estimate_quad_faces(e, nu, nv) == len(dicing.quad_faces(e, nu, nv)["faces"])
    for i in range(0, 200, 7):                             # and patch by patch
        one = slice(i, i + 1)
        assert dicing.estimate_quad_faces(e[one], nu[one], nv[one]) == \
            len(dicing.quad_faces(e[one], nu[one], nv[one])["faces"])


def test_thin_lens_sensor_is_measured_through_the_lens_centre(variant):
    """A thin lens's chief rays (through the centre of the aperture) are the pinhole's: the
    same pixel size and frustum as a perspective sensor of the same field of view."""
    pin = dicing.sensor_view(mi.load_dict(camera([0, -3.2, 0], res=128)))
    lens = dict(camera([0, -3.2, 0], res=128), type="thinlens", fov=39.6, aperture_radius=0.2,
                focus_distance=3.2)
    thin = dicing.sensor_view(mi.load_dict(lens))
    assert not thin.orthographic
    np.testing.assert_allclose(thin.origin, pin.origin, atol=1e-6)
    np.testing.assert_allclose(thin.axes, pin.axes, atol=1e-5)
    assert thin.pixel == pytest.approx(pin.pixel, rel=1e-4)
    np.testing.assert_allclose(thin.half, pin.half, rtol=1e-4)
