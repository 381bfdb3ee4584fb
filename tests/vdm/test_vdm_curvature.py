"""Curvature resampling (appendix) and the MVM (§3.3) against analytic bent geometry."""
import math

import mitsuba as mi
import numpy as np

from mi_displace.vdm import curvature, mvm, table


def test_bend_stable_forms(variant):
    l = np.linspace(0.0, 0.8, 50)
    h = np.linspace(0.0, 0.2, 50)
    x0, y0 = curvature.bend(l, h, 0.0)
    np.testing.assert_array_equal(x0, l)
    np.testing.assert_array_equal(y0, -h)
    x1, y1 = curvature.bend(l, h, 1e-9)
    np.testing.assert_allclose(x1, l, atol=1e-12)
    np.testing.assert_allclose(y1, -h, atol=1e-12)
    for c in (-1.3, 0.7, 2.5):  # the naive form divides by c
        x, y = curvature.bend(l, h, c)
        np.testing.assert_allclose(x, (1 / c - h) * np.sin(c * l), atol=1e-12)
        np.testing.assert_allclose(y, (1 / c - h) * np.cos(c * l) - 1 / c, atol=1e-12)
    # Dr.Jit and NumPy agree
    xd, yd = curvature.bend(mi.Float(l), mi.Float(h), mi.Float(0.7))
    x, y = curvature.bend(l, h, 0.7)
    np.testing.assert_allclose(np.asarray(xd), x, atol=1e-5)
    np.testing.assert_allclose(np.asarray(yd), y, atol=1e-5)


def _resample(t_flat, n_rows, n_theta, curvs, D, src_over=1, floor_depth=None):
    d, m = curvature.resample(mi.Float(t_flat.ravel()), n_rows, table.theta_grid(n_theta * src_over),
                              table.theta_grid(n_theta), np.asarray(curvs), D, floor_depth)
    return np.asarray(d).reshape(n_rows, len(curvs), n_theta), np.asarray(m).reshape(n_rows, len(curvs))


def test_zero_curvature_reproduces_flat(variant):
    heights = np.random.default_rng(2).random((8, 8)).astype(np.float32)
    t = table.flat_distances(heights, 0.2, 8, 8)
    d, m = _resample(t, 8 * 64, 8, [0.0], 0.2)
    np.testing.assert_allclose(d[:, 0, :], t.reshape(-1, 8), rtol=2e-5, atol=1e-6)
    assert np.all(m == np.float32(math.pi / 2))


def test_constant_floor_on_a_sphere_is_analytic(variant):
    """H = 0.5 everywhere: bent, the mesostructure is a sphere of radius 1/c - D/2."""
    D, H, c, n_theta = 0.2, 0.5, 1.5, 8
    src = 8
    t = table.flat_distances(np.full((4, 4), H, np.float32), D, n_theta * src, 4)
    d, m = _resample(t, 4 * 16, n_theta, [c], D, src)
    h0 = D * (1 - H)
    R, r = 1 / c, 1 / c - h0
    mvm_true = math.asin(r / R)           # the ray tangent to the inner sphere
    # the largest kept bent angle approaches the tangent ray from below ...
    assert np.all(m[:, 0] <= mvm_true + 1e-5) and np.all(m[:, 0] > mvm_true - 1e-3)
    # ... and the floor bound (build passes D (1 - min H)) gives it exactly
    _, m_floor = _resample(t, 4 * 16, n_theta, [c], D, src, floor_depth=h0)
    np.testing.assert_allclose(m_floor[:, 0], mvm_true, atol=2e-6)
    for j, theta in enumerate(table.theta_grid(n_theta)):
        if theta > mvm_true:
            continue
        # ray from P = (0, R) towards the centre at angle theta: first hit on radius r
        b = R * math.cos(theta)
        s = b - math.sqrt(b * b - (R * R - r * r))
        qx, qy = s * math.sin(theta), R - s * math.cos(theta)
        l = R * math.atan2(qx, qy)         # arc length on the reference sphere
        np.testing.assert_allclose(d[:, 0, j], l / math.sin(theta), rtol=0.02)
    # the paper's raw table: -1 exactly beyond the MVM
    raw = mvm.with_invalid(d[:, 0, :], table.theta_grid(n_theta), m[:, 0])
    assert np.all((raw == -1) == (table.theta_grid(n_theta)[None, :] > mvm_true))


