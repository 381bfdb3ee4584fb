"""Procedural height fields: values at hand-computed points, analytic gradients against
central finite differences, periodicity, range, finiteness, means, validation."""
import math

import mitsuba as mi
import numpy as np
import pytest


@pytest.fixture
def hf(variant):
    """The module under test, once ``variant`` (tests/conftest.py) has set a variant."""
    from mi_displace.core import heightfield
    return heightfield


def run(hf, name, u, v, **params):
    """``(h (N,), grad (2, N))`` as float64 NumPy arrays at float32 ``uv``."""
    h, g = hf.evaluate(name, mi.Point2f(np.ravel(u), np.ravel(v)), **params)
    return h.numpy().astype(np.float64), g.numpy().astype(np.float64)


# Each case: parameters, max |grad| (Lipschitz constant G) and max |d^3h/du^3| (M3),
# both per unit uv and derived by hand from the formulas in the docstrings.
#   ripples: G <= pi f_max,  M3 = 1/2 (2 pi f_max)^3
#   bricks:  G = 1.5 rows/bevel (max S' = 3/2),  M3 = 12 rows^3/bevel^3 (S''' = -12)
#   cells:   G = 4 (2/3) (1/sqrt 3) n/r (max at r = radius/sqrt 3),  M3 = 24 n^3/r^3
CASES = {
    "ripples": (dict(frequency=(3, 5), phase=0.7), math.pi * 5, 0.5 * (2 * math.pi * 5) ** 3),
    "bricks": (dict(rows=4, columns=2, mortar=0.1, bevel=0.3), 1.5 * 4 / 0.3,
               12 * 4 ** 3 / 0.3 ** 3),
    "cells": (dict(cells=4, radius=0.8, jitter=1.0, seed=3), 8 / (3 * math.sqrt(3)) * 4 / 0.8,
              24 * 4 ** 3 / 0.8 ** 3),
}
EPS = 1e-3


@pytest.mark.parametrize("name", CASES)
def test_gradient_matches_central_differences(hf, name):
    params, lipschitz, m3 = CASES[name]
    rng = np.random.default_rng(7)
    u, v = rng.random(20_000), rng.random(20_000)
    _, grad = run(hf, name, u, v, **params)
    fd = np.empty_like(grad)
    for axis, (du, dv) in enumerate([(EPS, 0.0), (0.0, EPS)]):
        hp, _ = run(hf, name, u + du, v + dv, **params)
        hm, _ = run(hf, name, u - du, v - dv, **params)
        fd[axis] = (hp - hm) / (2 * EPS)
    err = np.abs(fd - grad).max(axis=0)
    # Taylor remainder eps^2/6 * M3, plus float32 rounding: uv carries ~2^-24 relative
    # error, so each h is off by <= G 2^-23 (+ an ulp of h); the difference divides by 2 eps.
    tol = EPS ** 2 / 6 * m3 + (lipschitz + 1) * 2.0 ** -22 / EPS
    if name == "ripples":            # C-infinity: every point obeys the bound
        assert err.max() <= tol
    else:                            # creases / C1 ramp ends: a few % of stencils straddle one
        assert np.percentile(err, 95) <= tol
        assert np.median(err) <= tol
    assert err.max() <= 2 * lipschitz * (1 + 1e-3)   # |FD| <= G holds even across creases
    assert np.abs(grad).max() <= lipschitz * (1 + 1e-5)


@pytest.mark.parametrize("name", CASES)
def test_range_finite_and_periodic(hf, name):
    params, lipschitz, _ = CASES[name]
    t = np.linspace(0.0, 1.0, 257)           # includes 0, 1/2 and 1 exactly
    u, v = (x.ravel() for x in np.meshgrid(t, t))
    h, grad = run(hf, name, u, v, **params)
    assert np.all(np.isfinite(h)) and np.all(np.isfinite(grad))
    assert h.min() >= 0.0 and h.max() <= 1.0
    assert h.max() - h.min() > 0.5           # a real pattern, not a constant
    for ku, kv in [(1, 0), (0, 1), (-1, 0), (0, -1), (3, -2), (-7, 5)]:
        hs, _ = run(hf, name, u + ku, v + kv, **params)
        # u + k rounds to 2^-24 (1 + |k| + 1) in float32; h is G-Lipschitz.
        tol = lipschitz * 2.0 ** -23 * (2 + abs(ku) + abs(kv)) + 2.0 ** -22
        assert np.abs(hs - h).max() <= tol, (ku, kv)
    # u = 1 and u = 0 reduce to the same texel coordinate exactly.
    h0, _ = run(hf, name, np.zeros_like(t), t, **params)
    h1, _ = run(hf, name, np.ones_like(t), t, **params)
    np.testing.assert_array_equal(h0, h1)


