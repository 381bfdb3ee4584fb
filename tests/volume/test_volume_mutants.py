"""Tests written for mutants of volume/ that survived the suite (issue 19; docs/testing.md,
"Bake, volume and slicing modules").  Each asserts numbers against an independent truth."""
import re

import numpy as np
import pytest
from volume_helpers import points as _p, to_numpy as _np

#: parameters of each primitive that put every feature well inside the sampled box
CASES = [("gaussian", {"amount": 0.4, "sigma": 0.2}),
         ("peel", {"angle": 50.0, "hinge": 0.8, "height": 0.4, "radius": 0.5}),
         ("slabs", {"count": 3.0, "gap": 0.2}),
         ("wave", {"amount": 0.1, "frequency": 1.5, "phase": 0.2}),
         ("seam", {"amount": 0.3})]


@pytest.mark.parametrize("kind,params", CASES)
def test_the_support_box_holds_every_displacement(variant, kind, params):
    # maps.support: outside the box D = 0 and alpha = 1, or D is constant along the open
    # axes (slabs do not depend on x, y, the wave not on z, the seam's opening stops
    # growing above z = 1); a grid over a box twice as large checks both
    from mi_displace.volume import maps

    q = maps.check_params(kind, params)
    lo, hi = maps.support(kind, q)
    g = [np.linspace(a - 0.6 * (b - a), b + 0.6 * (b - a), 41) for a, b in zip(lo, hi)]
    pts = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 3)
    d, alpha = maps.evaluate(kind, q, _p(pts))
    d, alpha = _np(d), np.array(alpha)
    open_axes = {"slabs": [0, 1], "wave": [2], "seam": [2]}.get(kind, [])
    closed = [a for a in range(3) if a not in open_axes]
    out = np.zeros(len(pts), bool)
    for a in closed:
        out |= (pts[:, a] < lo[a] - 1e-9) | (pts[:, a] > hi[a] + 1e-9)
    assert out.sum() > 1000 and (~out).sum() > 1000
    assert np.abs(d[out]).max() == 0 and alpha[out].min() == 1
    assert np.abs(d[~out]).max() > 0.05            # the box is not empty of displacement
    if open_axes:                                  # beyond the box along an open axis: D constant
        pc = pts.copy()
        pc[:, open_axes] = np.clip(pc[:, open_axes], lo[open_axes], hi[open_axes])
        dc, ac = maps.evaluate(kind, q, _p(pc))
        np.testing.assert_allclose(d, _np(dc), atol=1e-6)
        assert np.array_equal(alpha, np.array(ac))
    # and the box is tight: the last quarter of its last closed axis holds displacement
    a = closed[-1]
    top = ~out & (pts[:, a] > hi[a] - 0.25 * (hi[a] - lo[a]))
    assert np.abs(d[top]).max() > 0


def test_peel_is_continuous_across_the_cut_plane_beyond_the_hinge(variant):
    # §4.1: D is C0 wherever matter is kept; right of the hinge (x > hinge) the lid's
    # rotation fades to 0 at the cut plane, where the matter below does not move
    from mi_displace.volume import maps

    q = maps.check_params("peel", {"angle": 60.0, "hinge": 0.5, "height": 0.5, "radius": 1.0})
    x = np.linspace(0.55, 1.2, 27)
    for eps in (1e-3, 1e-4):
        up = np.stack([x, np.full_like(x, 0.5), np.full_like(x, 0.5 + eps)], 1)
        down = up * [1, 1, 0] + [0, 0, 0.5 - eps]
        du, au = maps.evaluate("peel", q, _p(up))
        dd, ad = maps.evaluate("peel", q, _p(down))
        assert np.abs(_np(dd)).max() == 0 and np.array(ad).min() == 1 and np.array(au).min() == 1
        # |D| is bounded by the arc length r * beta, beta <= angle of the ramp at phi ~ pi
        assert np.abs(_np(du)).max() < 10 * eps


def test_placement_messages_name_the_parameter_whole(variant):
    from mi_displace.volume.maps import Placement

    with pytest.raises(ValueError) as e:
        Placement(np.eye(3), what="maps[1].to_world")
    assert str(e.value) == "maps[1].to_world: expected a 4x4 matrix, got shape (3, 3)"
    m = np.eye(4)
    m[3, 0] = 0.5
    with pytest.raises(ValueError, match=re.escape("maps[1].to_world: M must be affine (last row 0 0 0 1)")):
        Placement(m, what="maps[1].to_world")
    assert np.allclose(Placement(np.diag([2.0, 3.0, 4.0, 1.0])).world_box([0, 0, 0], [1, 1, 1]),
                       [[0, 0, 0], [2, 3, 4]])


