"""Render-time lookups of the compressed table (§3.3) against the NumPy reconstruction
W E^T of the same terms: texel centres, the interpolation along each axis, wrapping and
clamping (issue 19: mutants of vdm/lookup.py)."""
import math

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.vdm import build, lookup, table

RES, N_THETA, N_PHI, N_C = 8, 4, 8, 3
SVD, MVM = 4, 2


@pytest.fixture
def tables(variant, tmp_path, monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    heights = np.random.default_rng(7).random((RES, RES)).astype(np.float32)
    spec = build.VDMSpec(res=RES, n_theta=N_THETA, n_phi=N_PHI, n_curv=N_C, depth=0.2,
                         c_range=(-1.0, 2.0))
    data = build.build(heights, spec, use_cache=False)
    rec = data.compressed.reconstruct(SVD, MVM).astype(np.float64)
    # h[k, j, i, c, m] (VDM block, rows (phi, y, x), columns (c, theta)) and mvm[k, j, i, c]
    h = rec[:, :N_C * N_THETA].reshape(N_PHI, RES, RES, N_C, N_THETA)
    mvm = rec[:, N_C * N_THETA:].reshape(N_PHI, RES, RES, N_C)
    return data, lookup.VDMLookup(data, SVD, MVM), h, mvm


def _d(lk, x, y, theta, phi, c):
    f = lambda v: mi.Float(np.broadcast_to(np.asarray(v, np.float32), np.shape(x)).copy())
    return np.asarray(lk.d(mi.Point2f(f(x), f(y)), f(theta), f(phi), f(c)), np.float64)


def _mvm(lk, x, y, phi, c):
    f = lambda v: mi.Float(np.broadcast_to(np.asarray(v, np.float32), np.shape(x)).copy())
    return np.asarray(lk.mvm(mi.Point2f(f(x), f(y)), f(phi), f(c)), np.float64)


def _pos(a, b):
    """The lookup's h midway between two table entries: their mean, clipped at 0 (d >= 0)."""
    return np.maximum(0.5 * (a + b), 0.0)


def _centres():
    k, j, i = np.meshgrid(np.arange(N_PHI), np.arange(RES), np.arange(RES), indexing="ij")
    return k.ravel(), j.ravel(), i.ravel()


def test_texel_centres_give_the_table(tables):
    data, lk, h, mvm = tables
    k, j, i = _centres()
    x, y, phi = (i + 0.5) / RES, (j + 0.5) / RES, table.phi_grid(N_PHI)[k]
    thetas = table.theta_grid(N_THETA)
    for ci, c in enumerate(data.curvatures):
        for m, theta in enumerate(thetas):
            expected = np.maximum(h[k, j, i, ci, m], 0) / max(math.cos(theta), lookup.MIN_COS)
            np.testing.assert_allclose(_d(lk, x, y, theta, phi, c), expected, rtol=2e-4, atol=2e-5)
        np.testing.assert_allclose(_mvm(lk, x, y, phi, c), mvm[k, j, i, ci], atol=2e-5)
    assert lk.nbytes == data.compressed.nbytes(SVD, MVM)
    assert (lk.c_lo, lk.c_hi) == (-1.0, 2.0)
    # the largest sampled view angle (step 3 clamps light angles to it)
    np.testing.assert_allclose(lk.theta_max, thetas[-1], rtol=1e-12)


def test_interpolation_wrapping_and_clamping(tables):
    data, lk, h, mvm = tables
    k, j, i = _centres()
    x, y, phi = (i + 0.5) / RES, (j + 0.5) / RES, table.phi_grid(N_PHI)[k]
    theta, c = table.theta_grid(N_THETA)[1], data.curvatures[1]
    ct = math.cos(theta)
    hh = h[..., 1, 1]
    # half a texel along x and y (x = 1 - 1/(2 res) + 1/(2 res) wraps to the first texel),
    # half a phi step (the last wraps to phi = 0), whole periods of T are the same point
    np.testing.assert_allclose(_d(lk, x + 0.5 / RES, y, theta, phi, c) * ct,
                               _pos(hh[k, j, i], hh[k, j, (i + 1) % RES]), rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(_d(lk, x, y + 0.5 / RES - 3, theta, phi, c) * ct,
                               _pos(hh[k, j, i], hh[k, (j + 1) % RES, i]), rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(_d(lk, x, y, theta, phi + math.pi / N_PHI, c) * ct,
                               _pos(hh[k, j, i], hh[(k + 1) % N_PHI, j, i]), rtol=2e-4, atol=2e-5)
    # between two theta samples and two curvature samples: linear in each
    t_mid = 0.5 * (table.theta_grid(N_THETA)[1] + table.theta_grid(N_THETA)[2])
    np.testing.assert_allclose(_d(lk, x, y, t_mid, phi, c) * math.cos(t_mid),
                               _pos(h[k, j, i, 1, 1], h[k, j, i, 1, 2]), rtol=2e-4, atol=2e-5)
    c_mid = 0.5 * (data.curvatures[1] + data.curvatures[2])
    np.testing.assert_allclose(_d(lk, x, y, theta, phi, c_mid) * ct,
                               _pos(h[k, j, i, 1, 1], h[k, j, i, 2, 1]), rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(_mvm(lk, x, y, phi, c_mid),
                               0.5 * (mvm[k, j, i, 1] + mvm[k, j, i, 2]), atol=2e-5)
    # beyond the sampled ranges the lookups clamp: theta 0 and the first sample, c outside
    np.testing.assert_allclose(_d(lk, x, y, 0.0, phi, c), np.maximum(h[k, j, i, 1, 0], 0),
                               rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(_d(lk, x, y, theta, phi, 5.0) * ct, np.maximum(h[k, j, i, 2, 1], 0),
                               rtol=2e-4, atol=2e-5)
    np.testing.assert_allclose(_mvm(lk, x, y, phi, -4.0), mvm[k, j, i, 0], atol=2e-5)
    # the silhouette test reads the nearest texel: 0.4 texel off the centre changes nothing
    np.testing.assert_allclose(_mvm(lk, x + 0.4 / RES, y - 0.4 / RES, phi, c), mvm[k, j, i, 1],
                               atol=2e-5)


def test_grazing_views_divide_by_at_least_min_cos(tables):
    data, lk, h, _ = tables
    k, j, i = _centres()
    x, y, phi = (i + 0.5) / RES, (j + 0.5) / RES, table.phi_grid(N_PHI)[k]
    # at 90 deg the last theta sample is held (clamped) and cos is floored at MIN_COS
    got = _d(lk, x, y, math.pi / 2, phi, data.curvatures[0])
    np.testing.assert_allclose(got, np.maximum(h[k, j, i, 0, -1], 0) / lookup.MIN_COS,
                               rtol=2e-3, atol=2e-3)


def test_one_curvature_reads_its_only_column(variant, tmp_path, monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    H, D = 0.4, 0.2
    data = build.build(np.full((4, 4), H, np.float32),
                       build.VDMSpec(res=4, n_theta=4, n_phi=4, depth=D), use_cache=False)
    lk = lookup.VDMLookup(data, 2, 1)
    x = np.linspace(0.0, 1.0, 7)
    for c in (-3.0, 0.0, 3.0):
        for theta in table.theta_grid(4):   # constant height: d = D (1 - H) / cos(theta)
            np.testing.assert_allclose(_d(lk, x, x, theta, 1.0, c), D * (1 - H) / math.cos(theta),
                                       rtol=2e-4)
        np.testing.assert_allclose(_mvm(lk, x, x, 1.0, c), math.pi / 2, rtol=1e-5)


def test_cached_lookup_shares_textures_by_key(tables):
    data, lk, _, _ = tables
    lookup._CACHE.clear()
    first = lookup.cached_lookup(data, SVD, MVM)
    assert lookup.cached_lookup(data, SVD, MVM) is first
    assert lookup.cached_lookup(data, SVD, 1) is not first
    # no key (a table built outside the cache): a fresh lookup every time
    keyless = build.VDMData(data.spec, data.curvatures, data.compressed, data.mvm_full, {})
    assert lookup.cached_lookup(keyless, SVD, MVM) is not lookup.cached_lookup(keyless, SVD, MVM)
    # at most CACHE_ENTRIES tables, the least recently used dropped first
    for m in range(1, lookup.CACHE_ENTRIES + 2):
        lookup.cached_lookup(data, 1, m)
    assert len(lookup._CACHE) == lookup.CACHE_ENTRIES
    assert (data.stats["key"], 1, 1, mi.variant()) not in lookup._CACHE
    lookup._CACHE.clear()
