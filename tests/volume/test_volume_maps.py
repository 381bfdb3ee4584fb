"""Inverse displacement maps: closed-form inverses, D_k sampling, placement, composition."""
import re

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest


from volume_helpers import points as _p, to_numpy as _np


M_ROT = np.array([[0.0, -1.2, 0, 0.3], [0.9, 0, 0, -0.2], [0, 0, 1.1, 0.1], [0, 0, 0, 1]])


def _to_world(m, l):
    return l @ m[:3, :3].T + m[:3, 3]


@pytest.mark.parametrize("kind", ["wave", "gaussian", "seam", "slabs", "peel"])
def test_exact_inverse_undoes_the_closed_form_forward_map(variant, kind, rng):
    """G(F(p)) = p with F the forward map in closed form, placed by a rotation + scale M."""
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap(kind, to_world=M_ROT)
    q = m.params
    l = rng.uniform(0.05, 0.95, (4000, 3))
    x, y, z = l.T
    f = l.copy()
    if kind == "wave":
        f[:, 2] = z - q["amount"] * np.sin(2 * np.pi * (q["frequency"] * x + q["phase"])) * \
            np.clip(np.minimum(x, 1 - x) / 0.1, 0, 1) * np.clip(np.minimum(y, 1 - y) / 0.1, 0, 1)
    elif kind == "gaussian":
        s2 = 2 * q["sigma"] ** 2
        edge = np.exp(-0.25 / s2)
        g = np.maximum(np.exp(-((x - .5) ** 2 + (y - .5) ** 2) / s2) - edge, 0) / (1 - edge)
        z = z * (1 - q["amount"] * g)            # object points that the cube's z' in [0, 1] shows
        l[:, 2] = z
        f[:, 2] = z / (1 - q["amount"] * g)
    elif kind == "seam":
        w = q["amount"] * z * np.sin(np.pi * y)
        d = x - 0.5
        f[:, 0] = 0.5 + np.sign(d) * (w + np.abs(d) * (0.5 - w) / 0.5)
    elif kind == "slabs":
        n, gap = q["count"], q["gap"]
        f[:, 2] = z + np.minimum(np.floor(z * n), n - 1) * gap
    elif kind == "peel":
        f = _peel_forward(l, q)
    p_world, pp_world = _to_world(M_ROT, l), _to_world(M_ROT, f)
    d, alpha = m.exact(_p(pp_world))
    np.testing.assert_allclose(pp_world + _np(d), p_world, atol=2e-5)
    assert np.array(alpha).min() == 1.0                 # every displaced point has a pre-image


def _peel_forward(l, q):
    """The peel's forward map in closed form (maps.py): about the hinge, a point above the cut
    plane at distance r and polar angle φ (from -x towards +z) goes to angle φ + θ(r) on the
    lid side (φ <= 90°) and to (φ (90° - θ) + 180° θ) / 90° beyond it, at the same r;
    θ(r) = angle (1 - curl + curl min(r / radius, 1)), faded to 0 between radius and 1.2 radius."""
    u, w = l[:, 0] - q["hinge"], l[:, 2] - q["height"]
    r, phi = np.hypot(u, w), np.arctan2(w, -u)
    fade = np.clip((1.2 * q["radius"] - r) / (0.2 * q["radius"]), 0, 1)
    th = np.radians(q["angle"]) * (1 - q["curl"] + q["curl"] * np.minimum(r / q["radius"], 1)) * fade
    to = np.where(phi <= np.pi / 2, phi + th, (phi * (np.pi / 2 - th) + th * np.pi) / (np.pi / 2))
    moved = (w > 0) & (l[:, 1] >= 0) & (l[:, 1] <= 1)
    f = l.copy()
    f[moved, 0] = (q["hinge"] - r * np.cos(to))[moved]
    f[moved, 2] = (q["height"] + r * np.sin(to))[moved]
    return f


@pytest.mark.parametrize("params", [{"curl": 1.0}, {"curl": 0.0}, {"curl": 0.5, "angle": 85.0},
                                    {"curl": 1.0, "angle": 80.0, "radius": 0.6}])
