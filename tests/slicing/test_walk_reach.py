"""The slice walk with each query bounded by the previous step (``reach`` of
:func:`mi_displace.slicing.trace.first_passing_slice`, the self-shadow walk's
:data:`mi_displace.slicing.sliced.SHADOW_REACH`) against the unbounded walk, its second
implementation: the same polygons, distances and barycentrics, bit for bit."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.slicing import rasterised, sliced
from slicing_scenes import donut



def volume(direction):
    scene = mi.load_dict({"type": "scene", "obj": donut(direction)})
    return next(s for s in scene.shapes() if hasattr(s, "volume")).volume


def random_rays(count=4000, seed=3):
    """Rays from points in and around the displacement volume (the torus's surface, pushed
    up to 1.5 scale along its normal), in every direction."""
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(0, 2 * np.pi, (2, count))
    r = 0.4 + rng.uniform(-0.02, 0.12, count)
    o = np.c_[(1 + r * np.cos(b)) * np.cos(a), (1 + r * np.cos(b)) * np.sin(a), r * np.sin(b)]
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    f32 = lambda x: x.T.astype(np.float32)
    return mi.Point3f(*f32(o)), mi.Vector3f(*f32(d))


def fields(hit):
    return [np.array(f) for f in hit.fields()]


@pytest.mark.parametrize("direction", ["a", "b", "c", "best"])
@pytest.mark.parametrize("coherent", [False, True])
def test_bounded_walk_is_the_unbounded_walk(variant, direction, coherent):
    vol = volume(direction)
    o, d = random_rays()
    n = dr.width(o)
    choice = mi.UInt32(np.random.default_rng(4).integers(0, len(sliced.FAMILIES[direction]), n))
    active = mi.Bool(np.arange(n) % 7 != 0)
    ref = fields(vol.find(o, d, choice, active, coherent=coherent))
    assert 0.2 < ref[0].mean() < 0.9   # some rays find a fragment, some walk out
    # 0.5 (every bounded query short of the next polygon but the first: all retried),
    # the default's, and a bound much larger than a step
    for factor in (0.5, 1.5, 50.0):
        reach = dict.fromkeys(sliced.FAMILIES[direction], factor)
        got = fields(vol.find(o, d, choice, active, coherent=coherent, reach=reach))
        for a, b in zip(ref, got):
            assert np.array_equal(a, b, equal_nan=True), reach
    # from the proxy wall (a view walk's t_floor): the same too
    t_floor = mi.Float(np.random.default_rng(5).uniform(0, 0.1, n).astype(np.float32))
    ref = fields(vol.find(o, d, choice, active, t_floor, coherent))
    got = fields(vol.find(o, d, choice, active, t_floor, coherent, reach=dict.fromkeys("abc", 1.5)))
    for a, b in zip(ref, got):
        assert np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("direction", ["a", "best"])
def test_bounded_self_shadows_draw_the_same_frame(variant, helpers, monkeypatch, direction):
    sensor = helpers.look([0, -3.4, 2.2], [0, 0, -0.1], fov=38, res=48)
    monkeypatch.setattr(sliced, "SHADOW_REACH", dict.fromkeys("abc", 1.5))   # every family
    img, scene = helpers.render({**donut(direction), "bsdf": helpers.MATERIAL}, sensor)
    vol = next(s for s in scene.shapes() if hasattr(s, "volume")).volume
    hit = rasterised.draw(vol, mi.load_dict(sensor)).hit
    normal = vol.normal(hit)
    wl = dr.normalize(mi.Vector3f(0.4, -0.5, 0.75)) + dr.zeros(mi.Vector3f, dr.width(normal))
    lit = hit.found & (dr.dot(normal, wl) > 0)
    bounded = np.array(vol.occluded(hit, normal, wl, lit))
    monkeypatch.setattr(sliced, "SHADOW_REACH", None)
    plain = np.array(mi.render(scene))[..., :3]
    assert np.array_equal(img, plain)
    unbounded = np.array(vol.occluded(hit, normal, wl, lit))
    assert 10 < unbounded.sum() < np.array(lit).sum()
    assert np.array_equal(bounded, unbounded)
