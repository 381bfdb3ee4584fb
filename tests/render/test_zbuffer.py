"""`raster` with visibility="zbuffer" (issue 18): the same image as ray-traced visibility,
the alpha test as fragment discard, the extremes of a rasteriser, bad input."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.render import raster, zbuffer


def make_mesh(name, vertices, faces, reflectance=(0.5, 0.5, 0.5), bsdf=None):
    """A mi.Mesh from (V, 3) vertices and (F, 3) faces with a diffuse (or given) BSDF."""
    props = mi.Properties()
    props["bsdf"] = bsdf or mi.load_dict({"type": "diffuse", "reflectance": {
        "type": "rgb", "value": list(reflectance)}})
    vertices = np.asarray(vertices, np.float32)
    faces = np.asarray(faces, np.uint32)
    mesh = mi.Mesh(name, len(vertices), len(faces), props=props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(vertices.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    params.update()
    return mesh


def quad(name, corners, **kw):
    return make_mesh(name, corners, [[0, 1, 2], [0, 2, 3]], **kw)


def camera(res=(64, 64), kind="perspective", origin=(0, -5, 1.5), target=(0, 0, 0), **kw):
    film = {"type": "hdrfilm", "width": res[0], "height": res[1], "rfilter": {"type": "box"}}
    film.update(kw.pop("film", {}))
    sensor = {"type": kind, "film": film, "to_world": mi.ScalarTransform4f().look_at(
        origin=list(origin), target=list(target), up=[0, 0, 1])}
    if kind == "perspective":
        sensor["fov"] = 30
    sensor.update(kw)
    return sensor


def displaced_sphere():
    return {"type": "displaced", "base": "sphere", "resolution": 96, "scale": 0.08,
            "height": {"type": "checkerboard", "to_uv": mi.ScalarTransform4f().scale([8, 4, 1])},
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.6, 0.5]}}}


LIGHTS = {
    "point": {"type": "point", "position": [3, -3, 4], "intensity": {"type": "rgb", "value": 40}},
    "sun": {"type": "directional", "direction": [-1, 1, -1],
            "irradiance": {"type": "rgb", "value": 0.5}},
    "ambient": {"type": "constant", "radiance": {"type": "rgb", "value": 0.2}},
}


def load(shapes, sensor=None, lights=("point", "sun", "ambient"), **integrator):
    d = {"type": "scene", "integrator": {"type": "raster", **integrator},
         "sensor": sensor or camera()}
    d.update({k: LIGHTS[k] for k in lights})
    d.update(shapes)
    return mi.load_dict(d)


def render(scene, **options):
    sensor = scene.sensors()[0]
    aa = options.pop("aa", 1)
    img = np.array(raster.render(scene, sensor, aa, options=raster.Options(**options)))
    assert np.all(np.isfinite(img))
    return img


def sensor_of(kind):
    if kind == "orthographic":
        return camera(kind="orthographic", to_world=mi.ScalarTransform4f().look_at(
            origin=[0, -5, 1.5], target=[0, 0, 0], up=[0, 0, 1]).scale([1.3, 1.3, 1]))
    if kind == "crop":
        return camera(res=(80, 48), film={"crop_offset_x": 20, "crop_offset_y": 8,
                                          "crop_width": 40, "crop_height": 32})
    return camera()


@pytest.mark.parametrize("kind", ["perspective", "orthographic", "crop"])
def test_zbuffer_matches_raytrace(variant, kind):
    """Same triangle at (almost) every sample; the rest are pixel centres within float
    rounding of an edge (the two methods compute barycentrics differently)."""
    scene = load({"s": displaced_sphere()}, sensor_of(kind))
    for aa in (1, 2):
        ray = render(scene, aa=aa)
        zb = render(scene, aa=aa, visibility="zbuffer")
        assert ray.mean() > 0.05
        differs = np.abs(zb - ray).max(axis=2) > 1e-3
        assert differs.mean() < 2e-3
        assert np.abs(zb - ray)[~differs].max() < 1e-4


def test_zbuffer_is_bit_identical_between_runs(variant):
    scene = load({"s": displaced_sphere()})
    first = render(scene, aa=2, visibility="zbuffer", shadows="map")
    assert np.array_equal(first, render(scene, aa=2, visibility="zbuffer", shadows="map"))


def card(opacity, y=-4.0):
    """A 0.3-wide card between camera and sphere, off every shadow ray."""
    s = 0.15
    corners = [[-s, y, 1.2 - s], [s, y, 1.2 - s], [s, y, 1.2 + s], [-s, y, 1.2 + s]]
    bsdf = mi.load_dict({"type": "mask", "opacity": {"type": "rgb", "value": opacity},
                         "bsdf": {"type": "diffuse"}})
    return quad("card", corners, bsdf=bsdf)


def test_alpha_test_is_a_fragment_discard(variant):
    bare = render(load({"s": displaced_sphere()}), visibility="zbuffer")
    for opacity, hidden in ((0.0, False), (0.3, False), (1.0, True)):
        scene = load({"s": displaced_sphere(), "card": card(opacity)})
        zb = render(scene, visibility="zbuffer")
        ray = render(scene)
        change = np.mean(np.abs(zb - bare))
        assert (change > 1e-2) if hidden else (change < 1e-6), opacity
        assert np.mean(np.abs(zb - ray).max(axis=2) > 1e-3) < 2e-3


def test_triangles_behind_and_across_the_near_plane(variant):
    """A ground plane running from behind the camera to the horizon, a red quad behind the
    camera (must not appear), a zero-area triangle (draws nothing)."""
    ground = quad("ground", [[-50, -50, -1], [50, -50, -1], [50, 50, -1], [-50, 50, -1]])
    behind = quad("behind", [[-3, -9, 0], [3, -9, 0], [3, -9, 3], [-3, -9, 3]],
                  reflectance=(1, 0, 0))
    degenerate = make_mesh("degenerate", [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]],
                           reflectance=(0, 1, 0))
    scene = load({"ground": ground, "behind": behind, "degenerate": degenerate},
                 camera(origin=(0, -5, 0.2), target=(0, 0, 0)), lights=("sun", "ambient"))
    ray = render(scene)
    zb = render(scene, visibility="zbuffer")
    ground_px = np.abs(ray - 0.2).max(axis=2) > 1e-3
    assert 0.2 < ground_px.mean() < 0.95  # the plane reaches the image's bottom edge
    assert np.mean(np.abs(zb - ray).max(axis=2) > 1e-3) < 2e-3
    assert np.all(zb[..., 0] <= zb[..., 1] + 1e-6)  # no red from behind the camera


def test_screen_covering_and_tiny_films(variant):
    wall = quad("wall", [[-40, 2, -40], [40, 2, -40], [40, 2, 40], [-40, 2, 40]])
    for res in ((64, 48), (1, 1)):
        scene = load({"wall": wall}, camera(res=res, origin=(0, -5, 0)), lights=("ambient",))
        zb = render(scene, visibility="zbuffer")
        assert zb.shape == (res[1], res[0], 3)
        assert np.allclose(zb, 0.1)  # albedo 0.5 x ambient 0.2 at every pixel


def test_film_too_large_is_refused_before_allocation(variant):
    scene = load({"s": displaced_sphere()}, camera(res=(16384, 16384)), lights=("ambient",))
    with pytest.raises(ValueError, match="16384x16384 film"):
        render(scene, visibility="zbuffer")


def test_depth_ties_go_to_the_first_triangle(variant):
    """Two coincident quads: the smaller triangle id (the first shape) wins every sample."""
    corners = [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]
    shapes = {"a": quad("a", corners, reflectance=(1, 0, 0)),
              "b": quad("b", corners, reflectance=(0, 0, 1))}
    scene = load(shapes, camera(origin=(0, -5, 0)), lights=("ambient",))
    zb = render(scene, visibility="zbuffer")
    on = ~np.all(np.abs(zb - 0.2) < 1e-6, axis=2)  # not the environment
    assert on.mean() > 0.05
    first = 0 if scene.shapes()[0].id() == "a" else 2
    assert np.all(zb[on][:, first] > 0.19) and np.all(zb[on][:, 2 - first] < 1e-6)
    assert np.array_equal(zb, render(scene, visibility="zbuffer"))


def test_distant_geometry_keeps_depth_order(variant):
    """Two quads a million units away, 10 units apart, near clip 1e-2: linear float32
    depth resolves them (relative gap 1e-5 >> 2^-24); a [0, 1] depth with this near/far
    ratio would not."""
    far = 1e6
    size = 0.5 * far  # wider than the 30-degree view

    def wall(name, y, colour):
        return quad(name, [[-size, y, -size], [size, y, -size], [size, y, size], [-size, y, size]],
                    reflectance=colour)
    shapes = {"back": wall("back", far, (1, 0, 0)), "front": wall("front", far - 10, (0, 0, 1))}
    sensor = camera(origin=(0, 0, 0), target=(0, 1, 0), near_clip=1e-2, far_clip=1e7)
    zb = render(load(shapes, sensor, lights=("ambient",)), visibility="zbuffer")
    assert np.all(zb[..., 2] > 0.09) and np.all(zb[..., 0] < 1e-6)


def test_bad_options(variant):
    scene = load({"s": displaced_sphere()})
    with pytest.raises(ValueError, match="'visibility'"):
        render(scene, visibility="scanline")
    with pytest.raises(ValueError, match="'shadows'"):
        render(scene, shadows="soft")
    with pytest.raises(ValueError, match="'shadow_resolution'"):
        render(scene, shadows="map", shadow_resolution=0)
    with pytest.raises(ValueError, match="shadow_bias"):
        render(scene, shadows="map", shadow_bias=float("nan"))
    with pytest.raises(ValueError, match="explicit 'shapes'"):
        raster.render(scene, scene.sensors()[0], shapes=list(scene.shapes()))
    analytic = load({"ball": {"type": "sphere"}})
    with pytest.raises(ValueError, match="triangle meshes only"):
        render(analytic, visibility="zbuffer")
    with pytest.raises(Exception, match="'visibility'"):
        load({"s": displaced_sphere()}, visibility="scanline")


def test_empty_scene_shows_the_environment(variant):
    """No triangles at all: every sample misses, as under ray tracing."""
    scene = load({}, lights=("point", "sun", "ambient"))
    zb = render(scene, visibility="zbuffer", shadows="map")
    assert np.array_equal(zb, render(scene)) and np.allclose(zb, 0.2)


def random_triangles(n=300, seed=1):
    """Triangles of every shape and size, slivers included, some crossing the near plane
    and some behind the camera of :func:`camera` (at y = -5, looking along +y)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform([-3, -6, -2], [3, 4, 3], (n, 3))
    size = np.exp(rng.uniform(np.log(0.02), np.log(4.0), (n, 1, 1)))
    offsets = rng.normal(size=(n, 3, 3)) * size
    offsets[: n // 4, 2] = offsets[: n // 4, 0] + 1e-3 * offsets[: n // 4, 2]   # slivers
    vertices = (centres[:, None] + offsets).reshape(-1, 3)
    return make_mesh("random", vertices, np.arange(3 * n).reshape(n, 3))


def test_row_spans_cover_every_sample_the_box_does(variant, monkeypatch):
    """The row threads visit only each row's span (the edges the row meets): the same keys
    as the brute-force enumeration of every candidate of each triangle's box (every
    triangle through the one-thread loop, MEDIUM raised), on ordinary meshes, slivers,
    triangles across and behind the near plane, with an alpha test, both key kinds and
    sample orders."""
    ground = quad("ground", [[-50, -50, -1], [50, -50, -1], [50, 50, -1], [-50, 50, -1]])
    behind = quad("behind", [[-3, -9, 0], [3, -9, 0], [3, -9, 3], [-3, -9, 3]])
    scenes = [(load({"ground": ground, "behind": behind}, camera(origin=(0, -5, 0.2))), 1),
              (load({"r": random_triangles()}, camera(res=(72, 56))), 1),
              (load({"r": random_triangles(seed=2)}, sensor_of("orthographic")), 2),
              (load({"r": random_triangles(seed=3)}, sensor_of("crop")), 2)]

    def checker(t, active):   # discard fragments on a checker of sample indices
        return lambda s, b1, b2, a: ((s // 3 + t) % 2) == 0

    for scene, aa in scenes:
        geom = zbuffer.gather_geometry(scene.shapes())
        view = zbuffer.view_from_sensor(scene.sensors()[0], aa)
        for kw in ({}, {"with_ids": False}, {"alpha": checker}):
            monkeypatch.setattr(zbuffer, "MEDIUM", 64)
            rows, _ = zbuffer.rasterise(view, geom, aa=aa, **kw)
            monkeypatch.setattr(zbuffer, "MEDIUM", 1 << 30)
            boxes, _ = zbuffer.rasterise(view, geom, aa=aa, **kw)
            drawn = np.array(rows) != (zbuffer.EMPTY if kw.get("with_ids", True) else 0xFFFFFFFF)
            assert drawn.mean() > 0.1
            assert np.array_equal(np.array(rows), np.array(boxes)), kw


def layered(mesh, layers, seed=0):
    """Per-vertex steps of thin, non-parallel layers over ``mesh`` (2 % of each triangle's
    size along its normal, tilted by noise) and the explicit copies as one mesh (copy k
    of face f is face k F + f, as :func:`zbuffer.rasterise_layers` numbers them)."""
    p = np.array(mi.traverse(mesh)["vertex_positions"]).reshape(-1, 3)
    f = np.array(mi.traverse(mesh)["faces"]).reshape(-1, 3)
    tri = p[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    size = np.sqrt(np.linalg.norm(n, axis=1, keepdims=True))
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    noise = np.random.default_rng(seed).normal(size=tri.shape) * 0.2
    step = np.zeros_like(p)
    step[f] = 0.02 / layers * size[:, :, None] * (n[:, None] + noise)   # vertices are per triangle
    copies = np.concatenate([p + k * step.astype(np.float32) for k in range(layers)])
    faces = np.concatenate([f + k * len(p) for k in range(layers)])
    return mi.Vector3f(*(mi.Float(c) for c in step.astype(np.float32).T)), make_mesh("copies", copies, faces)


@pytest.mark.parametrize("kind", ["perspective", "orthographic", "crop"])
def test_layers_are_the_copies_drawn_as_triangles(variant, kind):
    """zbuffer.rasterise_layers (one prism per triangle, copies visited front to back with
    an early exit) against zbuffer.rasterise of the copies as an explicit mesh: the same
    fragment wins (same triangle, or a depth within rounding: the copies' vertices are
    rounded differently), with a discard per (sample, copy) and over an existing buffer;
    triangles across and behind the near plane, slivers, 1 and 2 samples per pixel."""
    mesh = random_triangles(seed=4)
    layers = 9
    step, copies = layered(mesh, layers)
    scene = load({"m": mesh}, sensor_of(kind))
    geom, explicit = zbuffer.gather_geometry([mesh]), zbuffer.gather_geometry([copies])
    F = dr.width(geom.faces)

    def discard(s, k):   # a checker over samples and copies
        return ((s // 3 + k) % 2) == 0

    by_copy = lambda t, active: lambda s, b1, b2, a: discard(s, t // F)
    by_layer = lambda f, active: lambda s, k, b1, b2, a: discard(s, k)
    for aa in (1, 2):
        view = zbuffer.view_from_sensor(scene.sensors()[0], aa)
        wall = quad("wall", [[-9, 0.5, -9], [9, 0.5, -9], [9, 0.5, 9], [-9, 0.5, 9]])
        over, _ = zbuffer.rasterise(view, zbuffer.gather_geometry([wall]), aa=aa)
        for kw_layers, kw_copies in (({}, {}), ({"alpha": by_layer}, {"alpha": by_copy}),
                                     ({"initial": over}, {"initial": over})):
            got, _ = zbuffer.rasterise_layers(view, geom, step, layers, aa=aa, **kw_layers)
            ref, _ = zbuffer.rasterise(view, explicit, aa=aa, **kw_copies)
            got, ref = np.array(got), np.array(ref)
            drawn = ref != zbuffer.EMPTY
            assert drawn.mean() > 0.1
            assert (got != zbuffer.EMPTY).sum() == pytest.approx(drawn.sum(), rel=2e-3)
            low = np.uint64(0xFFFFFFFF)
            same = (got & low) == (ref & low)
            assert same[drawn].mean() > 0.99, (kind, aa, kw_layers.keys())
            z = lambda k: (k >> np.uint64(32)).astype(np.uint32).view(np.float32)
            both = drawn & (got != zbuffer.EMPTY)
            assert np.all(np.abs(z(got[both]) - z(ref[both])) <= 2e-3 * z(ref[both]))
            if "initial" in kw_layers:   # nothing drawn behind the wall
                mine = got != zbuffer.EMPTY
                assert np.all(z(got[mine]) <= z(np.array(over)[mine]))


def face_on_stack():
    """A 4 x 4 grid of quads in the plane y = 1, facing the camera at (0, -5, 0), and a
    step of 0.01 towards it per copy: every copy's fragments lie at its vertices' depth."""
    g = np.linspace(-0.9, 0.9, 5)
    x, z = np.meshgrid(g, g)
    vertices = np.stack([x.ravel(), np.ones(25), z.ravel()], 1)
    i = (np.arange(4)[:, None] * 5 + np.arange(4)[None]).ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + 6], 1), np.stack([i, i + 6, i + 5], 1)])
    step = mi.Vector3f(dr.zeros(mi.Float, 25), dr.full(mi.Float, -0.01, 25), dr.zeros(mi.Float, 25))
    return make_mesh("stack", vertices, faces), step


@pytest.mark.parametrize("kind", ["perspective", "orthographic"])
def test_layers_over_their_own_depths_keep_every_fragment(variant, kind):
    """rasterise_layers drawn over its own result with every id raised (same depths): each
    sample's fragment ties the stored depth and wins it by its smaller id, so the result is
    the first one exactly — no prism is skipped whose fragment reaches the stored depth
    (the per-sample skip behind the stored fragment, its rounding margin: face-on copies,
    whose fragments lie at the prism's nearest depth), with and without a discard."""
    layers = 7
    mesh = random_triangles(seed=5)
    step, _ = layered(mesh, layers)
    stack, stack_step = face_on_stack()
    scenes = [(mesh, step, sensor_of(kind)),
              (stack, stack_step, camera(kind=kind, origin=(0, -5, 0)))]
    checker = lambda f, active: lambda s, k, b1, b2, a: ((s // 5 + k) % 3) != 0
    for shape, shape_step, sensor in scenes:
        geom = zbuffer.gather_geometry([shape])
        view = zbuffer.view_from_sensor(load({"m": shape}, sensor).sensors()[0], 1)
        for alpha in (None, checker):
            first, _ = zbuffer.rasterise_layers(view, geom, shape_step, layers, alpha=alpha)
            drawn = first != zbuffer.EMPTY
            raised = dr.select(drawn, first | mi.UInt64(0xFFFFFFFF), first)   # depth kept
            again, _ = zbuffer.rasterise_layers(view, geom, shape_step, layers, alpha=alpha,
                                                initial=raised)
            assert dr.count(drawn)[0] > 0.1 * dr.width(first)
            assert dr.all(again == first)[0], (kind, shape.id(), alpha is None)