def test_ripples_hand_values(hf):
    # f = (2, 3): a = 2 pi 2 u, b = 2 pi 3 v.  (1/8, 1/12): a = b = pi/2 -> crest, flat.
    h, g = run(hf, "ripples", [1 / 8, 1 / 8, 0.0], [1 / 12, 3 / 12, 1 / 12], frequency=(2, 3))
    np.testing.assert_allclose(h, [1.0, 0.0, 0.5], atol=1e-6)
    # (0, 1/12): sin a = 0, cos a = 1, sin b = 1 -> grad = (pi f_u, 0) = (2 pi, 0)
    np.testing.assert_allclose(g[:, 2], [2 * math.pi, 0.0], atol=1e-5)
    np.testing.assert_allclose(g[:, 0], [0.0, 0.0], atol=1e-5)


def test_bricks_hand_values(hf):
    p = dict(rows=4, columns=2, mortar=0.1, bevel=0.3)   # bricks 1/2 x 1/4 uv, W = 2 heights
    pts = [(0.25, 0.125),   # centre of brick (0, 0): stone top
           (0.0, 0.125),    # vertical joint of row 0
           (0.25, 0.375),   # row 1 is shifted by half a brick: its joint is at u = 1/4
           (0.5, 0.375),    # ... and its brick centre at u = 1/2
           (0.25, 0.05)]    # d = 0.2 heights -> t = (0.2 - 0.05)/0.3 = 1/2 -> S = 1/2
    h, g = run(hf, "bricks", *zip(*pts), **p)
    np.testing.assert_allclose(h, [1.0, 0.0, 0.0, 1.0, 0.5], atol=1e-6)
    # S'(1/2) / bevel * rows = 1.5 / 0.3 * 4 = 20, pointing up (+v) away from the v = 0 joint.
    np.testing.assert_allclose(g[:, 4], [0.0, 20.0], rtol=1e-5)
    np.testing.assert_allclose(g[:, 0], [0.0, 0.0], atol=1e-6)


def test_cells_hand_values(hf):
    p = dict(cells=4, radius=0.5, jitter=0.0)        # features at cell centres (i + 1/2)/4
    u = [0.125, 0.125 + 0.0625, 0.25, 0.125]         # centre, q = 1/4, cell border, v-offset
    v = [0.125, 0.125, 0.125, 0.125 - 0.0625]
    h, g = run(hf, "cells", u, v, **p)
    np.testing.assert_allclose(h, [1.0, 0.5625, 0.0, 0.5625], atol=1e-6)
    # grad = -4 (1 - q) (x - c) n / r^2 = -4 * 0.75 * 0.25 * 4 / 0.25 = -12 (cell units)
    np.testing.assert_allclose(g.T, [[0, 0], [-12, 0], [0, 0], [0, 12]], atol=1e-5)


def test_cells_deterministic_and_seeded(hf):
    rng = np.random.default_rng(0)
    u, v = rng.random(4096), rng.random(4096)
    a, _ = run(hf, "cells", u, v, seed=1)
    b, _ = run(hf, "cells", u, v, seed=1)
    c, _ = run(hf, "cells", u, v, seed=2)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.5


def test_means(hf):
    # ripples, closed form; non-integer frequency checked against the midpoint rule.
    assert hf.mean_ripples(frequency=4) == pytest.approx(0.5, abs=1e-12)
    p = dict(frequency=(0.5, 0.75), phase=0.3)   # mean 0.5646
    grid = hf.grid_mean(lambda uv: hf.ripples(uv, **p)[0], 1024)
    assert hf.mean_ripples(**p) == pytest.approx(grid, abs=2e-5)
    assert abs(hf.mean_ripples(**p) - 0.5) > 0.05
    # bricks: one square brick, no mortar, bevel 1/2 -> 6 B(2, 4) = 0.3 exactly.
    assert hf.mean_bricks(rows=1, columns=1, mortar=0.0, bevel=0.5) == pytest.approx(0.3, 1e-8)
    p = dict(rows=6, columns=4, mortar=0.1, bevel=0.2)
    grid = hf.grid_mean(lambda uv: hf.bricks(uv, **p)[0], 2048)
    assert hf.mean_bricks(**p) == pytest.approx(grid, abs=2e-4)
    # cells without overlap: one bump per cell of integral pi r^2 / 3.
    assert hf.mean_cells(cells=5, radius=0.45, jitter=0.0) == pytest.approx(
        math.pi * 0.45 ** 2 / 3, rel=1e-4)


