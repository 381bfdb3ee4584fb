"""Horizon mapping, relief mapping and the geometry masks against independent truth."""
import math
import re

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.vdm import horizon, relief
from mi_displace.vdm.frame import TiledHeight


def _brute_horizon(bilinear, heights, D, x, y, phi, max_distance):
    """Second implementation: dense NumPy march with bilinear periodic lookups."""
    res = heights.shape[0]
    r = np.arange(1, int(max_distance * res * 8) + 1) / (res * 8)
    hb = bilinear(heights, x + r * math.cos(phi), y + r * math.sin(phi))
    z0 = -D * (1 - heights[int(y * res), int(x * res)])
    return max(0.0, float(np.max(np.arctan2(-D * (1 - hb) - z0, r))))


def test_horizon_table(variant, bilinear):
    res, D = 16, 0.2
    np.testing.assert_allclose(horizon.horizon_table(np.full((res, res), 0.3, np.float32), D, 8), 0, atol=1e-5)
    u = (np.arange(res) + 0.5) / res
    heights = (0.5 + 0.5 * np.sin(2 * np.pi * u)[None, :] * np.cos(2 * np.pi * u)[:, None]).astype(np.float32)
    tab = horizon.horizon_table(heights, D, 8, max_distance=0.5)
    assert np.all(np.isfinite(tab)) and tab.min() >= 0 and tab.max() < math.pi / 2
    rng = np.random.default_rng(0)
    for _ in range(20):
        k, j, i = rng.integers(8), rng.integers(res), rng.integers(res)
        ref = _brute_horizon(bilinear, heights, D, (i + 0.5) / res, (j + 0.5) / res, 2 * math.pi * k / 8, 0.5)
        assert abs(tab[k, j, i] - ref) < 0.05, (k, j, i, tab[k, j, i], ref)


def _constant_texture(value):
    return mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.full((2, 2, 1), value, np.float32)),
                         "raw": True})


def test_relief_march_on_a_constant_floor(variant):
    """H constant: the ray meets the plane z = -D(1-H) at T - D(1-H) tan(theta) u."""
    H, D, n = 0.4, 0.3, 64
    height = TiledHeight(_constant_texture(H), (1.0, 1.0), 1e-3)
    theta = mi.Float(np.linspace(0.0, 1.3, n))
    phi = mi.Float(np.linspace(0.0, 6.0, n))
    T = mi.Point2f(0.3, 0.6)
    direction = mi.Vector2f(dr.cos(phi), dr.sin(phi))
    T2, depth = relief.march_view(height, T, dr.cos(theta), direction, D, 32, 10)
    h0 = D * (1 - H)
    np.testing.assert_allclose(np.asarray(depth), h0, atol=D / 32 / 2**10 * 2)
    off = h0 * np.tan(np.linspace(0.0, 1.3, n))
    np.testing.assert_allclose(np.asarray(T2.x), 0.3 - off * np.cos(np.linspace(0, 6, n)), atol=1e-3)
    # a constant floor casts no shadow on itself
    shadow = relief.march_shadow(height, T2, depth, dr.cos(theta), direction, D, 16)
    assert not np.any(np.asarray(shadow))