def test_peel_inverse_undoes_its_forward_map(variant, params, rng):
    """The curling peel (and the rigid hinge, curl 0) with the hinge inside the cube: lid,
    the squeezed part right of the hinge and (radius 0.6) the fade zone all come back; the
    lid's underside turns by θ(r) + atan(r θ'(r)) > 90° at the radius when fully curled."""
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("peel", {"hinge": 0.7, "height": 0.4, **params}, to_world=M_ROT)
    l = rng.uniform(0.0, 1.0, (6000, 3))
    f = _peel_forward(l, m.params)
    assert (np.abs(f - l).max(axis=1) > 1e-3).mean() > 0.4             # most points move
    d, alpha = m.exact(_p(_to_world(M_ROT, f)))
    np.testing.assert_allclose(_to_world(M_ROT, f) + _np(d), _to_world(M_ROT, l), atol=3e-5)
    assert np.array(alpha).min() == 1.0
    # the underside (z = height, left of the hinge) as a curve: its direction at the radius
    q = m.params
    s = np.linspace(0.5, 1.0, 201) * q["radius"]
    under = _peel_forward(np.stack([q["hinge"] - s, np.full_like(s, 0.5), q["height"] + 1e-9 + 0 * s], -1), q)
    t = np.diff(under[:, [0, 2]], axis=0)
    turn = np.degrees(np.arctan2(t[-1, 1], -t[-1, 0]))
    expected = q["angle"] + np.degrees(np.arctan(np.radians(q["angle"]) * q["curl"]))  # θ(radius) = angle
    assert abs(turn - expected) < 1.0
    if q["curl"] == 1.0:
        assert turn > 90                                                 # turned over


def test_cuts_have_alpha_zero(variant):
    from mi_displace.volume.displacement import PlacedMap

    slabs = PlacedMap("slabs", {"count": 2, "gap": 0.2})
    _, a = slabs.exact(_p([[0.5, 0.5, 0.6], [0.5, 0.5, 0.4], [0.5, 0.5, 0.8]]))
    assert list(np.array(a)) == [0.0, 1.0, 1.0]        # the gap (0.5, 0.7) is the cut
    peel = PlacedMap("peel", {"angle": 60, "hinge": 1.0, "height": 0.5})
    # curled: at r = 1.2 from the hinge the wedge is (0, 60 * 1.2 / 1.5) = (0, 48) degrees
    # (30 degrees lies in it), at r = 0.3 it is (0, 12) (30 degrees is lid)
    wedge = [[1 - r * np.cos(np.radians(30)), 0.5, 0.5 + r * np.sin(np.radians(30))] for r in (1.2, 0.3)]
    d, a = peel.exact(_p(wedge + [[0.5, 0.5, 0.3]]))
    assert list(np.array(a)) == [0.0, 1.0, 1.0]
    # the C0 pseudo-inverse of §4.1: the gap maps onto the cut face (z = height) at the same r
    pre = np.array(wedge[0]) + _np(d)[0]
    assert abs(pre[2] - 0.5) < 1e-6 and abs(np.hypot(pre[0] - 1, pre[2] - 0.5) - 1.2) < 1e-5
    seam = PlacedMap("seam", {"amount": 0.2})
    _, a = seam.exact(_p([[0.5, 0.5, 1.0], [0.5, 0.5, 0.0], [0.9, 0.5, 1.0]]))
    assert list(np.array(a)) == [0.0, 1.0, 1.0]


