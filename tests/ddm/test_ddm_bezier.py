"""The Utah teapot body from Newell's Bezier patches as a DDM base."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.bezier import load_patches, teapot_body


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