def test_to_uv_chain_rule(hf):
    rng = np.random.default_rng(3)
    u, v = rng.random(1000), rng.random(1000)
    # scale by 2: h(uv) = h0(2 uv), grad = 2 grad0(2 uv)
    h, g = hf.evaluate("cells", mi.Point2f(u, v), hf.uv_affine(np.diag([2.0, 2.0, 1.0])))
    h0, g0 = run(hf, "cells", 2 * u, 2 * v)
    np.testing.assert_allclose(h.numpy(), h0, atol=1e-6)
    np.testing.assert_allclose(g.numpy(), 2 * g0, rtol=1e-5, atol=1e-4)
    # general affine map (shear + translation): gradient = A^T grad0(A uv + t)
    m = np.array([[1.5, 0.5, 0.3], [-0.25, 2.0, 0.1], [0, 0, 1]])
    h, g = hf.evaluate("ripples", mi.Point2f(u, v), hf.uv_affine(m), frequency=3)
    a_uv = m[:2, :2] @ np.stack([u, v]) + m[:2, 2:]
    h0, g0 = run(hf, "ripples", a_uv[0], a_uv[1], frequency=3)
    np.testing.assert_allclose(h.numpy(), h0, atol=1e-5)
    np.testing.assert_allclose(g.numpy(), m[:2, :2].T @ g0, rtol=1e-4, atol=1e-3)
    assert hf.uv_affine(mi.ScalarTransform4f()) is None


@pytest.mark.parametrize("name, params, match", [
    ("ripples", dict(frequency=0), "'frequency'"),
    ("ripples", dict(frequency=(1, -2)), "'frequency_v'"),
    ("ripples", dict(frequency=(1, 2, 3)), "'frequency'"),
    ("ripples", dict(phase=float("nan")), "'phase'"),
    ("bricks", dict(rows=2.5), "'rows'"),
    ("bricks", dict(columns=0), "'columns'"),
    ("bricks", dict(mortar=0.5), "'mortar'"),
    ("bricks", dict(mortar=-0.1), "'mortar'"),
    ("bricks", dict(bevel=0.0), "'bevel'"),
    ("bricks", dict(mortar=0.4, bevel=0.35), "'mortar' \\+ 2\\*'bevel'"),
    ("cells", dict(cells=1.5), "'cells'"),
    ("cells", dict(radius=1.2), "'radius'"),
    ("cells", dict(jitter=-0.1), "'jitter'"),
    ("cells", dict(seed=-1), "'seed'"),
    ("cells", dict(seed="x"), "'seed'"),
])
def test_bad_parameters_raise_before_kernels(hf, name, params, match):
    fn = hf.PATTERNS[name][0]
    with pytest.raises(ValueError, match=f"{name}: parameter {match}"):
        fn(mi.Point2f(0.5, 0.5), **params)


def test_bad_to_uv(hf):
    with pytest.raises(ValueError, match="'to_uv'"):
        hf.uv_affine(np.eye(2))
    with pytest.raises(ValueError, match="'to_uv'"):
        hf.uv_affine(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="unknown height pattern"):
        hf.evaluate("waves", mi.Point2f(0.5, 0.5))


# -- mutants that survived the tests above (docs/testing.md, mutation testing) ---------------


@pytest.mark.parametrize("name, params, message", [
    ("ripples", dict(frequency="x"), "ripples: parameter 'frequency' must be a number, got 'x'"),
    ("ripples", dict(frequency=0), "ripples: parameter 'frequency' must be finite and in (0, inf), got 0"),
    ("ripples", dict(phase=math.inf), "ripples: parameter 'phase' must be finite and in (-inf, inf), got inf"),
    ("ripples", dict(frequency=(1, 2, 3)),
     "ripples: parameter 'frequency' must be a number or a (u, v) pair, got (1, 2, 3)"),
    ("bricks", dict(mortar=0.5), "bricks: parameter 'mortar' must be finite and in [0, 0.5), got 0.5"),
    ("bricks", dict(rows=2.5), "bricks: parameter 'rows' must be an integer, got 2.5"),
    ("cells", dict(radius=1.5), "cells: parameter 'radius' must be finite and in (0, 1], got 1.5"),
    ("cells", dict(cells=(1 << 15) + 1),
     "cells: parameter 'cells' must be finite and in [1, 32768], got 32769"),
])
def test_bad_parameter_messages_are_exact(hf, name, params, message):
    """The whole message: pattern, parameter, the allowed interval with its open/closed ends."""
    with pytest.raises(ValueError) as caught:
        hf.PATTERNS[name][0](mi.Point2f(0.5, 0.5), **params)
    assert str(caught.value) == message


