"""The walks step from a slice polygon to the adjacent one over the same base triangle in
closed form (:class:`mi_displace.slicing.geometry.LayerStack`: direction a's slices k +- 1,
b's / c's quads at the adjacent iso-levels), asking the BVH only where the ray leaves that
prism: against its second implementation, the walk that asks the BVH for every polygon (the
family's stack removed)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.slicing import sliced
from mi_displace.slicing.trace import step_past
from test_walk_reach import fields, random_rays, volume


@pytest.mark.parametrize("family", ["a", "b", "c"])
def test_step_is_the_polygon_the_bvh_finds(variant, family):
    vol = volume(family)
    slices, _, stack = vol.families[family]
    o, d = random_rays(20000, seed=11)
    pi = slices.scene.ray_intersect_preliminary(mi.Ray3f(o, d))
    face = pi.prim_index
    slice_hit = pi.is_valid() & (dr.gather(mi.UInt32, slices.flags, face, pi.is_valid()) == 0)
    p = o + pi.t * d
    fn = slices.face_normal(face, slice_hit)
    ray = mi.Ray3f(p + step_past(p, fn, d, slices.length) * d, d)
    nxt = stack.next_face(face, fn, d, slice_hit)
    stepped, t, u, v, tri = stack.step(nxt, ray, slice_hit)
    bvh = slices.scene.ray_intersect_preliminary(ray, active=stepped)
    stepped, lanes = np.array(stepped), np.array(slice_hit)
    # most steps stay in the prism: the closed form answers them
    assert lanes.sum() > 3000 and stepped.sum() > 0.5 * lanes.sum(), (stepped.sum(), lanes.sum())
    same = np.array(bvh.prim_index)[stepped] == np.array(tri)[stepped]
    assert same.mean() > 0.999, same.mean()
    gap = np.abs(np.array(bvh.t) - np.array(t))[stepped][same]
    assert gap.max() < 1e-5 * float(slices.length[0])
    for a, b in ((bvh.prim_uv.x, u), (bvh.prim_uv.y, v)):
        assert np.abs(np.array(a) - np.array(b))[stepped][same].max() < 1e-4


@pytest.mark.parametrize("direction", ["a", "b", "best"])
def test_stacked_walk_finds_the_fragments_of_the_bvh_walk(variant, direction):
    vol = volume(direction)
    o, d = random_rays(20000, seed=12)
    n = dr.width(o)
    choice = mi.UInt32(np.random.default_rng(4).integers(0, len(sliced.FAMILIES[direction]), n))
    active = mi.Bool(np.arange(n) % 5 != 0)
    for t_floor in (None, mi.Float(np.random.default_rng(5).uniform(0, 0.1, n).astype(np.float32))):
        stacked = fields(vol.find(o, d, choice, active, t_floor))
        families = dict(vol.families)
        vol.families = {f: (slices, bound, None) for f, (slices, bound, _) in families.items()}
        try:
            queried = fields(vol.find(o, d, choice, active, t_floor))
        finally:
            vol.families = families
        found = queried[0]
        assert 0.2 < found.mean() < 0.9
        assert np.array_equal(stacked[0], found)
        for a, b in zip(stacked[1:], queried[1:]):   # p, uv, n, su, sv (where found)
            assert np.isfinite(a[:, found]).all()
            scale = np.abs(b[:, found]).max()   # tangents are longer than unit vectors
            assert np.abs(a - b)[:, found].max() < 1e-5 * scale, np.abs(a - b)[:, found].max() / scale