def test_searches_stop_early_with_the_full_searches_results(variant, rng):
    """The linear search of ``first_crossing`` and the shadow march stop a lane at its
    first sample below the relief and skip lanes outside ``active``: on the lanes read,
    bit for bit what the full, fixed-length loops (written out here) give."""
    n, steps, refine = 4000, 16, 5
    phase = mi.Float(rng.uniform(0, 2 * np.pi, n).astype(np.float32))
    active = mi.Bool(rng.uniform(size=n) < 0.7)
    below = lambda s: s >= 0.5 + 0.3 * dr.sin(7.0 * s + phase)
    lo, hi = (mi.Float(rng.uniform(*r, n).astype(np.float32)) for r in ((0, 0.3), (0.35, 0.9)))
    s, found = relief.first_crossing(below, lo, hi, steps, refine, active=active)
    ds, a, b, full = (hi - lo) / steps, mi.Float(lo), mi.Float(hi), dr.zeros(mi.Bool, n)
    for i in range(steps):                          # the full search, every lane, every step
        x = lo + mi.Float(i + 1) * ds
        hit = ~full & below(x)
        b, a, full = dr.select(hit, x, b), dr.select(~full & ~hit, x, a), full | hit
    for _ in range(refine):
        mid = 0.5 * (a + b)
        a, b = dr.select(below(mid), a, mid), dr.select(below(mid), mid, b)
    on = np.asarray(active)
    assert 0.2 < np.asarray(full)[on].mean() < 1.0            # both outcomes occur
    np.testing.assert_array_equal(np.asarray(found)[on], np.asarray(full)[on])
    np.testing.assert_array_equal(np.asarray(s)[on], np.asarray(0.5 * (a + b))[on])

    res, D, k = 32, 0.3, 24
    u = (np.arange(res) + 0.5) / res
    heights = (0.5 + 0.5 * np.sin(2 * np.pi * u)[None, :] * np.cos(4 * np.pi * u)[:, None]).astype(np.float32)
    height = TiledHeight(mi.load_dict({"type": "bitmap", "raw": True,
                                       "bitmap": mi.Bitmap(heights[..., None])}), (1.0, 1.0), 1e-3)
    T = mi.Point2f(*(mi.Float(rng.uniform(0, 1, n).astype(np.float32)) for _ in range(2)))
    h = mi.Float(rng.uniform(0, D, n).astype(np.float32))
    cos_l = mi.Float(rng.uniform(0.2, 1.0, n).astype(np.float32))
    angle = mi.Float(rng.uniform(0, 2 * np.pi, n).astype(np.float32))
    direction = mi.Vector2f(dr.cos(angle), dr.sin(angle))
    shadow = relief.march_shadow(height, T, h, cos_l, direction, D, k, active)
    tan_l = dr.sqrt(dr.maximum(1.0 - cos_l * cos_l, 0.0)) / cos_l
    full = dr.zeros(mi.Bool, n)
    for i in range(k):                              # the full march
        depth = h * (1.0 - mi.Float(i + 1) / (k + 1))
        Ts = mi.Point2f(T.x + (h - depth) * tan_l * direction.x, T.y + (h - depth) * tan_l * direction.y)
        full |= depth > D * (1.0 - height.value(Ts)) + 0.5 * D / k
    assert 0.1 < np.asarray(full)[on].mean() < 0.9
    np.testing.assert_array_equal(np.asarray(shadow), np.asarray(full) & on)


@pytest.mark.parametrize("plugin", ["horizon", "relief"])
def test_baseline_plugins_depth_zero_and_bad_input(variant, plugin):
    mat = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.6}}

    def scene(bsdf):
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "raster"},
            "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, -4, 1], target=[0, 0, 0], up=[0, 0, 1]),
                "film": {"type": "hdrfilm", "width": 32, "height": 32}},
            "key": {"type": "point", "position": [3, -2, 2], "intensity": {"type": "rgb", "value": 20}},
            "shape": {"type": "vdm_mesh", "base": "sphere", "resolution": 24, "bsdf": bsdf}})

    bsdf = {"type": plugin, "height": {"type": "cells", "cells": 2}, "depth": 0.0,
            "tiling_u": 8, "tiling_v": 4, "nested": mat}
    a = np.asarray(mi.render(scene(bsdf)))
    b = np.asarray(mi.render(scene(mat)))
    np.testing.assert_allclose(a, b, atol=1e-5)
    bsdf["depth"] = 0.1
    c = np.asarray(mi.render(scene(bsdf)))
    assert np.all(np.isfinite(c)) and np.abs(c - b).max() > 0.01
    with pytest.raises(Exception, match="depth"):
        scene(dict(bsdf, depth=-1.0))


@pytest.mark.parametrize("plugin", ["horizon", "relief"])
def test_baseline_errors_name_their_own_plugin(variant, plugin):
    own = {"horizon": {"azimuths": 2}, "relief": {"steps": 0}}[plugin]
    for bad, name in ((own, next(iter(own))), ({"tiling_u": 0}, "tiling_u"),
                      ({"height": _constant_texture(3.0), "tile_size": 1.0}, "height")):
        props = dict({"type": plugin, "height": _constant_texture(0.5), "depth": 0.1}, **bad)
        with pytest.raises(Exception) as caught:
            mi.load_dict(props)
        assert re.search(rf"{plugin}: (parameter )?'{name}'", str(caught.value)), str(caught.value)
        assert "vdm:" not in str(caught.value)


@pytest.mark.parametrize("bad, bounds", [({"tiling_u": 0}, "(0, inf)"),
                                         ({"steps": 5000}, "[1, 4096]")])
def test_range_errors_print_both_bounds(variant, bad, bounds):
    """An open bound reads as infinity, never as 'None'."""
    props = dict({"type": "relief", "height": _constant_texture(0.5), "depth": 0.1}, **bad)
    name, value = next(iter(bad.items()))
    with pytest.raises(Exception) as caught:
        mi.load_dict(props)
    assert f"relief: parameter '{name}' must lie in {bounds}, got {value}" in str(caught.value)
