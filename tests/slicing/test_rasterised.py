"""The slices rasterised by our z-buffer (mi_displace.slicing.rasterised) against the
second implementation of the same slices: the ray-traced walk (rasterise=false)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.evaluate.metrics import flip
from mi_displace.render import pixel_order, zbuffer
from mi_displace.slicing import rasterised
from slicing_scenes import donut



def both(helpers, shape, sensor):
    """(rasterised image, walked image, the slicing shape)."""
    img, scene = helpers.render({**shape, "bsdf": helpers.MATERIAL}, sensor)
    obj = next(s for s in scene.shapes() if hasattr(s, "volume"))
    assert obj.volume.frame is None   # the frame is dropped after the render
    obj.rasterise = False
    walked = np.array(mi.render(scene))[..., :3]
    return img, walked, obj


def assert_same(img, walked):
    diff = np.abs(img - walked).max(-1)
    assert np.isfinite(img).all() and np.isfinite(walked).all()
    assert (diff > 1e-3).mean() < 0.005, (diff > 1e-3).mean()
    assert flip(walked, img)[0] < 0.005


@pytest.mark.parametrize("direction", ["a", "best"])
def test_rasterised_donut_is_the_walked_donut(variant, helpers, direction):
    sensor = helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=64)
    img, walked, obj = both(helpers, donut(direction), sensor)
    assert (np.abs(img - 0.1).max(-1) > 1e-3).mean() > 0.2   # the donut is there
    assert_same(img, walked)
    # the fragments themselves against the walk from the first wall the ray meets
    vol = obj.volume
    frame = rasterised.draw(vol, mi.load_dict(sensor))
    ray, *_ = rasterised.pixel_rays(mi.load_dict(sensor), 1)
    use, drawn = frame.lookup(ray.o, ray.d, mi.Bool(True))
    pi = vol.walls_scene.scene.ray_intersect_preliminary(ray)
    third = dr.full(mi.Float, 1 / 3, dr.width(ray.d))
    bn, su, sv = vol.walls_scene.frame(pi.prim_index, (third, third), pi.is_valid())
    walk = vol.find(ray.o, ray.d, vol.choose(ray.d, dr.normalize(bn), su, sv), pi.is_valid())
    use, found, ref = np.array(use), np.array(drawn.found), np.array(walk.found)
    assert use.mean() > 0.2 and np.array_equal(use, np.array(frame.covered))
    assert (found[use] == ref[use]).mean() > 0.99
    both_found = use & found & ref
    gap = np.linalg.norm(np.array(drawn.p) - np.array(walk.p), axis=0)[both_found]
    assert (gap < 1e-4).mean() > 0.99


@pytest.mark.parametrize("direction", ["c", "best"])
def test_slices_rasterised_by_rows_are_those_of_every_candidate(variant, helpers, monkeypatch,
                                                                direction):
    """The donut's slice polygons (alpha test, base polygons drawn first, a family per
    sample; direction a's are prisms, tested below) drawn by the row threads:
    bit-identical fragments to every candidate of each triangle's box enumerated (MEDIUM
    raised: one thread loops over the whole box)."""
    sensor = mi.load_dict(helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=56))
    _, scene = helpers.render({**donut(direction), "bsdf": helpers.MATERIAL},
                              helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=8))
    vol = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
    frames = []
    for medium in (zbuffer.MEDIUM, 1 << 30):
        monkeypatch.setattr(zbuffer, "MEDIUM", medium)
        frames.append(rasterised.draw(vol, sensor))
    rows, boxes = frames
    found = np.array(rows.hit.found)
    assert found.mean() > 0.2 and np.array_equal(found, np.array(boxes.hit.found))
    for name in ("p", "uv", "n", "su", "sv"):
        assert np.array_equal(np.array(getattr(rows.hit, name))[:, found],
                              np.array(getattr(boxes.hit, name))[:, found]), name


@pytest.mark.parametrize("direction", ["a", "best"])
def test_slivers_drawn_whole_are_those_drawn_by_rows(variant, helpers, monkeypatch, direction):
    """Slivers (boxes at most SPAN wide, TALL tall: the orthogonal slices, the walls) drawn
    by one thread each looping over their rows: bit-identical keys of every pass of the
    donut's frame (``best``: walls, base polygons, slices b and c, alpha-tested; ``a``: the
    base polygons, its slices being prisms) to the same triangles drawn by one thread per
    row piece (TALL 0)."""
    sensor = mi.load_dict(helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=96))
    _, scene = helpers.render({**donut(direction), "bsdf": helpers.MATERIAL},
                              helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=8))
    vol = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
    passes, slivers, rasterise = [], [], zbuffer.rasterise

    def recorded(view, geom, *args, **kwargs):
        keys, clip = rasterise(view, geom, *args, **kwargs)
        passes.append(np.array(keys))
        return keys, clip

    def counted_loop(state, cond, body, label=None, **kwargs):
        slivers.append(label == "raster_slivers" and dr.width(state[0]))
        return loop(state, cond, body, label=label, **kwargs)

    loop = dr.while_loop
    monkeypatch.setattr(zbuffer, "rasterise", recorded)
    monkeypatch.setattr(zbuffer.dr, "while_loop", counted_loop)
    whole = rasterised.draw(vol, sensor)
    drawn_whole, passes[:] = list(passes), []
    assert sum(slivers) > 50, slivers   # slivers were drawn whole
    monkeypatch.setattr(zbuffer, "TALL", 0)
    slivers.clear()
    rows = rasterised.draw(vol, sensor)
    assert not any(slivers)
    assert len(passes) == len(drawn_whole) >= (1 if direction == "a" else 4)
    for a, b in zip(drawn_whole, passes):
        assert np.array_equal(a, b)
    found = np.array(whole.hit.found)
    assert found.mean() > 0.2 and np.array_equal(found, np.array(rows.hit.found))
    for name in ("p", "uv", "n", "su", "sv"):
        assert np.array_equal(np.array(getattr(whole.hit, name))[:, found],
                              np.array(getattr(rows.hit, name))[:, found]), name


@pytest.mark.parametrize("alpha", ["basic", "ramp"])
def test_aligned_prisms_are_the_slice_polygons(variant, helpers, monkeypatch, alpha):
    """Direction a drawn as prisms, front to back with an early exit and a slice-0 depth
    pre-pass (rasterised._draw_aligned), against its slices drawn as triangles one by one
    (rasterised._draw_polygons): the same samples found, the same fragments but for
    α-test and edge ties (a neighbouring slice, one spacing away), at an ordinary, a
    grazing and a below view, from inside the volume, with 1 and 2 samples per pixel."""
    spacing = 0.08 / 8
    views = [([0, -3.4, 2.2], [0, 0, -0.1]), ([0, -3.6, 0.06], [0, 0, 0]),
             ([0.3, -2.6, -2.2], [0, 0, 0]), ([0, -1.4 - 0.04, 0.0], [1, 0, 0])]
    polygons = lambda vol, view, aa, slices, start: rasterised._draw_polygons(
        vol, view, aa, slices, dr.full(mi.Bool, True, view.width * view.height), start)
    for origin, target in views:
        sensor = helpers.look(origin, target, fov=38, res=40)
        scene = mi.load_dict({"type": "scene", "s": {**donut("a"), "alpha": alpha, "draw_base": False},
                              "sensor": sensor})
        vol = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
        for aa in (1, 2):
            prisms = rasterised.draw(vol, scene.sensors()[0], aa).hit
            with monkeypatch.context() as m:
                m.setattr(rasterised, "_draw_aligned", polygons)
                triangles = rasterised.draw(vol, scene.sensors()[0], aa).hit
            found, ref = np.array(prisms.found), np.array(triangles.found)
            assert ref.mean() > 0.05 and (found != ref).mean() < 1e-3, (origin, aa)
            both = found & ref
            gap = np.linalg.norm(np.array(prisms.p) - np.array(triangles.p), axis=0)[both]
            assert (gap > 1e-4).mean() < 5e-3 and gap.max() < 3 * spacing, (origin, aa, gap.max())
            for name in ("uv", "n"):
                assert np.isfinite(np.array(getattr(prisms, name))).all()


def test_base_polygons_change_nothing_under_the_basic_test(variant, helpers):
    """Direction a with the basic alpha test: slice 0 (h = 0) passes everywhere, so drawing
    the base polygons too gives the same frame without self-shadows (the benchmark's
    like-for-like frame leaves them out, as the OpenGL peer does; the self-shadow walk
    does differ: with the base drawn, a walk leaving through the bottom wall is blocked)."""
    sensor = helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=48)
    shape = {**donut("a"), "self_shadows": False, "bsdf": helpers.MATERIAL}
    with_base, _ = helpers.render(shape, sensor)
    without, _ = helpers.render({**shape, "draw_base": False}, sensor)
    assert (np.abs(with_base - 0.1).max(-1) > 1e-3).mean() > 0.2
    assert np.abs(with_base - without).max() < 1e-6


def test_rasterised_plane_orthographic_and_aa(variant, helpers):
    """An orthographic view (other lookup) and 2 x 2 samples per pixel (other sample order)."""
    sensor = helpers.look([0.3, -2.0, 2.0], [0, 0, 0], res=40, ortho_size=0.9)
    img, walked, _ = both(helpers, helpers.plane(slices=12, direction="best"), sensor)
    assert_same(img, walked)
    scene = mi.load_dict({"type": "scene", "obj": {**helpers.plane(slices=12, direction="c")},
                          "sun": {"type": "directional", "direction": [-0.4, 0.5, -0.75]},
                          "sensor": helpers.look([0, -2.6, 2.6], [0, 0, 0], res=24)})
    raster = mi.load_dict({"type": "raster", "aa": 2})
    a = np.array(mi.render(scene, integrator=raster))
    next(s for s in scene.shapes() if hasattr(s, "volume")).rasterise = False
    assert_same(a, np.array(mi.render(scene, integrator=raster)))


@pytest.mark.parametrize("direction", ["a", "b"])
def test_one_family_with_its_base_is_the_walked_one(variant, helpers, direction):
    """One family draws no walls pass, its base polygons or not (every sample is the
    frame's: a ray that misses the walls misses the proxy), and a's slice 0 no depth
    pre-pass when the base polygons were drawn: the open plane seen at a grazing angle,
    its near edge (where the bottom wall reaches past slice 0) in view, as walked."""
    sensor = helpers.look([0.2, -2.4, 0.45], [0, -0.2, 0], fov=45, res=48)
    img, walked, obj = both(helpers, helpers.plane(slices=12, direction=direction), sensor)
    assert_same(img, walked)
    frame = rasterised.draw(obj.volume, mi.load_dict(sensor))
    assert np.array(frame.covered).all() and 0.2 < np.array(frame.hit.found).mean() < 1


def test_zero_heights_draw_nothing(variant, helpers):
    """ramp α-test: a zero map discards every fragment (the base not drawn: nothing)."""
    zero = {"type": "uniform", "value": 0.0}
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=32)
    img, walked, obj = both(helpers, helpers.plane(height=zero, direction="best", draw_base=False),
                            sensor)
    frame = rasterised.draw(obj.volume, mi.load_dict(sensor))
    assert np.array(frame.covered).mean() > 0.2 and not np.array(frame.hit.found).any()
    assert np.abs(img - 0.1).max() < 1e-5 and np.abs(walked - 0.1).max() < 1e-5


def test_path_renders_are_unchanged_after_raster(variant, helpers):
    sensor = helpers.look([0, -2.6, 2.6], [0, 0, 0], res=24)
    shape = {**helpers.plane(slices=8, direction="best"), "bsdf": helpers.MATERIAL}
    scene = mi.load_dict({"type": "scene", "obj": shape, "sensor": sensor,
                          "sun": {"type": "directional", "direction": [-0.4, 0.5, -0.75]}})
    path = mi.load_dict({"type": "path", "max_depth": 2})
    before = np.array(mi.render(scene, integrator=path, spp=4, seed=3))
    mi.render(scene, integrator=mi.load_dict({"type": "raster"}))
    after = np.array(mi.render(scene, integrator=path, spp=4, seed=3))
    assert np.array_equal(before, after)


def test_alpha_and_initial_keys_of_the_zbuffer(variant):
    """zbuffer.rasterise's discard and drawing over an existing buffer (with hierarchical z)
    against the same triangles drawn plainly."""
    sensor = mi.load_dict({"type": "perspective", "fov": 50, "to_world": mi.ScalarTransform4f().look_at(
        origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": 96, "height": 80}})
    # two big overlapping quads (near z = 0.5 and far z = 0) and a small one behind both
    quads = [(0.5, 1.0), (0.0, 1.2), (-0.5, 0.2)]
    pos, faces = [], []
    for z, r in quads:
        base = len(pos)
        pos += [[-r, -r, z], [r, -r, z], [r, r, z], [-r, r, z]]
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    mesh = mi.Mesh("quads", len(pos), len(faces))
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.array(pos, np.float32).ravel())
    params["faces"] = mi.UInt32(np.array(faces, np.uint32).ravel())
    params.update()
    geom = zbuffer.gather_geometry([mesh])
    view = zbuffer.view_from_sensor(sensor)
    plain, _ = zbuffer.rasterise(view, geom)
    tri = np.array(plain) & 0xFFFFFFFF
    assert set(np.unique(tri[np.array(plain) != zbuffer.EMPTY])) <= {0, 1, 2, 3}
    # discard the near quad's fragments left of x = 0: the far quad shows through there
    X, _ = zbuffer.sample_xy(view, dr.arange(mi.UInt32, view.width * view.height), 1)
    left = X < view.width // 2
    keys, _ = zbuffer.rasterise(view, geom, alpha=lambda t, active: lambda s, b1, b2, a: ~(
        (t < 2) & dr.gather(mi.Bool, left, s, a)))
    got = np.array(keys) & 0xFFFFFFFF
    near = np.isin(tri, [0, 1])
    assert np.all(np.isin(got[near & np.array(left)], [2, 3]))
    assert np.array_equal(got[near & ~np.array(left)], tri[near & ~np.array(left)])
    # drawing the small far quad over the plain buffer changes nothing (all behind)
    small = dataclass_faces(geom, [4, 5])
    over, _ = zbuffer.rasterise(view, small, initial=plain)
    assert np.array_equal(np.array(over), np.array(plain))
    # over an empty buffer the small quad is drawn
    alone, _ = zbuffer.rasterise(view, small, initial=dr.full(mi.UInt64, zbuffer.EMPTY, dr.width(plain)))
    assert (np.array(alone) != zbuffer.EMPTY).sum() > 20


def dataclass_faces(geom, faces):
    import dataclasses
    return dataclasses.replace(geom, faces=dr.gather(mi.Vector3u, geom.faces, mi.UInt32(faces)))


@pytest.mark.parametrize("integrator, follows", [("path", False), ("volpath", True)])
def test_shadows_onto_other_objects(variant, integrator, follows):
    """path's shadow rays stop at the volume's boundary (a solid shadow); volpath's
    next-event estimation passes through null-BSDF surfaces, asking the slicing BSDF's null
    transmission, so the floor gets the slices' own shadow (bricks, lit through the cut-out
    mortar).  Truth: the slice walk from each floor point towards the light."""
    T = mi.ScalarTransform4f
    wl = np.array([-0.6, 0.0, 1.0]) / np.linalg.norm([-0.6, 0.0, 1.0])   # towards the sun
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": integrator, "max_depth": 3},
        "obj": {"type": "slicing", "base": "plane", "slices": 16, "direction": "a",
                "alpha": "ramp", "scale": 0.3, "bsdf": {"type": "diffuse"},
                "height": {"type": "bricks", "rows": 3, "columns": 2, "mortar": 0.3, "bevel": 0.1},
                "to_world": T().translate([0, 0, 1.0]) @ T().scale(0.6)},
        "floor": {"type": "rectangle", "to_world": T().scale(3), "bsdf": {"type": "diffuse"}},
        "sun": {"type": "directional", "direction": (-wl).tolist(), "irradiance": 3.0},
        # looking down at the floor east of the object, where its shadow falls
        "sensor": {"type": "orthographic", "to_world": T().look_at(
            origin=[0.95, 0, 3], target=[0.95, 0, 0], up=[0, 1, 0]) @ T().scale([0.25, 0.25, 1]),
            "film": {"type": "hdrfilm", "width": 40, "height": 40}}})
    img = np.array(mi.render(scene, spp=4))[..., :3].mean(-1)
    assert np.isfinite(img).all()
    lit = 0.5 / np.pi * 3.0 * wl[2]                     # the floor's radiance in the sun
    dark = (img < 0.5 * lit).ravel()
    # the truth: walk the slices from each pixel's floor point towards the light
    sensor = scene.sensors()[0]
    ray, *_ = rasterised.pixel_rays(sensor, 1)
    o = np.array(ray.o) + np.array(ray.d) * (-np.array(ray.o)[2] / np.array(ray.d)[2])
    vol = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
    n = o.shape[1]
    hit = vol.find(mi.Point3f(*[mi.Float(x.astype(np.float32)) for x in o]),
                   mi.Vector3f(*[mi.Float(np.full(n, x, np.float32)) for x in wl]),
                   dr.zeros(mi.UInt32, n), mi.Bool(True))
    shadow = np.array(pixel_order.rows(hit.found, 40, 40))   # the frame's lanes in rows
    assert 0.2 < shadow.mean() < 0.8                  # bricks and lit mortar both there
    agree = (dark == shadow).mean()
    assert (agree > 0.9) == follows, agree


@pytest.mark.parametrize("direction", ["a", "c"])
def test_orthographic_frame_covers_every_sample(variant, helpers, direction):
    """An orthographic sensor's rays share one direction (a width-1 array): the frame's
    buffers still hold one entry per sample (one family without base polygons skips the
    walls pass, so nothing else sizes them), and match the walk."""
    sensor = helpers.look([0.3, -2.0, 2.0], [0, 0, 0], res=40, ortho_size=0.9)
    shape = helpers.plane(slices=12, direction=direction, draw_base=False)
    img, walked, obj = both(helpers, shape, sensor)
    frame = rasterised.draw(obj.volume, mi.load_dict(sensor))
    for buffer in (frame.covered, *frame.hit.fields()):
        assert np.array(buffer).shape[-1] == 40 * 40
    assert np.array(frame.hit.found).mean() > 0.2
    assert_same(img, walked)


def test_one_slice_walk_for_the_shading(variant, helpers, monkeypatch):
    """Under ``raster`` the shading asks the slicing BSDF's queries (eval per light, the
    ambient albedo) in one dispatch (raster.shade_hit), so the slices are walked once for
    the shading (they were walked once per query)."""
    from mi_displace.slicing.bsdf import SlicingBSDF
    from mi_displace.render import raster

    counts = {"shading": False, "walks": 0, "shade_hit": 0}
    walk, shade_hit = SlicingBSDF._walk, raster.shade_hit

    def counted_walk(*args):
        counts["walks"] += counts["shading"]
        return walk(*args)

    def counted_shade_hit(*args):
        counts["shade_hit"] += 1
        counts["shading"] = True
        try:
            return shade_hit(*args)
        finally:
            counts["shading"] = False

    monkeypatch.setattr(SlicingBSDF, "_walk", counted_walk)
    monkeypatch.setattr(raster, "shade_hit", counted_shade_hit)
    sensor = helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=32)
    helpers.render({**donut("a"), "bsdf": helpers.MATERIAL}, sensor)
    assert counts["shade_hit"] == 1 and counts["walks"] == 1, counts


@pytest.mark.parametrize("direction", ["a", "best"])
def test_a_camera_move_compiles_no_new_kernel(variant, direction):
    """The view enters the slicing frame's kernels as parameters, not as traced constants:
    after two views, the first one turned by a hair more (the same fragments, other numbers
    in its transforms) launches only kernels Dr.Jit has compiled."""
    from mi_displace.bench import frames
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    scene, _ = load(scene_path("slicing_donut.xml"), mode="approximation", integrator="raster",
                    direction=direction, coarse=16, res=32)
    integrator = mi.load_dict({"type": "raster", "aa": 1})
    # degrees; the hair is new to each run: a view traced as constants would otherwise find
    # an earlier run's kernels in Dr.Jit's on-disk cache.  A hair, not a new place: a view
    # whose buffers differ in size (a batch of one triangle) has kernels of its own
    angles = np.array([5.0, 5.5, 5.0 + np.random.default_rng().uniform(1e-3, 2e-3)])
    profile, moved, images = frames.camera_move_profile(
        scene, angles, lambda: np.array(mi.render(scene, integrator=integrator, spp=1)))
    assert moved                      # other float32 numbers in the camera's transform
    assert all(np.isfinite(img).all() for img in images)
    assert profile["kernels"] > 10
    assert profile["cache_misses"] == 0, profile


@pytest.mark.parametrize("direction", ["a", "best", "screen"])
def test_coherent_self_shadow_walk_is_the_incoherent_one(variant, helpers, monkeypatch, direction):
    """During a raster frame the slicing walks (self-shadows; the view rays of screen
    slicing, which is never rasterised) query the slices as coherent rays (Embree's packet
    traversal, faster for a frame's rays); the walk finds the same polygons: the same
    occlusion per sample and the same image as the incoherent walk; after the frame (path
    tracing) the walks are incoherent again."""
    from mi_displace.slicing import sliced

    calls = []
    walk = sliced.first_passing_slice

    def recorded(*args, **kwargs):
        calls.append(kwargs.get("coherent", args[8] if len(args) > 8 else False))
        return walk(*args, **kwargs)

    monkeypatch.setattr(sliced, "first_passing_slice", recorded)
    sensor = helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=48)
    img, scene = helpers.render({**donut(direction), "bsdf": helpers.MATERIAL}, sensor)
    obj = next(s for s in scene.shapes() if hasattr(s, "volume"))
    assert calls and all(calls), calls   # every walk of the frame
    assert obj.volume.coherent is False   # cleared after the frame
    # the same frame with the flag cleared: the incoherent walk of the same shadow rays
    begin = type(obj).raster_begin

    def incoherent(self, sensor, aa):
        begin(self, sensor, aa)
        self.volume.coherent = False

    monkeypatch.setattr(type(obj), "raster_begin", incoherent)
    calls.clear()
    plain = np.array(mi.render(scene))[..., :3]
    assert calls and not any(calls)
    assert np.isfinite(img).all() and np.array_equal(img, plain)
    if direction == "screen":   # planes, not rasterised: no fragments to compare
        return
    # per sample: the frame's fragments lit by the sun, occluded alike either way
    vol = obj.volume
    hit = rasterised.draw(vol, mi.load_dict(sensor)).hit
    normal = vol.normal(hit)
    wl = dr.normalize(mi.Vector3f(0.4, -0.5, 0.75)) + dr.zeros(mi.Vector3f, dr.width(normal))
    lit = hit.found & (dr.dot(normal, wl) > 0)
    occluded = []
    for coherent in (False, True):
        vol.coherent = coherent
        occluded.append(np.array(vol.occluded(hit, normal, wl, lit)))
    vol.coherent = False
    assert np.array(lit).mean() > 0.2 and 10 < occluded[0].sum() < np.array(lit).sum()
    assert np.array_equal(occluded[0], occluded[1])