@pytest.mark.parametrize("kind,channels", [("gaussian", 4), ("wave", 3)])
def test_texture_bytes_count_the_non_zero_channels(variant, kind, channels):
    # gaussian: D = (0, 0, D_z(x, y, z)), no cut: D_z plus the three entries of J's row z;
    # wave: D_z(x, y) only, so J's row z has two entries; alpha = 1 and grad alpha = 0 are
    # not stored.  16 bit: 2 bytes a channel; the full format stores all 16 channels
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    m = PlacedMap(kind)
    for bits in (8, 16):
        s = m.sampled(bits, 1.5)
        voxels = int(np.prod(m.resolution))
        assert s.voxels == voxels
        assert s.nbytes() == voxels * channels * bits // 8
        assert s.nbytes(all_channels=True) == voxels * 16 * bits // 8
        assert DisplacementChain([m, PlacedMap(kind)], bits=bits).nbytes() == 2 * s.nbytes()


def _rotation(ax, ay, az):
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _texture_and_fd_jacobian(m, s, pw, h=1e-3):
    """(N, 3, 3) J read from the D_k ``s`` of map ``m`` at world points pw (N, 3), and the
    central differences (step h) of m's exact world D there."""
    jac, _ = s.derivatives(_p(pw))
    n = len(pw)
    # derivatives gives J^T; an all-zero entry may be a one-lane literal
    J = np.stack([np.broadcast_to(np.array(jac[j][i]), n) for i in range(3) for j in range(3)],
                 -1).reshape(-1, 3, 3)
    fd = np.zeros_like(J)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fd[:, :, k] = (_np(m.exact(_p(pw + e))[0]) - _np(m.exact(_p(pw - e))[0])) / (2 * h)
    return J, fd


def test_jacobian_of_an_obliquely_placed_map_matches_finite_differences(variant):
    # placed by a rotation about all three axes (and a non-uniform scale), the world D of the
    # wave has three non-zero components, so all nine entries of J are distinct
    from mi_displace.volume.displacement import PlacedMap

    m4 = np.eye(4)
    m4[:3, :3] = _rotation(0.5, -0.7, 0.9) @ np.diag([1.2, 0.8, 1.0])
    m4[:3, 3] = [0.1, -0.2, 0.3]
    m = PlacedMap("wave", {"amount": 0.08, "frequency": 1.0}, to_world=m4, resolution=(96, 16, 8))
    s = m.sampled(32, 0.0)
    l = np.random.default_rng(11).uniform(0.25, 0.75, (400, 3))
    pw = l @ m4[:3, :3].T + m4[:3, 3]
    J, fd = _texture_and_fd_jacobian(m, s, pw)
    assert (np.abs(fd).max(0) > 1e-3).all()          # all nine entries are live
    assert np.abs(J - fd).max() < 0.05 * np.abs(fd).max()


def test_peel_skips_its_undisplaced_cells(variant):
    # the peel (three stored channels: D_x, D_z, 1 - alpha) turns nothing farther than
    # 1.2 radius from its hinge: the corners of its support box are flagged all-zero and
    # skipped, and reading there gives D = 0, alpha = 1, J = 0
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("peel", {"angle": 60.0, "hinge": 1.0, "height": 0.5, "radius": 0.6})
    s = m.sampled(16, 1.5)
    assert s.nonzero is not None and 0.05 < 1 - s.flags.mean() < 0.9
    r = 1.2 * 0.6
    far = _p([[1 - 0.97 * r, 0.5, 0.5 + 0.97 * r], [1 + 0.97 * r, 0.2, 0.5 + 0.97 * r]])
    d, a = s.lookup(far)
    jac, ga = s.derivatives(far)
    assert np.abs(_np(d)).max() == 0 and np.array(a).min() == 1
    assert max(np.abs(np.array(jac[i][j])).max() for i in range(3) for j in range(3)) == 0


def _ball_volume(maps=(), mode="approximation", **kw):
    """The soft ball of test_volume_normals (density 1 for r < 0.15, ramp to 0 at r = 0.3)."""
    from mi_displace.volume.displacement import DisplacementChain
    from mi_displace.volume.field import DisplacedVolume
    from mi_displace.volume.objects import ObjectVolume

    n = 48
    c = (np.arange(n) + 0.5) / n - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    obj = ObjectVolume(np.clip((0.3 - r) / 0.15, 0, 1), [-0.5] * 3, [0.5] * 3, value_range=(0, 1))
    v = DisplacedVolume(obj, DisplacementChain(list(maps), bits=32), mode=mode, **kw)
    v.prepare()
    return v