def test_cell_count_limit_is_the_32_bit_key_bound(hf):
    """Cell keys i + n j with n = 2^15 cells stay below 2^31: the largest count accepted."""
    h, _ = run(hf, "cells", [0.3], [0.7], cells=1 << 15)
    assert np.isfinite(h).all()
    with pytest.raises(ValueError, match="'cells'"):
        run(hf, "cells", [0.3], [0.7], cells=(1 << 15) + 1)


def test_defaults_are_the_documented_ones(hf):
    """The defaults the plugin docstrings (plugins/ripples.py, bricks.py, cells.py) state."""
    assert hf.pattern_defaults("ripples") == {"frequency": 8.0, "phase": 0.0}
    assert hf.pattern_defaults("bricks") == {"rows": 8, "columns": 4, "mortar": 0.1, "bevel": 0.15}
    assert hf.pattern_defaults("cells") == {"cells": 8, "radius": 0.5, "jitter": 1.0, "seed": 0}


def test_ripples_phase_shifts_the_u_wave(hf):
    """h = 1/2 + 1/2 sin(2 pi f_u u + phase) sin(2 pi f_v v), by hand at a non-zero phase."""
    u, v, phase = np.array([0.1, 0.35]), np.array([0.2, 0.05]), 0.5
    h, _ = run(hf, "ripples", u, v, frequency=(1, 2), phase=phase)
    expected = 0.5 + 0.5 * np.sin(2 * np.pi * u + phase) * np.sin(4 * np.pi * v)
    np.testing.assert_allclose(h, expected, atol=2e-6)


def test_pattern_functions_default_to_the_checked_defaults(hf):
    """Called without parameters, each pattern is the one its documented defaults give."""
    u, v = np.random.default_rng(6).random((2, 64))
    for name in ("ripples", "bricks", "cells"):
        plain = run(hf, name, u, v)
        explicit = run(hf, name, u, v, **hf.pattern_defaults(name))
        np.testing.assert_array_equal(plain[0], explicit[0])
        np.testing.assert_array_equal(plain[1], explicit[1])


@pytest.mark.parametrize("name, params, message", [
    ("cells", dict(jitter=1.5), "cells: parameter 'jitter' must be finite and in [0, 1], got 1.5"),
    ("cells", dict(seed=2**31), "cells: parameter 'seed' must be finite and in [0, 2147483647], "
                                "got 2147483648"),
    ("bricks", dict(mortar=0.4, bevel=0.35),
     "bricks: parameter 'mortar' + 2*'bevel' must be <= 1 (the joint and both ramps fit in one "
     "brick height), got 0.4 + 2*0.35"),
])
def test_more_bad_parameter_messages_are_exact(hf, name, params, message):
    with pytest.raises(ValueError) as caught:
        hf.PATTERNS[name][0](mi.Point2f(0.5, 0.5), **params)
    assert str(caught.value) == message


def test_largest_seed_is_accepted(hf):
    h, _ = run(hf, "cells", [0.3], [0.7], seed=2**31 - 1)
    assert np.isfinite(h).all()


def test_running_bond_repeats_every_two_rows(hf):
    """Odd rows are shifted by half a brick, even rows not: h(u, v) = h(u, v + 2/rows) for
    every row (rows 1 and 3 included), and rows 0 and 1 differ."""
    rows = 8
    u, v = np.random.default_rng(7).random((2, 400))
    v = v * (6 / rows)                                 # rows 0 to 5
    h, _ = run(hf, "bricks", u, v, rows=rows, columns=4)
    h2, _ = run(hf, "bricks", u, v + 2 / rows, rows=rows, columns=4)
    np.testing.assert_allclose(h, h2, atol=1e-5)
    h1, _ = run(hf, "bricks", u, v + 1 / rows, rows=rows, columns=4)
    assert np.abs(h - h1).max() > 0.5