def test_sampled_map_matches_exact_and_bits_order(variant):
    """D_k reproduces D between its nodes; quantisation moves D_k by at most half a level.

    The quantised maps are compared with the float map (not with D): against D, the trilinear
    reconstruction error can cancel a level's rounding at the worst point, so 8 bit beating
    16 bit there is not a property."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    rng = np.random.default_rng(11)                       # this test's own points, not the order's
    pts = _p(_to_world(M_ROT, rng.uniform(0.1, 0.9, (3000, 3))))
    exact = _np(DisplacementChain([PlacedMap("gaussian", to_world=M_ROT)]).exact(pts).p)
    moved = {}
    for bits in (8, 16, 32):
        chain = DisplacementChain([PlacedMap("gaussian", to_world=M_ROT, resolution=(48, 48, 48))], bits=bits)
        moved[bits] = _np(chain.approximate(pts).p)
        scale = chain.sampled_maps()[0].scale
    assert np.isfinite(np.stack(list(moved.values()))).all()
    assert np.abs(moved[32] - exact).max() < 0.02 * scale     # trilinear reconstruction of a smooth field
    q8, q16 = (np.abs(moved[b] - moved[32]).max() for b in (8, 16))
    half8, half16 = scale / 254, scale / 65534                # snorm: 2^(bits-1) - 1 levels each side
    assert 0.5 * half8 < q8 <= 1.01 * half8 + 1e-6           # 8 bit: visible, within half a level
    assert q16 <= 1.01 * half16 + 1e-6
    assert q16 < q8 / 50


def test_jacobian_texture_matches_finite_differences(variant, rng):
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("wave", {"amount": 0.08, "frequency": 1.0}, to_world=M_ROT, resolution=(96, 16, 8))
    s = m.sampled(32, 0.0)
    # away from the window's kinks (x, y in 0.1 / 0.9) by more than one D_k voxel
    l = rng.uniform(0.25, 0.75, (500, 3))
    pw = _to_world(M_ROT, l)
    jac, _ = s.derivatives(_p(pw), False)
    # lookup gives Jᵀ; entries that are 0 in every lane (unstored channels) may be one literal lane
    J = np.stack([np.broadcast_to(np.array(jac[j][i]), 500) for i in range(3) for j in range(3)], -1).reshape(-1, 3, 3)
    h = 1e-3
    fd = np.zeros_like(J)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        dp, _ = m.exact(_p(pw + e))
        dm, _ = m.exact(_p(pw - e))
        fd[:, :, k] = (_np(dp) - _np(dm)) / (2 * h)
    assert np.abs(J - fd).max() < 0.05 * np.abs(fd).max()


@pytest.mark.parametrize("bad", [np.zeros((4, 4)), np.diag([1, 1, 0, 1.0]),
                                 np.where(np.eye(4) > 0, np.nan, 0.0), np.ones((3, 3))])
def test_bad_placement_is_refused(variant, bad):
    from mi_displace.volume.displacement import PlacedMap

    with pytest.raises(ValueError, match="to_world"):
        PlacedMap("wave", to_world=bad)


def test_bad_parameters_are_refused(variant):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    with pytest.raises(ValueError, match="unknown parameter"):
        PlacedMap("wave", {"amplitude": 1})
    with pytest.raises(ValueError, match="angle"):
        PlacedMap("peel", {"angle": 170})
    with pytest.raises(ValueError, match="invertible"):
        PlacedMap("gaussian", {"amount": 1.0})
    with pytest.raises(ValueError, match="not one of"):
        PlacedMap("twist")
    with pytest.raises(ValueError, match="limit"):
        PlacedMap("wave", resolution=(4096, 4096, 4096))
    with pytest.raises(ValueError, match="bits"):
        DisplacementChain([], bits=12)


def test_zero_displacement_is_bit_identical(variant, rng):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    pts = _p(rng.uniform(-1, 1, (2000, 3)))
    maps = [PlacedMap("gaussian", {"amount": 0.0}, to_world=M_ROT), PlacedMap("wave", {"amount": 0.0})]
    for bits in (8, 16, 32):
        for comp in ("on_the_fly", "precomputed"):
            chain = DisplacementChain(maps, bits=bits, composition=comp)
            for r in (chain.exact(pts), chain.approximate(pts, True)):
                assert np.array_equal(_np(r.p), _np(pts))
                assert np.array(r.alpha).min() == 1.0
            B = np.array([np.array(r.B[i][j]) for i in range(3) for j in range(3)])
            assert np.array_equal(B, np.repeat(np.eye(3).ravel()[:, None], B.shape[1], 1))


def test_composition_is_not_commutative_and_both_compositions_agree(variant, rng):
    """Fig. 5: wave then peel differs from peel then wave; on-the-fly ~ precomputed ~ exact."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    def maps():
        return [PlacedMap("wave", {"amount": 0.1, "frequency": 1.5}),
                PlacedMap("peel", {"angle": 40, "hinge": 0.8, "height": 0.6, "radius": 0.8})]

    pts = _p(rng.uniform(0, 1, (4000, 3)))
    ab = DisplacementChain(maps()).exact(pts)
    ba = DisplacementChain(maps()[::-1]).exact(pts)
    assert np.abs(_np(ab.p) - _np(ba.p)).max() > 0.05
    fly = DisplacementChain(maps(), bits=32, smoothing=0).approximate(pts)
    pre = DisplacementChain(maps(), bits=32, smoothing=0, composition="precomputed",
                            composite_resolution=(96, 96, 96)).approximate(pts)
    keep = (np.array(ab.alpha) == 1) & (np.array(fly.alpha) > 0.99) & (np.array(pre.alpha) > 0.99)
    err_fly = np.median(np.linalg.norm(_np(fly.p) - _np(ab.p), axis=1)[keep])
    err_pre = np.median(np.linalg.norm(_np(pre.p) - _np(ab.p), axis=1)[keep])
    assert err_fly < 0.01 and err_pre < 0.01