def test_where_the_field_is_flat_every_normal_is_the_fallback(variant):
    # inside the ball's core the density is constant (gradient 0): no direction is defined,
    # and every method returns the caller's fallback, with its sign
    import mitsuba as mi

    v = _ball_volume(tf_low=0.0, tf_high=1.0)
    core = _p(np.random.default_rng(2).uniform(-0.05, 0.05, (50, 3)))
    for fallback in ([0.0, 0.0, 1.0], [0.6, -0.8, 0.0]):
        for method in ("gradient", "jacobian", "blend"):
            n = _np(v.normal(core, method, mi.Vector3f(fallback)))
            assert np.allclose(n, fallback, atol=1e-6), (method, fallback)


def test_majorant_is_the_tight_bound_of_sigma_t(variant):
    # density_scale * tau(largest voxel), raised by only 1e-5 relative (field docstring)
    v = _ball_volume(tf_low=0.2, tf_high=0.8, density_scale=7.0)
    pts = _p(np.random.default_rng(4).uniform(-0.3, 0.3, (20000, 3)))
    top = np.array(v.sigma_t(pts)).max()
    assert top == pytest.approx(7.0, rel=1e-5)          # the core reaches tau = 1
    assert top <= v.majorant() <= 7.0 * (1 + 1.5e-5)
    assert v.nbytes() == {"object": v.obj.nbytes(), "maps": 0}


def test_a_lookup_without_the_alpha_gradient_gives_the_same_blend_normals(variant):
    # normal(lookup=...) reuses a caller's D_k pre-image and reads the terms its method needs
    # itself: a lookup made without grad alpha gives the blend normals of none
    import mitsuba as mi

    from mi_displace.volume.displacement import PlacedMap

    v = _ball_volume([PlacedMap("slabs", {"count": 2, "gap": 0.15},
                                to_world=np.diag([1.0, 1.0, 0.6, 1.0]) + np.c_[np.zeros((4, 3)), [-.5, -.5, -.3, 0]])],
                     tf_low=0.0, tf_high=1.0)
    p = _p(np.random.default_rng(6).uniform(-0.3, 0.3, (2000, 3)))
    fb = mi.Vector3f(0, 0, 1)
    plain = v.chain.approximate(p, normals=True, alpha_gradient=False)
    assert plain.B is not None and plain.galpha is None
    for method in ("jacobian", "blend"):
        np.testing.assert_allclose(_np(v.normal(p, method, fb, lookup=plain)), _np(v.normal(p, method, fb)),
                                   atol=1e-6)
    full = v.chain.approximate(p, normals=True)
    np.testing.assert_allclose(_np(v.normal(p, "blend", fb, lookup=full)), _np(v.normal(p, "blend", fb)), atol=1e-6)


def test_parameter_edges_and_messages(variant):
    from mi_displace.volume import maps
    from mi_displace.volume.displacement import PlacedMap
    from mi_displace.volume.field import AlbedoField

    q = maps.check_params("gaussian", {"amount": 0.0})          # |amount| < 1 includes 0
    d, a = maps.evaluate("gaussian", q, _p([[0.5, 0.5, 0.5]]))
    assert np.abs(_np(d)).max() == 0
    assert maps.check_params("wave", {"amount": 0.9})["amount"] == 0.9   # the seam's bound is the seam's
    with pytest.raises(ValueError) as e:
        PlacedMap("wave", resolution=(1, 8, 8))
    assert str(e.value).startswith("wave resolution: ")
    v = _ball_volume()
    for bad in ([1.5, 0, 0], [-0.1, 0.5, 0.5], [np.nan, 0, 0]):
        with pytest.raises(ValueError) as e:
            AlbedoField(v, bad, [1, 1, 1])
        assert str(e.value) == f"albedo_low: an RGB albedo needs three values in [0, 1], got {np.asarray(bad, float)}"
    from mi_displace.volume.field import DisplacedVolume

    with pytest.raises(ValueError) as e:
        DisplacedVolume(v.obj, v.chain, tf_low=0.5, tf_high=0.5)
    assert str(e.value) == "tf_low/tf_high: need finite tf_low < tf_high, got 0.5, 0.5"


def test_world_box_of_an_uneven_box(variant):
    from mi_displace.volume.maps import Placement

    m = np.diag([2.0, 3.0, 4.0, 1.0])
    m[:3, 3] = [1, 0, -1]
    lo, hi = Placement(m).world_box([0, 1, 2], [1, 3, 5])
    assert np.allclose(lo, [1, 3, 7]) and np.allclose(hi, [3, 9, 19])


