"""Zero-curvature VDM by ray casting (paper §3.1) against analytic and brute-force truth."""
import math
import re

import numpy as np
import pytest

from mi_displace.vdm import build, table


def test_constant_height_is_analytic(variant):
    D, H = 0.2, 0.3
    t = table.flat_distances(np.full((8, 8), H, np.float32), D, 6, 8)
    theta = table.theta_grid(6)
    expected = D * (1 - H) / np.cos(theta)
    assert np.all(t >= 0)
    np.testing.assert_allclose(t, np.broadcast_to(expected, t.shape), rtol=1e-4, atol=1e-6)


def _brute_force(bilinear, heights, D, x, y, theta, phi, step=1e-4):
    """March the ray through the bilinear periodic height field (second implementation)."""
    s = np.arange(1, int(20 / step)) * step
    px = x - s * math.sin(theta) * math.cos(phi)
    py = y - s * math.sin(theta) * math.sin(phi)
    pz = -s * math.cos(theta)
    hb = bilinear(heights, px, py)
    below = pz <= -D * (1 - hb)
    return s[np.argmax(below)]


def _ripples(res=32):
    u = (np.arange(res) + 0.5) / res
    return (0.5 + 0.5 * np.sin(2 * np.pi * u)[None, :] * np.cos(2 * np.pi * u)[:, None]).astype(np.float32)


BRUTE_STEP = 1e-4


def _brute_samples(bilinear, heights, D, n_theta, n_phi, samples=60, seed=1):
    """Random table entries (phi, y, x, theta) with their brute-force distance and tolerance.

    The table traces two triangles per cell while the brute force marches the bilinear
    patch; the two differ vertically by at most dz = D |H00 + H11 - H10 - H01| / 4 per
    cell, i.e. dz / cos(theta) along a ray.  Tolerance: twice that (hits on slopes:
    measured up to 1.4x over 200 samples, docs/vdm.md) plus two march steps.
    """
    res = heights.shape[0]
    h = heights.astype(np.float64)
    dz = D * np.abs(h + np.roll(h, (-1, -1), (0, 1)) - np.roll(h, -1, 0) - np.roll(h, -1, 1)).max() / 4
    rng = np.random.default_rng(seed)
    thetas, phis = table.theta_grid(n_theta), table.phi_grid(n_phi)
    out = []
    for _ in range(samples):  # one brute-force march per sample (NumPy, vectorised along it)
        k, j, i, m = rng.integers(n_phi), rng.integers(res), rng.integers(res), rng.integers(n_theta)
        x = (i + 0.5 + table.NUDGE[0]) / res
        y = (j + 0.5 + table.NUDGE[1]) / res
        ref = _brute_force(bilinear, heights, D, x, y, thetas[m], phis[k], BRUTE_STEP)
        out.append(((k, j, i, m), ref, 2 * dz / math.cos(thetas[m]) + 2 * BRUTE_STEP))
    return out


def _worst_over_tolerance(t, samples) -> float:
    """max |t - t_brute| / tolerance over the samples of :func:`_brute_samples`."""
    return max(abs(t[idx] - ref) / tol for idx, ref, tol in samples)


def test_ripples_match_brute_force_march(variant, bilinear):
    D, heights = 0.15, _ripples()
    t = table.flat_distances(heights, D, 8, 8)
    assert np.all(t >= 0) and np.all(np.isfinite(t))
    samples = _brute_samples(bilinear, heights, D, 8, 8)
    assert _worst_over_tolerance(t, samples) < 1.0
    # fault injection: a table 10 % off, or 0.02 too long everywhere, fails the same check
    assert _worst_over_tolerance(1.1 * t, samples) > 1.0
    assert _worst_over_tolerance(t + 0.02, samples) > 1.0


def test_depth_zero_and_grazing(variant):
    heights = np.random.default_rng(0).random((16, 16)).astype(np.float32)
    assert np.all(table.flat_distances(heights, 0.0, 8, 8) == 0)
    # finest grid: last theta within 0.5 deg of grazing; deep relief; every ray still hits
    t = table.flat_distances(heights, 1.5, 90, 8)
    assert np.all(t >= 0) and np.all(np.isfinite(t))


def test_bad_heights_and_spec(variant):
    bad = np.ones((4, 4), np.float32)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        table.check_heights(bad)
    with pytest.raises(ValueError, match="depth"):
        build.check_spec(build.VDMSpec(res=4, depth=-0.1))
    with pytest.raises(ValueError, match="res"):
        build.check_spec(build.VDMSpec(res=0))
    with pytest.raises(ValueError, match="theta"):
        build.check_spec(build.VDMSpec(res=4, n_theta=1))
    with pytest.raises(ValueError, match="curvature range"):
        build.check_spec(build.VDMSpec(res=4, c_range=(1.0, -1.0)))


# --- mutants that survived the tests above (scripts/mutation.sh, docs/testing.md) ---------

class _LinearTexture:
    """A height texture H(u, v) = a u + b v, evaluated exactly (duck-typed: only ``eval_1``)."""

    def __init__(self, a, b):
        self.a, self.b = a, b

    def eval_1(self, si):
        return self.a * si.uv.x + self.b * si.uv.y


def test_sample_heights_divides_each_axis_by_its_own_tiling(variant):
    res, tiling = 4, (2.0, 4.0)
    h = table.sample_heights(_LinearTexture(0.5, 0.75), res, tiling)
    centres = (np.arange(res) + 0.5) / res
    expected = 0.5 * centres[None, :] / tiling[0] + 0.75 * centres[:, None] / tiling[1]
    assert h.shape == (res, res) and h.dtype == np.float32
    np.testing.assert_allclose(h, expected, rtol=1e-6)


def test_periodicity_warning_on_a_four_texel_wide_tile():
    # a ramp along x: its wrap-around jump is (n - 1) times the neighbour difference
    ramp = np.tile(np.linspace(0.0, 1.0, 64), (4, 1))
    message = table.periodicity_warning(ramp, "vdm", (1, 1))
    assert message is not None and "edge jump 63.0x" in message
    # below 4 texels the ratio says nothing (at most n - 1 < 4): no warning
    assert table.periodicity_warning(ramp[:3], "vdm", (1, 1)) is None
    assert table.periodicity_warning(np.tile(np.linspace(0.0, 1.0, 4), (64, 1)), "vdm", (1, 1)) is None


def test_heights_just_outside_the_unit_interval_are_clipped_not_refused():
    tol = table.HEIGHT_TOLERANCE
    h = np.array([[-0.9 * tol, 0.5], [0.25, 1 + 0.9 * tol]], np.float32)
    np.testing.assert_array_equal(table.check_heights(h), [[0.0, 0.5], [0.25, 1.0]])
    for bad, shown in ((-2 * tol, "-0.002..1"), (1 + 2 * tol, "0..1.002")):
        h = np.array([[0.0, 1.0], [0.5, bad]], np.float32)
        message = (f"vdm: 'height' values must lie in [0, 1] (1 = the reference surface), got "
                   f"{shown}; rescale the height map (or use 'depth')")
        with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
            table.check_heights(h)