def test_concave_and_occlusion_rules(variant):
    heights = np.random.default_rng(3).random((8, 8)).astype(np.float32)
    t = table.flat_distances(heights, 0.3, 8, 8)
    d, m = _resample(t, 8 * 64, 8, [-2.0, 0.0, 3.0], 0.3)
    assert np.all(np.isfinite(d)) and np.all(d >= 0)
    assert np.all(m[:, 0] == np.float32(math.pi / 2))       # concave: every ray hits
    assert np.all(m[:, 2] < math.pi / 2)                      # convex: silhouettes exist
    # MVM decreases with curvature (rays escape more easily)
    d2, m2 = _resample(t, 8 * 64, 8, [0.5, 1.0, 2.0, 4.0], 0.3)
    assert np.all(np.diff(m2, axis=1) <= 1e-6)


# --- mutants that survived the tests above (scripts/mutation.sh, docs/testing.md) ---------

def test_depth_zero_resamples_to_zero(variant):
    """D = 0 (flat_distances' zeros): every curved distance is 0 (the chord r of l = 0) and
    every ray reaches the surface."""
    n_rows, n_theta = 16, 4
    d, m = _resample(np.zeros((n_rows, n_theta), np.float32), n_rows, n_theta, [-1.0, 0.0, 2.0], 0.0)
    np.testing.assert_array_equal(d, 0)
    assert np.all(np.isfinite(m)) and np.all(m > 0)


def test_sinc_and_curvature_grid(variant):
    x = np.array([0.0, 1e-5, 5e-5, 2e-4, 0.3, -2.0])
    np.testing.assert_allclose(curvature.sinc(x), np.where(x == 0, 1.0, np.sin(x) / np.where(x == 0, 1, x)),
                               rtol=1e-12)
    np.testing.assert_allclose(np.asarray(curvature.sinc(mi.Float(x))), curvature.sinc(x), rtol=1e-6)
    np.testing.assert_allclose(curvature.curvature_grid(-1.0, 2.0, 4), [-1.0, 0.0, 1.0, 2.0])
    np.testing.assert_allclose(curvature.curvature_grid(-1.0, 2.0, 1), [0.5])


def test_constant_floor_on_a_concave_sphere_is_analytic(variant):
    """c < 0 (centre of curvature above): the floor bends to a sphere of radius 1/|c| + h0
    outside the reference sphere; every ray hits it (MVM pi/2).  The bent angles start
    above the first table angle, where the first value is held."""
    D, H, c, n_theta, src = 0.2, 0.5, -1.5, 8, 1
    t = table.flat_distances(np.full((4, 4), H, np.float32), D, n_theta * src, 4)
    d, m = _resample(t, 4 * 16, n_theta, [c], D, src)
    assert np.all(m == np.float32(math.pi / 2))
    h0, R = D * (1 - H), 1 / abs(c)
    for j, theta in enumerate(table.theta_grid(n_theta)):
        # P = (0, -R) below the centre; the ray leaves the centre at angle theta
        b = R * math.cos(theta)
        s = -b + math.sqrt(b * b + (R + h0) ** 2 - R * R)
        qx, qy = s * math.sin(theta), -R - s * math.cos(theta)
        l = R * math.atan2(qx, -qy)
        # linear interpolation between bent pairs pi/16 apart (no oversampling): 3.5 %
        # at most, at the grazing sample; holding the wrong end at j = 0 is 280 % off
        np.testing.assert_allclose(d[:, 0, j], l / math.sin(theta), rtol=0.05)
