"""The Utah teapot body from Newell's Bezier patches as a DDM base."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.bezier import load_patches, teapot_body
from mi_displace.core.surfaces import principal_curvatures


def _np(v):
    return np.stack([np.asarray(c) for c in v], 1)


def test_patch_file_parses():
    patches, points = load_patches(teapot_body.__globals__["DEFAULT_TEAPOT"])
    assert patches.shape == (32, 16) and points.shape == (306, 3)
    assert patches.min() == 0 and patches.max() == 305


def test_teapot_body_is_closed_around_and_continuous(variant):
    body = teapot_body()
    assert body.periodic_u
    v = mi.Float(np.linspace(0, 1, 40))
    a, b = body.sample(dr.zeros(mi.Float, 40), v), body.sample(dr.ones(mi.Float, 40), v)
    assert np.allclose(_np(a.p), _np(b.p), atol=1e-5)
    c, d = body.sample(dr.zeros(mi.Float, 40) + 0.1, v), body.sample(dr.zeros(mi.Float, 40) + 1.1, v)
    assert np.allclose(_np(c.p), _np(d.p), atol=1e-5)     # u wraps (tiles across the seam)
    # C0 across patch boundaries (columns at u = k/4, rows at v = 1/3, 2/3)
    for k in (0.25, 0.5, 0.75):
        lo = body.sample(dr.zeros(mi.Float, 40) + (k - 1e-6), v)
        hi = body.sample(dr.zeros(mi.Float, 40) + (k + 1e-6), v)
        assert np.abs(_np(lo.p) - _np(hi.p)).max() < 1e-4
        assert np.abs(_np(lo.n) - _np(hi.n)).max() < 1e-2      # G1: normals continuous


def test_teapot_normals_point_outward_and_match_derivatives(variant):
    body = teapot_body()
    rng = np.random.default_rng(0)
    u = mi.Float(rng.uniform(0.01, 0.99, 500))
    v = mi.Float(rng.uniform(0.36, 0.97, 500))       # body rows (the rim lip turns over)
    s = body.sample(u, v)
    radial = _np(s.p) * [1, 1, 0]
    assert np.all(np.einsum("ij,ij->i", _np(s.n), radial) > 0)
    assert np.allclose(np.einsum("ij,ij->i", _np(s.n), _np(s.dp_du)), 0, atol=1e-4)
    h = 1e-3
    fd = (_np(body.sample(u + h, v).p) - _np(body.sample(u - h, v).p)) / (2 * h)
    assert np.allclose(fd, _np(s.dp_du), rtol=1e-3, atol=1e-2)
    fdn = (_np(body.sample(u + h, v).n) - _np(body.sample(u - h, v).n)) / (2 * h)
    assert np.allclose(fdn, _np(s.dn_du), atol=2e-2)


def test_bad_patch_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.txt"):
        load_patches(tmp_path / "nope.txt")
    bad = tmp_path / "bad.txt"
    bad.write_text("2\n1,2,3\n")
    with pytest.raises(ValueError, match="malformed|expected"):
        load_patches(bad)


def _body_points(rng, n=400):
    """Random (u, v) inside the teapot body's patches, away from patch borders (C = 4 columns,
    R = 3 rows: the derivatives jump across a border)."""
    col, row = rng.integers(0, 4, n), rng.integers(0, 3, n)
    return (col + rng.uniform(0.1, 0.9, n)) / 4, (row + rng.uniform(0.1, 0.9, n)) / 3


def test_teapot_derivatives_along_v_match_finite_differences(variant):
    """S_v and n_v (the tests above check only u) against central differences of S and n."""
    body = teapot_body()
    u, v = _body_points(np.random.default_rng(1))
    u, v = mi.Float(u), mi.Float(v)
    s, h = body.sample(u, v), 1e-3
    hi, lo = body.sample(u, v + h), body.sample(u, v - h)
    fd = (_np(hi.p) - _np(lo.p)) / (2 * h)
    scale = np.abs(fd).max()
    assert np.abs(fd - _np(s.dp_dv)).max() < 1e-3 * scale
    fdn = (_np(hi.n) - _np(lo.n)) / (2 * h)
    assert np.abs(fdn - _np(s.dn_dv)).max() < 2e-2 * max(np.abs(fdn).max(), 1.0)
    # n is the unit normal of S_u x S_v, pointing away from the z axis on the body rows
    cross = np.cross(_np(s.dp_du), _np(s.dp_dv))
    cross /= np.linalg.norm(cross, axis=1, keepdims=True)
    assert np.allclose(_np(s.n), cross, atol=1e-4) or np.allclose(_np(s.n), -cross, atol=1e-4)


def test_teapot_extent_is_the_longest_isoparametric_curve(variant):
    """extent() = (longest u-line, longest v-line) in object units, measured as polylines."""
    body = teapot_body()
    n, k = 96, 1024
    t = (np.arange(n) + 0.5) / n
    a = np.linspace(0, 1, k + 1)

    def lengths(u, v):
        p = _np(body.sample(mi.Float(u.ravel()), mi.Float(v.ravel())).p).reshape(*u.shape, 3)
        return np.linalg.norm(np.diff(p, axis=1), axis=2).sum(1)

    around = lengths(*np.meshgrid(a, t)[::1])                   # each row: u from 0 to 1
    down = lengths(*np.meshgrid(t, a, indexing="ij"))           # each row: v from 0 to 1
    eu, ev = body.extent()
    assert eu == pytest.approx(around.max(), rel=2e-3)
    assert ev == pytest.approx(down.max(), rel=2e-3)


def test_teapot_curvature_bounds_are_the_extremes_on_a_finer_grid(variant):
    """curvature_bounds() (sampled on a grid) against the principal curvatures on a grid
    three times finer, of other points: within 25 % (the extremes are spikes at the rim lip, which the coarse grid
    only approaches)."""
    body = teapot_body()
    n = 288
    t = (np.arange(n) + 0.25) / n
    u, v = np.meshgrid(t, t)
    k_max, k_min, _, _ = principal_curvatures(body.sample(mi.Float(u.ravel()), mi.Float(v.ravel())))
    lo, hi = body.curvature_bounds()
    assert lo == pytest.approx(float(np.min(k_min)), rel=0.25)
    assert hi == pytest.approx(float(np.max(k_max)), rel=0.25)
    assert body.name == "teapot"
