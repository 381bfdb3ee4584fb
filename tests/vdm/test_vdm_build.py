"""The table build (paper §3.1 -> appendix -> §3.3) against analytic tables, direct
residuals and its documented limits (issue 19: mutants of vdm/build.py)."""
import math
import re

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.vdm import build, table


def test_spec_defaults_are_the_plugin_defaults(variant):
    """VDMSpec() (the library's entry point) builds what the vdm plugin builds by default."""
    bsdf = mi.load_dict({"type": "vdm", "height": {"type": "cells"}})
    default = build.VDMSpec()
    for name in ("res", "n_theta", "n_phi", "n_curv", "theta_oversample"):
        assert getattr(default, name) == getattr(bsdf.spec, name), name


@pytest.mark.parametrize("field,name,low,high", [
    ("res", "res", 1, 1024), ("n_theta", "theta", 2, 64), ("n_phi", "phi", 4, 256),
    ("n_curv", "curvatures", 1, 64), ("theta_oversample", "theta_oversample", 1, 8)])
def test_integer_sizes_are_checked_at_their_bounds(field, name, low, high):
    small = {"res": 1, "n_theta": 2, "n_phi": 4, "n_curv": 1, "theta_oversample": 1}
    # theta above 32 passes this check but not the pair limit (32^2 = 1024, below)
    for ok in (low, 32 if name == "theta" else high):
        assert getattr(build.check_spec(build.VDMSpec(**dict(small, **{field: ok}))), field) == ok
    for bad in (low - 1, high + 1, low + 0.5, True):
        message = f"vdm: '{name}' must be an integer [{low}, {high}], got {bad!r}"
        with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
            build.check_spec(build.VDMSpec(**dict(small, **{field: bad})))


def test_theta_pairs_limit():
    assert build.check_spec(build.VDMSpec(res=1, n_theta=32, theta_oversample=1)).n_theta == 32
    message = ("vdm: 'theta'^2 x 'theta_oversample' = 2048 exceeds 1024; lower 'theta' or "
               "'theta_oversample'")
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        build.check_spec(build.VDMSpec(res=1, n_theta=32, theta_oversample=2))


def test_single_curvature_when_the_range_is_a_point():
    """n_curv samples unless hi - lo <= 1e-9 max(1, |hi|) (then one: the midpoint)."""
    for lo, hi, n in [(0.0, 0.9e-9, 1), (0.0, 1.5e-9, 4), (1e3, 1e3 + 0.9e-6, 1),
                      (1e3, 1e3 + 1.5e-6, 4), (-2.0, 1.0, 4)]:
        c = build.VDMSpec(n_curv=4, c_range=(lo, hi)).curvatures()
        assert len(c) == n, (lo, hi)
        np.testing.assert_allclose(c[[0, -1]], [lo, hi] if n > 1 else [0.5 * (lo + hi)] * 2,
                                   rtol=0, atol=1e-15 * max(1.0, abs(hi)))


def test_constant_height_table_is_analytic(variant):
    """H = const: the stored block is h = d cos(theta) = D (1 - H) at every theta (module
    doc); the MVM is pi/2 where flat, asin(r / R) on a sphere of curvature c (the ray
    tangent to the floor, radius r = 1/c - D (1 - H), of the reference sphere R = 1/c)."""
    D, H, c = 0.2, 0.3, 1.5
    heights = np.full((4, 4), H, np.float32)
    flat = build.build(heights, build.VDMSpec(res=4, n_theta=8, n_phi=4, depth=D))
    rec = flat.compressed.reconstruct(9, 9)          # 9 columns: every term is stored
    np.testing.assert_allclose(rec[:, :8], D * (1 - H), rtol=1e-4)
    np.testing.assert_array_equal(flat.mvm_full, np.float32(math.pi / 2))
    bent = build.build(heights, build.VDMSpec(res=4, n_theta=8, n_phi=4, depth=D,
                                              c_range=(c, c)))
    R = 1 / c
    np.testing.assert_allclose(bent.mvm_full, math.asin((R - D * (1 - H)) / R), atol=2e-6)
    # the uncompressed table is float32 VDM + MVM: (n_theta + 1) values per row and curvature
    assert flat.table_bytes() == 4 * 4 * 4 * (8 + 1) * np.dtype(np.float32).itemsize
    # 16 weight columns are stored (svd_terms, mvm_terms <= 16, docs/vdm.md), fewer only
    # where the table has fewer columns (2 curvatures x 9 = 18 here; 9 above)
    two = build.build(heights, build.VDMSpec(res=4, n_theta=8, n_phi=4, n_curv=2, depth=D,
                                             c_range=(0.0, c)))
    assert (two.compressed.k_stored, flat.compressed.k_stored) == (16, 9)


def test_reconstruction_rmse_is_the_direct_residual(variant):
    """With every term stored (9 columns <= 16) the full table is known: the RMSE at k
    terms is the plain residual of each block."""
    heights = np.random.default_rng(5).random((4, 4)).astype(np.float32)
    data = build.build(heights, build.VDMSpec(res=4, n_theta=8, n_phi=4, depth=0.2))
    full = data.compressed.reconstruct(9, 9)
    np.testing.assert_allclose(full[:, 8:], data.mvm_full, atol=1e-5)
    for k, m in ((1, 1), (3, 2), (6, 4)):
        rec = data.compressed.reconstruct(k, m)
        rv, rm = data.reconstruction_rmse(k, m)
        np.testing.assert_allclose(rv, np.sqrt(np.mean((rec[:, :8] - full[:, :8]) ** 2)), rtol=1e-3)
        np.testing.assert_allclose(rm, np.sqrt(np.mean((rec[:, 8:] - data.mvm_full) ** 2)),
                                   rtol=1e-3, atol=1e-7)
