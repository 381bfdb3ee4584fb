"""Geometry images (§3.1), the shader-style lookup (§3.2), diffusion fill and pruning (§4.1)."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from scipy import ndimage

from mi_displace.core.surfaces import BaseSurface, SurfaceSample, make_base
from mi_displace.ddm import base_maps
from mi_displace.ddm.layout import make_layout
from mi_displace.ddm.model import DDMConfig, DDMModel


def _np(v):
    return np.stack([np.asarray(c) for c in v], 1)


def test_texels_hold_the_base_and_lookup_interpolates_them(variant):
    base = make_base("torus", major_radius=1.0, minor_radius=0.4)
    maps = base_maps.build_maps(base, 16, 12)
    u, v = base_maps.texel_coordinates(16, 12, True, True)
    s = base.sample(u, v)
    assert np.allclose(_np(maps.position), _np(s.p), atol=1e-6)
    p, n = maps.lookup(u, v)               # at texel coordinates: the texel values
    assert np.allclose(_np(p), _np(s.p), atol=1e-5)
    # midway between texels: the mean of the four neighbours (bilinear)
    p_mid, _ = maps.lookup(mi.Float(0.5 / 16), mi.Float(0.5 / 12))
    corners = base.sample(mi.Float([0, 1 / 16, 0, 1 / 16]), mi.Float([0, 0, 1 / 12, 1 / 12]))
    assert np.allclose(_np(p_mid)[0], _np(corners.p).mean(0), atol=1e-5)


def test_lookup_derivatives_match_finite_differences(variant):
    base = make_base("sphere", radius=1.3)
    maps = base_maps.build_maps(base, 32)
    rng = np.random.default_rng(1)
    # points away from texel edges so the finite difference stays inside one texel
    cell = rng.integers(1, 30, (200, 2))
    frac = rng.uniform(0.2, 0.8, (200, 2))
    u = mi.Float((cell[:, 0] + frac[:, 0]) / 32)
    v = mi.Float((cell[:, 1] + frac[:, 1]) / 31)
    _, _, (p_u, p_v, n_u, n_v) = maps.lookup(u, v, True)
    h = 1e-3 / 32
    for d, (du, dv) in ((p_u, (h, 0)), (p_v, (0, h))):
        a, _ = maps.lookup(u + du, v + dv)
        b, _ = maps.lookup(u - du, v - dv)
        fd = (_np(a) - _np(b)) / (2 * h)
        assert np.allclose(fd, _np(d), rtol=2e-2, atol=2e-2)
    a = maps.lookup(u + h, v)[1]
    b = maps.lookup(u - h, v)[1]
    assert np.allclose((_np(a) - _np(b)) / (2 * h), _np(n_u), atol=2e-2)


def test_periodic_maps_wrap_without_cracks(variant):
    base = make_base("torus", major_radius=1.0, minor_radius=0.3)
    maps = base_maps.build_maps(base, 24)
    v = mi.Float(np.linspace(0, 1, 50))
    for shift in (1.0, -1.0, 2.0):
        a, _ = maps.lookup(dr.zeros(mi.Float, 50) + 0.013, v)
        b, _ = maps.lookup(dr.zeros(mi.Float, 50) + 0.013 + shift, v + shift)
        assert np.allclose(_np(a), _np(b), atol=1e-5)
    a, _ = maps.lookup(dr.zeros(mi.Float, 50) + (1 - 1e-6), v)
    b, _ = maps.lookup(dr.zeros(mi.Float, 50), v)
    assert np.abs(_np(a) - _np(b)).max() < 1e-4


def test_diffusion_fill_finds_nearly_the_nearest_valid_texel():
    rng = np.random.default_rng(3)
    valid = ndimage.binary_dilation(rng.random((90, 70)) > 0.997, iterations=3)
    valid[40:50, 10:60] = True
    src, sweeps = base_maps.diffuse_fill(valid, False, False)
    yy, xx = np.mgrid[0:90, 0:70]
    d_ours = np.hypot(src // 70 - yy, src % 70 - xx)
    d_edt = ndimage.distance_transform_edt(~valid)
    assert np.all(valid.ravel()[src.ravel()])          # every texel points at a valid one
    assert np.array_equal(src[valid], np.flatnonzero(valid))
    assert np.all(d_ours >= d_edt - 1e-9)
    excess = d_ours - d_edt   # the diffusion approximates the distance transform (§4.1)
    assert np.mean(excess < 1e-6) > 0.9
    assert np.mean(excess) < 0.2 and np.percentile(excess, 99) < 4.0
    assert sweeps >= np.max(np.maximum(np.abs(src // 70 - yy), np.abs(src % 70 - xx)))


def test_diffusion_wraps_on_periodic_axes():
    valid = np.zeros((8, 20), bool)
    valid[:, 0] = True
    src, _ = base_maps.diffuse_fill(valid, True, False)
    assert np.all(src[:, 19] % 20 == 0)   # the right edge takes the column across the seam
    with pytest.raises(ValueError, match="no valid texel"):
        base_maps.diffuse_fill(np.zeros((4, 4), bool), False, False)


class _PinchedPlane(BaseSurface):
    """The plane with a NaN normal on a band of texels (degenerate normal map)."""
    name = "pinched"

    def sample(self, u, v):
        s = make_base("plane").sample(u, v)
        bad = (u > 0.4) & (u < 0.6)
        n = dr.select(bad, mi.Vector3f(dr.nan, dr.nan, dr.nan), s.n)
        return SurfaceSample(s.p, s.dp_du, s.dp_dv, n, s.dn_du, s.dn_dv)


def test_degenerate_normal_texels_are_invalid_and_filled(variant):
    maps = base_maps.build_maps(_PinchedPlane(), 21)
    assert maps.stats["invalid_texels"] == 21 * 3
    assert np.all(np.isfinite(_np(maps.normal)))
    p, n = maps.lookup(mi.Float([0.5, 0.45]), mi.Float([0.5, 0.2]))
    assert np.all(np.isfinite(_np(n))) and np.allclose(_np(n), [0, 0, 1])


def test_too_small_and_bad_resolutions(variant):
    # 1 texel put every vertex of a sphere on one point, 2 on a segment: refused
    for bad in (0, 1, 2, 3, -3, 2.5, base_maps.MAX_MAP_RESOLUTION + 1):
        with pytest.raises(ValueError, match="map_resolution"):
            base_maps.build_maps(make_base("sphere"), bad)
    with pytest.raises(ValueError, match="map_resolution.*collapse"):
        DDMModel(DDMConfig(base="sphere", tiles_u=4, tiles_v=2, map_resolution=1))
    # the smallest accepted one still encloses volume: 4 texels around the sphere
    maps = base_maps.build_maps(make_base("sphere"), base_maps.MIN_MAP_RESOLUTION)
    p, _ = maps.lookup(*base_maps.texel_coordinates(64, 64, True, False))
    p = _np(p)
    assert np.all(np.isfinite(p)) and np.ptp(p, 0).min() > 1.0


def test_pruning_counts_tiles_without_valid_texels(variant):
    maps = base_maps.build_maps(make_base("plane"), 40)
    maps.valid[:, 20:] = False            # right half invalid (texel columns 20..39)
    lay = make_layout("rect", 8, 4)
    kept, pruned = base_maps.prune(lay, np.array([[0.0, 0.0, 1.0, 1.0]]), maps)
    # tile columns 0..3 reach texel <= 20 (one-texel margin): columns 4.. are pruned except 4
    u_cols = np.round(kept.offsets[:, 0] * 8).astype(int)
    assert pruned == 4 * 3 and set(u_cols.tolist()) == {0, 1, 2, 3, 4}
    small = np.array([[0.4, 0.4, 0.6, 0.6]])   # a tile covering only its cell's centre
    _, pruned_small = base_maps.prune(lay, small, maps)
    assert pruned_small == 4 * 4


R_MAJOR, R_MINOR, W_MAX = 1.0, 0.4, 0.1


def torus_map_error(maps) -> float:
    """Largest |T_maps - T| / bbox diagonal over w in {0, W_MAX}, with T from the torus's
    closed form in NumPy (float64): independent of base.sample and of base_maps.map_error.
    Points: every cell centre (where bilinear interpolation errs most) and 20,000 random."""
    rng = np.random.default_rng(11)
    i, j = np.meshgrid(np.arange(maps.ru), np.arange(maps.rv))
    u = np.concatenate([((i + 0.5) / maps.ru).ravel(), rng.random(20000)])
    v = np.concatenate([((j + 0.5) / maps.rv).ravel(), rng.random(20000)])
    phi, psi = 2 * np.pi * u, 2 * np.pi * v
    n = np.stack([np.cos(psi) * np.cos(phi), np.cos(psi) * np.sin(phi), np.sin(psi)], 1)
    s = np.stack([(R_MAJOR + R_MINOR * np.cos(psi)) * np.cos(phi),
                  (R_MAJOR + R_MINOR * np.cos(psi)) * np.sin(phi), R_MINOR * np.sin(psi)], 1)
    p, nm = maps.lookup(mi.Float(u.astype(np.float32)), mi.Float(v.astype(np.float32)))
    p, nm = _np(p), _np(nm)
    err = max(np.linalg.norm(p + nm * w - (s + n * w), axis=1).max() for w in (0.0, W_MAX))
    diag = np.sqrt(2 * (2 * (R_MAJOR + R_MINOR)) ** 2 + (2 * R_MINOR) ** 2)
    return err / diag


def test_auto_resolution_meets_the_tolerance_with_the_smallest_power_of_two(variant):
    base = make_base("torus", major_radius=R_MAJOR, minor_radius=R_MINOR)
    r, trials, maps = base_maps.choose_resolution(base, 2e-4, W_MAX)
    assert r & (r - 1) == 0
    # independent check (closed form, not map_error): r meets it, r / 2 does not
    assert torus_map_error(base_maps.build_maps(base, r)) <= 2e-4 * 1.02
    assert maps.ru == r and torus_map_error(maps) == torus_map_error(base_maps.build_maps(base, r))
    assert torus_map_error(base_maps.build_maps(base, r // 2)) > 2e-4
    with pytest.raises(ValueError, match="tolerance"):
        base_maps.choose_resolution(base, 0.0, W_MAX)


def test_auto_check_catches_an_underestimating_map_error(variant, monkeypatch):
    """Fault injection (issue 19 item 6): a map_error that reports a quarter of the true
    error makes choose_resolution pick too small an R, and the closed-form check says so."""
    base = make_base("torus", major_radius=R_MAJOR, minor_radius=R_MINOR)
    honest = base_maps.map_error
    monkeypatch.setattr(base_maps, "map_error", lambda *a, **k: 0.25 * honest(*a, **k))
    r, _, _ = base_maps.choose_resolution(base, 2e-4, W_MAX)
    assert torus_map_error(base_maps.build_maps(base, r)) > 2e-4


def test_clamped_count_wraps_on_periodic_axes(variant):
    maps = base_maps.build_maps(make_base("torus"), 10)
    maps.valid[:, 0] = False                 # texel column u = 0 (and u = 1 by wrapping)
    u = mi.Float([0.0, 1.0, -1.0, 0.02, 0.5, 0.96])
    v = mi.Float([0.3] * 6)
    assert maps.clamped_count(u, v) == 5     # 0.96 rounds to texel 10 = 0 as well
    assert maps.clamped_count(u, v) == int((~maps.texel_valid(np.asarray(u), np.asarray(v))).sum())


def test_clamped_count_on_open_axes_takes_the_nearest_texel(variant):
    """Open axes: texel i holds u = i / (r - 1); a point is clamped when its nearest texel
    (round(u (r - 1))) is invalid — texel_valid (NumPy) and clamped_count (Dr.Jit) agree
    with that rule, at both ends of the axis too."""
    maps = base_maps.build_maps(make_base("plane"), 11)
    maps.valid[:, 3] = False                 # column u = 0.3
    maps.valid[:, 10] = False                # the last column, u = 1
    u = np.array([0.3, 0.26, 0.34, 0.24, 0.36, 0.5, 0.96, 1.0, 1.5, 0.0])
    v = np.full(len(u), 0.5)
    expect = [True, True, True, False, False, False, True, True, True, False]
    assert np.array_equal(~maps.texel_valid(u, v), expect)
    assert maps.clamped_count(mi.Float(u), mi.Float(v)) == sum(expect)


def test_map_error_skips_every_lookup_that_touches_an_invalid_texel(variant):
    """A texel column marked invalid and filled with garbage (z + 10): map_error must not
    see it (it skips points whose four lookup texels are not all valid), so the error is at
    most that of the intact maps; a lookup that read it would err by about 10."""
    base = make_base("torus")
    maps = base_maps.build_maps(base, 32)
    intact = base_maps.map_error(base, maps, 0.1, samples=1 << 14)
    p = _np(maps.position).copy()
    column = np.arange(32) * 32 + 5          # texels (i = 5, every row j), row-major
    p[column, 2] += 10.0
    maps.position = mi.Vector3f(*(mi.Float(p[:, k].astype(np.float32)) for k in range(3)))
    maps.valid[:, 5] = False
    assert intact < 0.1
    assert base_maps.map_error(base, maps, 0.1, samples=1 << 14) <= intact + 1e-6


def test_geometry_image_bytes_and_resolution_halving_gives_an_int(variant):
    """nbytes: two RGB float32 maps and a 1-byte validity bitmap per texel (§3.1);
    choose_resolution halves a resolution that meets the tolerance while its half does too
    and returns a power of two as an int (an error model e = 1e-2 (32 / R)^2 of the
    diagonal, from R = 512: 128 is the smallest R with e <= 7e-4)."""
    base = make_base("plane")
    maps = base_maps.build_maps(base, 16, 8)
    assert maps.nbytes == 16 * 8 * (2 * 3 * 4 + 1) and type(maps.nbytes) is int
    base = make_base("torus")
    diagonal = base_maps.base_sample_diagonal(base)
    r, trials, maps = base_maps.choose_resolution(
        base, 7e-4, 0.1, start=512, build=lambda r: r,
        error=lambda base, r, w: diagonal * 1e-2 * (32 / r) ** 2)
    assert r == 128 and type(r) is int and maps == 128   # the trial's build, kept
    assert [t[0] for t in trials] == [64, 128, 256, 512]


def test_diffusion_takes_the_first_texel_as_a_source():
    """Texel 0 (flat index 0) is a valid source like any other: with only the two corners
    valid, every texel nearer to (0, 0) takes texel 0."""
    valid = np.zeros((9, 9), bool)
    valid[0, 0] = valid[8, 8] = True
    src, _ = base_maps.diffuse_fill(valid, False, False)
    yy, xx = np.mgrid[0:9, 0:9]
    near = yy + xx < 6
    assert np.all(src[near] == 0) and np.all(src[yy + xx > 10] == 80)


def test_prune_reads_the_tile_footprint_in_v(variant):
    """A tile covering only the upper part of its cell (y in [0.6, 1]) over maps whose rows
    v >= 0.5 are invalid is pruned; with only rows v >= 0.7 invalid it keeps the valid
    texels at v = 0.5, 0.6 inside its footprint grown by one texel."""
    layout = make_layout("rect", 1, 1)
    bounds = np.array([[0.0, 0.6, 1.0, 1.0]])
    maps = base_maps.build_maps(make_base("plane"), 11)
    maps.valid[5:, :] = False
    assert base_maps.prune(layout, bounds, maps)[1] == 1
    maps.valid[:] = True
    maps.valid[7:, :] = False
    kept, pruned = base_maps.prune(layout, bounds, maps)
    assert pruned == 0 and kept.count == 1


def test_prune_grows_the_footprint_by_one_texel_and_auto_starts_at_a_power_of_two(variant):
    """prune: a tile over y in [0, 0.3] reads rows up to 0.3 (r - 1) + 1 = row 4 of an
    11-row map: pruned when rows 0..4 are invalid although row 5 is valid.
    choose_resolution from its default start: with an error model met by R = 32 and not by
    16 the answer is 32 (a power of two)."""
    layout = make_layout("rect", 1, 1)
    maps = base_maps.build_maps(make_base("plane"), 11)
    maps.valid[:5, :] = False
    assert base_maps.prune(layout, np.array([[0.0, 0.0, 1.0, 0.3]]), maps)[1] == 1
    base = make_base("torus")
    diagonal = base_maps.base_sample_diagonal(base)
    r, _, maps = base_maps.choose_resolution(base, 1.5e-2, 0.1, build=lambda r: r,
                                       error=lambda base, r, w: diagonal * 1e-2 * (32 / r) ** 2)
    assert r == 32 and maps == 32
