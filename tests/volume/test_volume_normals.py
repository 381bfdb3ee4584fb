"""Normals of §4.3: gradient (wrong), eq. 6 Jacobian, eq. 7 blend, finite differences; eq. 10."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from volume_helpers import points as _p, to_numpy as _np


def _ball(n=48):
    from mi_displace.volume.objects import ObjectVolume

    c = (np.arange(n) + 0.5) / n - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    return ObjectVolume(np.clip((0.3 - r) / 0.15, 0, 1), [-0.5] * 3, [0.5] * 3, value_range=(0, 1))


def _volume(maps, **kw):
    from mi_displace.volume.displacement import DisplacementChain
    from mi_displace.volume.field import DisplacedVolume

    v = DisplacedVolume(_ball(), DisplacementChain(maps, bits=32, **kw), mode="approximation",
                        tf_low=0.0, tf_high=1.0)
    v.prepare()
    return v


def _angle(a, b):
    return np.degrees(np.arccos(np.clip((_np(a) * _np(b)).sum(1), -1, 1)))


M_BOX = np.array([[1.0, 0, 0, -0.5], [0, 1, 0, -0.5], [0, 0, 1, -0.5], [0, 0, 0, 1]])


def test_jacobian_normals_follow_the_displaced_field(variant, rng):
    """eq. 6 agrees with finite differences of the displaced field; the undisplaced gradient
    does not (Fig. 4b)."""
    from mi_displace.volume.displacement import PlacedMap

    v = _volume([PlacedMap("wave", {"amount": 0.12, "frequency": 1.0}, to_world=M_BOX, resolution=(64, 64, 2))])
    pts = rng.uniform(-0.3, 0.3, (3000, 3))
    p = _p(pts)
    field = np.array(v.smooth_field(p))
    keep = (field > 0.1) & (field < 0.9)              # inside the soft shell, where ∇ is well defined
    fallback = mi.Vector3f(0, 0, 1)
    n = {m: v.normal(p, m, fallback) for m in ("gradient", "jacobian", "fd")}
    err_jac = np.median(_angle(n["jacobian"], n["fd"])[keep])
    err_grad = np.median(_angle(n["gradient"], n["fd"])[keep])
    assert err_jac < 3.0 and err_grad > 4 * err_jac
    for m in n.values():
        assert np.isfinite(_np(m)).all()


def test_blend_uses_the_alpha_gradient_on_the_cut_face(variant, rng):
    """eq. 7: at the cut face (α_s = 1/2) the normal is -∇α, here straight down into the gap."""
    from mi_displace.volume.displacement import PlacedMap

    # two slabs of the box, the upper one lifted by 0.1: the gap is z' in (0, 0.1)
    m = np.array([[1.0, 0, 0, -0.5], [0, 1, 0, -0.5], [0, 0, 1, -0.5], [0, 0, 0, 1]])
    v = _volume([PlacedMap("slabs", {"count": 2, "gap": 0.1}, to_world=m, resolution=(2, 2, 256))],
                smoothing=2.0)
    xy = rng.uniform(-0.1, 0.1, (400, 2))
    zs = np.linspace(0.05, 0.15, 801)                 # upper half of the gap and above
    p = _p(np.column_stack([np.repeat(xy, len(zs), 0), np.tile(zs, len(xy))]))
    alpha = np.array(v.chain.approximate(p).alpha).reshape(len(xy), len(zs))
    k = np.abs(alpha - 0.5).argmin(1)                 # the upper cut face: α_s crosses 1/2
    face = _p(np.column_stack([xy, zs[k]]))
    down = np.tile([0, 0, -1.0], (len(xy), 1))
    blend = _np(v.normal(face, "blend", mi.Vector3f(0, 0, 1)))
    jac = _np(v.normal(face, "jacobian", mi.Vector3f(0, 0, 1)))
    assert np.median((blend * down).sum(1)) > 0.95
    assert np.median((jac * down).sum(1)) < 0.5        # eq. 6 alone keeps the ball's radial normal


def test_singular_jacobians_give_finite_normals(variant, rng):
    """Inside the seam's gap D maps a slab onto a plane: det(I + J) = 0 there."""
    from mi_displace.volume.displacement import PlacedMap

    v = _volume([PlacedMap("seam", {"amount": 0.3}, to_world=M_BOX, resolution=(64, 64, 64))], smoothing=0.0)
    p = _p(np.column_stack([rng.uniform(-0.05, 0.05, 2000), rng.uniform(-0.2, 0.2, 2000),
                            rng.uniform(0.3, 0.5, 2000)]))
    r = v.chain.approximate(p, True)
    B = np.array([np.array(r.B[i][j]) for i in range(3) for j in range(3)]).T.reshape(-1, 3, 3)
    assert np.abs(np.linalg.det(B)).min() < 1e-3      # singular indeed
    for method in ("gradient", "jacobian", "blend", "fd"):
        n = _np(v.normal(p, method, mi.Vector3f(0, 0, 1)))
        assert np.isfinite(n).all()
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-4)


def test_composite_normal_matrix_is_the_chain_rule(variant, rng):
    """eq. 10 on the fly: the product of the maps' B equals (J of the composite G)ᵀ by FD."""
    from mi_displace.volume.displacement import DisplacementChain, PlacedMap

    maps = [PlacedMap("wave", {"amount": 0.1, "frequency": 1.0}, resolution=(128, 32, 2)),
            PlacedMap("gaussian", {"amount": 0.4, "sigma": 0.2}, resolution=(64, 64, 64))]
    chain = DisplacementChain(maps, bits=32, smoothing=0.0)
    pts = rng.uniform(0.3, 0.7, (400, 3))
    r = chain.approximate(_p(pts), True)
    B = np.array([np.array(r.B[i][j]) for i in range(3) for j in range(3)]).T.reshape(-1, 3, 3)
    h = 1e-3
    J = np.zeros((len(pts), 3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        J[:, :, k] = (_np(chain.exact(_p(pts + e)).p) - _np(chain.exact(_p(pts - e)).p)) / (2 * h)
    err = np.abs(B - J.transpose(0, 2, 1)).max((1, 2))
    assert np.median(err) < 0.02 and err.max() < 0.1


def _ball_volume(maps=(), **kw):
    """The soft ball of ``_ball`` under ``maps`` (32-bit D_k), approximated and prepared;
    ``kw`` go to DisplacedVolume (its transfer ramp is the default unless given)."""
    from mi_displace.volume.displacement import DisplacementChain
    from mi_displace.volume.field import DisplacedVolume

    v = DisplacedVolume(_ball(), DisplacementChain(list(maps), bits=32), mode="approximation", **kw)
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