def test_alpha_gradient_texture_matches_finite_differences(variant):
    # grad alpha_s (world units) read from the D_k equals central differences of the alpha_s
    # the same lookup returns, on a slanted cut (the peel's wedge), placed by a scaled frame
    from mi_displace.volume.displacement import PlacedMap

    m4 = np.diag([1.3, 0.9, 1.1, 1.0])
    m = PlacedMap("peel", {"angle": 40.0, "hinge": 0.8, "height": 0.4, "radius": 0.6}, to_world=m4,
                  resolution=(48, 8, 48))
    s = m.sampled(32, 1.5)
    rng = np.random.default_rng(8)
    l = np.c_[rng.uniform(0.35, 0.75, 600), rng.uniform(0.3, 0.7, 600), rng.uniform(0.45, 0.75, 600)]
    pw = l @ m4[:3, :3].T
    _, alpha = s.lookup(_p(pw))
    _, ga = s.derivatives(_p(pw))
    a0 = np.array(alpha)
    keep = (a0 > 0.05) & (a0 < 0.95)
    assert keep.sum() > 50
    h = 2e-3
    fd = np.zeros((len(pw), 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fd[:, k] = (np.array(s.lookup(_p(pw + e))[1]) - np.array(s.lookup(_p(pw - e))[1])) / (2 * h)
    g = _np(ga)
    err = np.linalg.norm(g[keep] - fd[keep], axis=1)
    assert np.median(err) < 0.1 * np.median(np.linalg.norm(fd[keep], axis=1))


def test_jacobian_along_every_local_axis_of_the_seam(variant):
    # the seam's D_x depends on x, y and z (w = amount z sin(pi y)); on a grid of different
    # spacings per axis, each column of J (the derivative along each axis) matches central
    # differences of the exact D away from the gap
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("seam", {"amount": 0.15}, resolution=(40, 24, 16))
    s = m.sampled(32, 0.0)
    rng = np.random.default_rng(12)
    pw = np.c_[rng.uniform(0.72, 0.85, 400), rng.uniform(0.25, 0.75, 400), rng.uniform(0.25, 0.75, 400)]
    J, fd = _texture_and_fd_jacobian(m, s, pw)
    assert (np.abs(fd[:, 0, :]).max(0) > 0.02).all()           # dD_x/dx, /dy, /dz all live
    for k in range(3):
        assert np.abs(J[:, 0, k] - fd[:, 0, k]).max() < 0.1 * np.abs(fd[:, 0, k]).max(), k


def test_set_moves_the_map_and_the_proxy_holds_matter_moved_down(variant):
    # PlacedMap.set(to_world=...) re-places the map (exact D follows the new M); a wave moves
    # matter both up and down, so the proxy box grows on both sides of the object's box and
    # holds every p' whose pre-image lies in the box
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    m = PlacedMap("wave", {"amount": 0.2, "frequency": 1.0})
    shift = np.eye(4)
    shift[:3, 3] = [2.0, 0.0, 0.0]
    m.set(to_world=shift)
    l = np.random.default_rng(13).uniform(0.2, 0.8, (300, 3))
    d_local, _ = PlacedMap("wave", {"amount": 0.2, "frequency": 1.0}).exact(_p(l))
    d_moved, _ = m.exact(_p(l + [2.0, 0.0, 0.0]))
    np.testing.assert_allclose(_np(d_moved), _np(d_local), atol=1e-6)
    assert np.allclose(m.support_world()[0], [2, 0, 0])
    chain = DisplacementChain([PlacedMap("wave", {"amount": 0.2, "frequency": 1.0})])
    lo, hi = chain.proxy_box([0, 0, 0], [1, 1, 1])
    assert lo[2] < -0.1 and hi[2] > 1.1
    pp = np.random.default_rng(14).uniform(-0.5, 1.5, (20000, 3))
    r = chain.exact(_p(pp))
    pre = _np(r.p)
    inside = ((pre >= 0) & (pre <= 1)).all(1)
    assert ((pp[inside] >= lo - 1e-6) & (pp[inside] <= hi + 1e-6)).all()


def test_blend_is_eq_7_between_the_jacobian_and_the_cut_normal(variant):
    # eq. 7: n = normalize(w n_J - (1 - w) grad alpha_s / |grad alpha_s|), w = clip(2 alpha_s - 1)
    # where 1/2 < alpha_s < 1 (near a cut face) both terms count
    import mitsuba as mi

    from mi_displace.volume.displacement import PlacedMap

    m4 = np.diag([1.0, 1.0, 0.6, 1.0])
    m4[:3, 3] = [-0.5, -0.5, -0.3]
    v = _ball_volume([PlacedMap("slabs", {"count": 2, "gap": 0.15}, to_world=m4)], tf_low=0.0, tf_high=1.0)
    rng = np.random.default_rng(15)
    pts = np.c_[rng.uniform(-0.25, 0.25, (20000, 2)), rng.uniform(-0.04, 0.13, 20000)]
    p = _p(pts)
    fb = mi.Vector3f(0, 0, 1)
    r = v.chain.approximate(p, normals=True)
    a, ga = np.array(r.alpha), _np(r.galpha)
    n_j = _np(v.normal(p, "jacobian", fb))
    n_b = _np(v.normal(p, "blend", fb))
    w = np.clip(2 * a - 1, 0, 1)
    g = np.linalg.norm(ga, axis=1)
    field = np.array(v.smooth_field(p))
    use = (w > 0.1) & (w < 0.9) & (g > 1e-2) & (field > 0.05)
    assert use.sum() > 100
    want = w[:, None] * n_j - (1 - w[:, None]) * ga / np.maximum(g, 1e-30)[:, None]
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    assert np.abs(n_b[use] - want[use]).max() < 1e-4


def test_precomputed_composition_reads_one_composite_d_k(variant):
    """§6: "precomputed" reads one D_k of the whole chain (at composite_resolution, the
    plugin's default 64³ when not given), not one per map: its pre-images differ from the
    on-the-fly ones (a different sampling) while both stay close to the exact chain."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    def maps():
        return [PlacedMap("wave", {"amount": 0.1, "frequency": 1.5}),
                PlacedMap("gaussian", {"amount": 0.3, "sigma": 0.2})]

    pts = _p(np.random.default_rng(21).uniform(0.1, 0.9, (3000, 3)))
    fly = DisplacementChain(maps(), bits=32)
    pre = DisplacementChain(maps(), bits=32, composition="precomputed", composite_resolution=(40, 48, 56))
    assert len(fly.sampled_maps()) == 2
    (composite,) = pre.sampled_maps()
    assert tuple(composite.res) == (40, 48, 56)
    assert tuple(DisplacementChain(maps(), composition="precomputed").sampled_maps()[0].res) == (64, 64, 64)
    exact = _np(fly.exact(pts).p)
    p_fly, p_pre = _np(fly.approximate(pts).p), _np(pre.approximate(pts).p)
    assert not np.array_equal(p_fly, p_pre)
    assert np.median(np.linalg.norm(p_pre - exact, axis=1)) < 0.01
    assert np.median(np.linalg.norm(p_fly - exact, axis=1)) < 0.01


def test_sampled_map_resolution_error_names_the_d_k(variant):
    from mi_displace.volume import maps
    from mi_displace.volume.displacement import SampledMap

    with pytest.raises(ValueError, match="^D_k resolution"):
        SampledMap(lambda p: (p * 0, p.x * 0 + 1), maps.Placement(), np.zeros(3), np.ones(3), (1, 4, 4))


def test_placement_vector_to_world_is_the_linear_part(variant):
    """M v for a displacement vector: the 3x3 part of a general (non-symmetric) M, no
    translation, against NumPy."""
    import mitsuba as mi

    from mi_displace.volume.maps import Placement

    rng = np.random.default_rng(22)
    m = np.eye(4)
    m[:3, :3] = rng.normal(size=(3, 3)) + 3 * np.eye(3)
    m[:3, 3] = [0.5, -2.0, 1.0]
    v = rng.normal(size=(50, 3))
    got = _np(Placement(m).vector_to_world(mi.Vector3f(*(v[:, i] for i in range(3)))))
    np.testing.assert_allclose(got, v @ m[:3, :3].T, rtol=1e-5, atol=1e-5)


def test_changed_rebuilds_the_precomputed_composite(variant):
    """After a map edit, ``changed()`` drops the composite D_k: the next read is a composite
    of the edited chain (as a fresh chain's), not the stale one."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    def chain(amount):
        return DisplacementChain([PlacedMap("gaussian", {"amount": amount, "sigma": 0.2})], bits=32,
                                 composition="precomputed", composite_resolution=(24, 24, 24))

    pts = _p(np.random.default_rng(23).uniform(0.2, 0.8, (2000, 3)))
    edited = chain(0.2)
    before = _np(edited.approximate(pts).p)
    edited.maps[0].set({"amount": 0.5})
    edited.changed()
    after = _np(edited.approximate(pts).p)
    assert np.abs(after - before).max() > 0.01
    np.testing.assert_array_equal(after, _np(chain(0.5).approximate(pts).p))