def test_ten_maps_composed(variant, rng):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    maps = [PlacedMap("wave", {"amount": 0.01, "frequency": 1 + i, "phase": 0.1 * i}) for i in range(10)]
    pts = _p(rng.uniform(0.1, 0.9, (2000, 3)))
    exact = DisplacementChain(maps).exact(pts)
    approx = DisplacementChain(maps, bits=32).approximate(pts, True)
    assert np.isfinite(_np(approx.p)).all()
    err = np.abs(_np(approx.p) - _np(exact.p)).max(1)
    assert np.percentile(err, 99) < 0.005 and err.max() < 0.02   # ten trilinear D_k, 10 waves deep
    # the ten waves only move z: G(p') = p' + (0, 0, sum of waves in order)
    assert np.array_equal(_np(exact.p)[:, :2], _np(pts)[:, :2])


def test_proxy_grows_to_contain_displaced_matter(variant, rng):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    chain = DisplacementChain([PlacedMap("slabs", {"count": 3, "gap": 0.3})])
    lo, hi = chain.proxy_box([0, 0, 0], [1, 1, 1])
    assert hi[2] >= 1.6 - 1e-6                       # two gaps of 0.3 above the unit box
    # every p' whose pre-image lies in the box is inside the proxy
    pp = rng.uniform(-0.5, 2.5, (20000, 3))
    r = chain.exact(_p(pp))
    pre = _np(r.p)
    inside = ((pre >= 0) & (pre <= 1)).all(1) & (np.array(r.alpha) == 1)
    assert ((pp[inside] >= lo - 1e-6) & (pp[inside] <= hi + 1e-6)).all()


def test_sparse_channels_and_zero_cells_read_what_the_full_texture_reads(variant):
    """ChannelTexture (only non-zero channels stored) reads bit for bit what a texture of all
    channels reads; every coordinate whose full read is non-zero lies in a flagged cell of
    nonzero_cells (a block of non-zero nodes in a zero grid, coordinates beyond the faces too)."""
    from mi_displace.volume.displacement import FLAG_NODES, ChannelTexture, nonzero_cells

    rng = np.random.default_rng(5)
    shape = (9, 12, 7)                                   # z, y, x nodes
    a = np.zeros((*shape, 9))
    a[3:6, 6:9, 2:4] = rng.uniform(-1, 1, (3, 3, 2, 9))
    a[..., [1, 4, 5]] = 0.0
    u = mi.Point3f(*(mi.Float(rng.uniform(-0.3, 1.3, 20000)) for _ in range(3)))
    sparse = ChannelTexture(a)
    assert sparse.stored == [0, 2, 3, 6, 7, 8]
    full = mi.Texture3f(mi.TensorXf(a.astype(np.float32)), use_accel=False,
                        filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp).eval(u)
    got = sparse.eval(u)
    assert all(np.array_equal(np.array(x), np.array(y)) for x, y in zip(got, full))
    flags = nonzero_cells(np.abs(a).max(-1) > 0)
    assert 0 < flags.mean() < 0.5
    n = np.array(shape[::-1], float)
    uu = np.stack([np.array(c) for c in u], -1)
    c = np.clip(np.floor((uu * n + 0.5) / FLAG_NODES), 0, np.array(flags.shape[::-1]) - 1).astype(int)
    nonzero = np.abs(np.stack([np.array(x) for x in full], -1)).max(-1) > 0
    assert 0.01 < nonzero.mean() < 0.5
    assert flags[c[:, 2], c[:, 1], c[:, 0]][nonzero].all()
    assert (~flags[c[:, 2], c[:, 1], c[:, 0]]).mean() > 0.3   # and most lanes may skip


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
