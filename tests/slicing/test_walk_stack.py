"""The walks step from a slice polygon to the adjacent one over the same base triangle in
closed form (:class:`mi_displace.slicing.geometry.LayerStack`: direction a's slices k +- 1
and its top wall, b's / c's quads at the adjacent iso-levels), asking the BVH only where the ray leaves that
prism: against its second implementation, the walk that asks the BVH for every polygon (the
family's stack removed)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.slicing import sliced
from mi_displace.slicing.trace import NO_FACE, step_past
from test_walk_reach import fields, random_rays, volume


@pytest.mark.parametrize("family", ["a", "b", "c"])
def test_step_is_the_polygon_the_bvh_finds(variant, family):
    vol = volume(family)
    slices, _, stack = vol.families[family]
    o, d = random_rays(20000, seed=11)
    pi = slices.scene.ray_intersect_preliminary(mi.Ray3f(o, d))
    face = pi.prim_index
    p = o + pi.t * d
    fn = slices.face_normal(face, pi.is_valid())
    ray = mi.Ray3f(p + step_past(p, fn, d, slices.length) * d, d)
    nxt = stack.next_face(face, fn, d, pi.is_valid())   # slices, and a's top wall
    on_stack = pi.is_valid() & (nxt != NO_FACE)
    stepped, t, u, v, tri = stack.step(nxt, ray, on_stack)
    bvh = slices.scene.ray_intersect_preliminary(ray, active=stepped)
    stepped, lanes = np.array(stepped), np.array(on_stack)
    # most steps stay in the prism: the closed form answers them
    assert lanes.sum() > 3000 and stepped.sum() > 0.5 * lanes.sum(), (stepped.sum(), lanes.sum())
    wall = lambda f: np.array(dr.gather(mi.UInt32, slices.flags, f, stepped) & 1) != 0
    into, out_of = wall(tri)[stepped], wall(face)[stepped]
    if family == "a":   # into the top wall (leaving the volume), and from it (entering)
        assert into.sum() > 100 and out_of.sum() > 100, (into.sum(), out_of.sum())
    else:   # b's / c's stacks hold no walls
        assert not (into | out_of).any()
    same = np.array(bvh.prim_index)[stepped] == np.array(tri)[stepped]
    assert same.mean() > 0.999, same.mean()
    gap = np.abs(np.array(bvh.t)[stepped][same] - np.array(t)[stepped][same])
    assert gap.max() < 1e-5 * float(slices.length[0])
    for a, b in ((bvh.prim_uv.x, u), (bvh.prim_uv.y, v)):
        assert np.abs(np.array(a) - np.array(b))[stepped][same].max() < 1e-4


def spot_volume(direction, scale=0.01, slices=12):
    """A user's base: Spot (a mesh with UV seams and hard edges), rotated, scaled
    non-uniformly and moved, in millimetres (the donut's volume is metres across); at
    ``scale`` 0.01 its prisms' corners spread up to 75 degrees apart."""
    from mi_displace.core.resources import data_path

    T = mi.ScalarTransform4f
    scene = mi.load_dict({"type": "scene", "spot": {
        "type": "slicing", "base": "mesh", "filename": str(data_path("spot/spot_triangulated.obj")),
        "scale": scale, "slices": slices, "direction": direction, "height": {"type": "bricks"},
        "to_world": T().translate([300, -120, 40]) @ T().rotate([1, 2, 0], 50) @ T().scale([900, 1100, 1000])}})
    return next(s for s in scene.shapes() if hasattr(s, "volume")).volume


def rays_around(vol, count, seed):
    """Rays from points within -0.5 .. 1.5 x the displacement along the base's vertex
    normals (its world positions), in every direction."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(vol.bm.positions), count)
    h = rng.uniform(-0.5, 1.5, count)[:, None] * vol.world_scale
    o = vol.bm.positions[pick] + h * vol.bm.normals[pick]
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    f32 = lambda x: x.T.astype(np.float32)
    return mi.Point3f(*f32(o)), mi.Vector3f(*f32(d))


def compare_walks(vol, o, d, choice, active, t_floor):
    """(stacked, BVH-only) :func:`fields` of ``vol.find``."""
    stacked = fields(vol.find(o, d, choice, active, t_floor))
    families = dict(vol.families)
    vol.families = {f: (slices, bound, None) for f, (slices, bound, _) in families.items()}
    try:
        return stacked, fields(vol.find(o, d, choice, active, t_floor))
    finally:
        vol.families = families


@pytest.mark.parametrize("direction, base", [("a", "donut"), ("b", "donut"), ("best", "donut"),
                                             ("a", "spot"), ("best", "spot"), ("a", "thick spot")])
def test_stacked_walk_finds_the_fragments_of_the_bvh_walk(variant, direction, base):
    """The same fragments as the BVH-only walk, to rounding, in all but a few rays: a ray
    that leaves the slab between two slices through a side where the volumes over
    neighbouring base triangles overlap (Spot's prisms' sides twist by up to 0.8 x the
    displacement at its sharp features; twice as thick, 12 of 20,000 rays, 4 before a's
    top wall joined its stacks) can come back to the stacked polygon and pass what the BVH
    walk stopped at."""
    if base == "donut":
        vol = volume(direction)
        o, d = random_rays(20000, seed=12)
    else:
        # best: fewer slices (its b / c counts follow, and their build is what takes time)
        vol = spot_volume(direction, 0.02 if base == "thick spot" else 0.01, 12 if direction == "a" else 4)
        o, d = rays_around(vol, 20000, 13)
    n = dr.width(o)
    choice = mi.UInt32(np.random.default_rng(4).integers(0, len(sliced.FAMILIES[direction]), n))
    active = mi.Bool(np.arange(n) % 5 != 0)
    size = float(vol.walls_scene.length[0])
    for t_floor in (None, mi.Float(np.random.default_rng(5).uniform(0, 0.05 * size, n).astype(np.float32))):
        stacked, queried = compare_walks(vol, o, d, choice, active, t_floor)
        found = queried[0]
        assert 0.2 < found.mean() < 0.9
        differ = stacked[0] != found
        both = found & stacked[0]
        for a, b in zip(stacked[1:], queried[1:]):   # p, uv, n, su, sv (where found)
            assert np.isfinite(a[:, stacked[0]]).all()
            scale = np.abs(b[:, found]).max()   # tangents are longer than unit vectors
            differ[both] |= (np.abs(a - b)[:, both] > 1e-4 * scale).any(0)
        assert np.count_nonzero(differ) <= 1e-3 * n, np.count_nonzero(differ)
