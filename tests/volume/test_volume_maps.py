"""Inverse displacement maps: closed-form inverses, D_k sampling, placement, composition."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest


from volume_helpers import points as _p, to_numpy as _np


RNG = np.random.default_rng(7)
M_ROT = np.array([[0.0, -1.2, 0, 0.3], [0.9, 0, 0, -0.2], [0, 0, 1.1, 0.1], [0, 0, 0, 1]])


def _to_world(m, l):
    return l @ m[:3, :3].T + m[:3, 3]


@pytest.mark.parametrize("kind", ["wave", "gaussian", "seam", "slabs", "peel"])
def test_exact_inverse_undoes_the_closed_form_forward_map(variant, kind):
    """G(F(p)) = p with F the forward map in closed form, placed by a rotation + scale M."""
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap(kind, to_world=M_ROT)
    q = m.params
    l = RNG.uniform(0.05, 0.95, (4000, 3))
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
def test_peel_inverse_undoes_its_forward_map(variant, params):
    """The curling peel (and the rigid hinge, curl 0) with the hinge inside the cube: lid,
    the squeezed part right of the hinge and (radius 0.6) the fade zone all come back; the
    lid's underside turns by θ(r) + atan(r θ'(r)) > 90° at the radius when fully curled."""
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("peel", {"hinge": 0.7, "height": 0.4, **params}, to_world=M_ROT)
    l = RNG.uniform(0.0, 1.0, (6000, 3))
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
    """D_k reproduces D between its nodes; quantisation error: 8 bit > 16 bit > float."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    pts = _p(_to_world(M_ROT, RNG.uniform(0.1, 0.9, (3000, 3))))
    exact = DisplacementChain([PlacedMap("gaussian", to_world=M_ROT)]).exact(pts)
    errors = {}
    for bits in (8, 16, 32):
        chain = DisplacementChain([PlacedMap("gaussian", to_world=M_ROT, resolution=(48, 48, 48))], bits=bits)
        r = chain.approximate(pts)
        errors[bits] = np.abs(_np(r.p) - _np(exact.p)).max()
        scale = chain.sampled_maps()[0].scale
    assert errors[8] > errors[16] >= 0.99 * errors[32]
    assert errors[32] < 0.02 * scale                    # trilinear reconstruction of a smooth field
    assert errors[8] <= errors[32] + 1.5 * scale / 255  # 8-bit: at most a level and a half


def test_jacobian_texture_matches_finite_differences(variant):
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("wave", {"amount": 0.08, "frequency": 1.0}, to_world=M_ROT, resolution=(96, 16, 8))
    s = m.sampled(32, 0.0)
    # away from the window's kinks (x, y in 0.1 / 0.9) by more than one D_k voxel
    l = RNG.uniform(0.25, 0.75, (500, 3))
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


def test_zero_displacement_is_bit_identical(variant):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    pts = _p(RNG.uniform(-1, 1, (2000, 3)))
    maps = [PlacedMap("gaussian", {"amount": 0.0}, to_world=M_ROT), PlacedMap("wave", {"amount": 0.0})]
    for bits in (8, 16, 32):
        for comp in ("on_the_fly", "precomputed"):
            chain = DisplacementChain(maps, bits=bits, composition=comp)
            for r in (chain.exact(pts), chain.approximate(pts, True)):
                assert np.array_equal(_np(r.p), _np(pts))
                assert np.array(r.alpha).min() == 1.0
            B = np.array([np.array(r.B[i][j]) for i in range(3) for j in range(3)])
            assert np.array_equal(B, np.repeat(np.eye(3).ravel()[:, None], B.shape[1], 1))


def test_composition_is_not_commutative_and_both_compositions_agree(variant):
    """Fig. 5: wave then peel differs from peel then wave; on-the-fly ~ precomputed ~ exact."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    def maps():
        return [PlacedMap("wave", {"amount": 0.1, "frequency": 1.5}),
                PlacedMap("peel", {"angle": 40, "hinge": 0.8, "height": 0.6, "radius": 0.8})]

    pts = _p(RNG.uniform(0, 1, (4000, 3)))
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


def test_ten_maps_composed(variant):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    maps = [PlacedMap("wave", {"amount": 0.01, "frequency": 1 + i, "phase": 0.1 * i}) for i in range(10)]
    pts = _p(RNG.uniform(0.1, 0.9, (2000, 3)))
    exact = DisplacementChain(maps).exact(pts)
    approx = DisplacementChain(maps, bits=32).approximate(pts, True)
    assert np.isfinite(_np(approx.p)).all()
    err = np.abs(_np(approx.p) - _np(exact.p)).max(1)
    assert np.percentile(err, 99) < 0.005 and err.max() < 0.02   # ten trilinear D_k, 10 waves deep
    # the ten waves only move z: G(p') = p' + (0, 0, sum of waves in order)
    assert np.array_equal(_np(exact.p)[:, :2], _np(pts)[:, :2])


def test_proxy_grows_to_contain_displaced_matter(variant):
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    chain = DisplacementChain([PlacedMap("slabs", {"count": 3, "gap": 0.3})])
    lo, hi = chain.proxy_box([0, 0, 0], [1, 1, 1])
    assert hi[2] >= 1.6 - 1e-6                       # two gaps of 0.3 above the unit box
    # every p' whose pre-image lies in the box is inside the proxy
    pp = RNG.uniform(-0.5, 2.5, (20000, 3))
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
