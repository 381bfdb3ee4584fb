"""The tile frame and the height lookup shared by VDM, horizon and relief mapping (§3.2)
against linear algebra and finite differences (issue 19: mutants of vdm/frame.py)."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.vdm.frame import TiledHeight, TileFrame, shading_interaction

TILING = (2.0, 4.0)


def _np(v):
    return np.stack([np.asarray(v.x), np.asarray(v.y), np.asarray(v.z)], 1).astype(np.float64)


def _interactions(n=64, seed=0):
    """Random normals, non-tangent dp/du, dp/dv (the frame projects them) and views."""
    rng = np.random.default_rng(seed)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    du, dv = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.sh_frame = mi.Frame3f(mi.Normal3f(*nrm.T))
    si.dp_du, si.dp_dv = mi.Vector3f(*du.T), mi.Vector3f(*dv.T)
    a = du / TILING[0] - np.sum(du / TILING[0] * nrm, 1, keepdims=True) * nrm
    b = dv / TILING[1] - np.sum(dv / TILING[1] * nrm, 1, keepdims=True) * nrm
    return si, nrm, a, b, rng


def test_tiled_height_is_the_texture_at_t_over_tiling(variant):
    texture = mi.load_dict({"type": "ripples"})
    height = TiledHeight(texture, TILING, 1e-3)
    rng = np.random.default_rng(1)
    T = mi.Point2f(*rng.random((2, 100)) * 3)
    si = dr.zeros(mi.SurfaceInteraction3f, 100)
    si.uv = mi.Point2f(T.x / TILING[0], T.y / TILING[1])
    np.testing.assert_allclose(np.asarray(height.value(T)), np.asarray(texture.eval_1(si)), atol=1e-7)
    h, g = height(T)
    np.testing.assert_allclose(np.asarray(h), np.asarray(texture.eval_1(si)), atol=1e-7)
    # the gradient per tile unit against central differences of H(T)
    e = 1e-3
    for axis, comp in ((0, g.x), (1, g.y)):
        dT = mi.Vector2f(e, 0) if axis == 0 else mi.Vector2f(0, e)
        fd = (np.asarray(height.value(T + dT)) - np.asarray(height.value(T - dT))) / (2 * e)
        np.testing.assert_allclose(np.asarray(comp), fd, atol=2e-3 * np.abs(fd).max())


def test_to_tile_inverts_the_tile_vectors(variant):
    si, nrm, a, b, rng = _interactions()
    frame = TileFrame(si, TILING)
    np.testing.assert_allclose(_np(frame.a), a, atol=1e-5)
    np.testing.assert_allclose(_np(frame.b), b, atol=1e-5)
    alpha, beta, gamma = rng.normal(size=(3, len(nrm)))
    w = alpha[:, None] * a + beta[:, None] * b + gamma[:, None] * nrm
    t = frame.to_tile(mi.Vector3f(*w.T))
    tx, ty = np.asarray(t.x, np.float64), np.asarray(t.y, np.float64)
    # compared in world units (a few random tile frames are nearly degenerate)
    tangential = alpha[:, None] * a + beta[:, None] * b
    np.testing.assert_allclose(tx[:, None] * a + ty[:, None] * b, tangential, atol=1e-4 * np.abs(w).max())
    good = np.abs(np.cross(a, b)).sum(1) > 0.1 * np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    np.testing.assert_allclose(tx[good], alpha[good], atol=1e-3)
    np.testing.assert_allclose(ty[good], beta[good], atol=1e-3)
    assert np.all(np.asarray(frame.valid))


def test_direction_angles_and_tile_step(variant):
    si, nrm, a, b, rng = _interactions(seed=2)
    frame = TileFrame(si, TILING)
    w = rng.normal(size=nrm.shape)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    ct, theta, phi, step = frame.direction(mi.Vector3f(*w.T))
    cos_t = np.sum(w * nrm, 1)
    np.testing.assert_allclose(np.asarray(ct), cos_t, atol=1e-6)
    np.testing.assert_allclose(np.asarray(theta), np.arccos(cos_t), atol=1e-3)
    # one world unit along the unit tangential direction covers `step` tile units
    wt = w - cos_t[:, None] * nrm
    wt /= np.linalg.norm(wt, axis=1, keepdims=True)
    sx, sy = np.asarray(step.x), np.asarray(step.y)
    np.testing.assert_allclose(sx[:, None] * a + sy[:, None] * b, wt, atol=2e-3)
    phi = np.asarray(phi)
    assert np.all((phi >= 0) & (phi < 2 * math.pi))
    # straight into the surface: theta = pi (cos clipped at -1: |n|^2 rounds above 1)
    ct, theta, _, _ = frame.direction(-frame.n)
    np.testing.assert_allclose(np.asarray(ct), -1, atol=1e-6)
    np.testing.assert_allclose(np.asarray(theta), math.pi, atol=1e-3)
    np.testing.assert_allclose(np.cos(phi), sx / np.hypot(sx, sy), atol=1e-5)
    np.testing.assert_allclose(np.sin(phi), sy / np.hypot(sx, sy), atol=1e-5)
    # exactly along the normal (no tangential part; z here, where w - (w.n) n is exactly
    # 0 in float32): azimuth 0, one world unit along a
    si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
    nrm = np.broadcast_to([0.0, 0.0, 1.0], nrm.shape)
    a = _np(si.dp_du) / TILING[0] * [1, 1, 0]
    b = _np(si.dp_dv) / TILING[1] * [1, 1, 0]
    frame = TileFrame(si, TILING)
    ct, theta, phi, step = frame.direction(mi.Vector3f(0, 0, 1))
    np.testing.assert_allclose(np.asarray(theta), 0, atol=1e-3)
    phi = np.asarray(phi)
    np.testing.assert_allclose(np.minimum(phi, 2 * math.pi - phi), 0, atol=1e-4)
    np.testing.assert_allclose(np.asarray(step.x), 1 / np.linalg.norm(a, axis=1), rtol=1e-4)
    np.testing.assert_allclose(np.asarray(step.y) * np.linalg.norm(b, axis=1), 0, atol=1e-4)


def test_meso_normal_is_normal_to_the_displaced_tangents(variant):
    si, nrm, a, b, rng = _interactions(seed=3)
    frame = TileFrame(si, TILING)
    grad, depth = rng.normal(size=(2, len(nrm))), 0.3
    m = _np(frame.meso_normal(mi.Vector2f(*grad), depth))
    # r(T) = P + J T - depth (1 - H(T)) n: tangents a + depth H_x n, b + depth H_y n
    for g, t in ((grad[0], a), (grad[1], b)):
        tangent = t + depth * g[:, None] * nrm
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
        np.testing.assert_allclose(np.sum(m * tangent, 1), 0, atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1, atol=1e-5)
    assert np.all(np.sum(m * nrm, 1) > 0)
    # a flat height field has the coarse normal
    flat = _np(frame.meso_normal(mi.Vector2f(0, 0), depth))
    np.testing.assert_allclose(flat, nrm, atol=1e-4)


def test_degenerate_frame_falls_back_to_the_coarse_normal(variant):
    si, nrm, a, b, _ = _interactions(seed=4)
    si.dp_dv = dr.zeros(mi.Vector3f, len(nrm))     # a pole: no tile frame
    frame = TileFrame(si, TILING)
    assert not np.any(np.asarray(frame.valid))
    np.testing.assert_allclose(_np(frame.meso_normal(mi.Vector2f(0.5, -0.2), 0.3)), nrm, atol=1e-6)
    # nearly parallel tile vectors still span a frame
    si2, *_ = _interactions(seed=4)
    si2.dp_dv = si2.dp_du * 2.0 + si2.sh_frame.s * 0.1
    assert np.all(np.asarray(TileFrame(si2, TILING).valid))


def test_shading_interaction_frame_and_view(variant):
    si, nrm, _, _, rng = _interactions(seed=5)
    n = len(nrm)
    wi = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    si.wi = mi.Vector3f(*wi.T)
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    tangent = rng.normal(size=(n, 3))
    tangent[:4] = normal[:4] * 2.0     # along the normal: any frame about the normal
    uv = rng.random((2, n))
    out = shading_interaction(si, mi.Point2f(*uv), mi.Vector3f(*normal.T), mi.Vector3f(*tangent.T))
    s, t, nn = _np(out.sh_frame.s), _np(out.sh_frame.t), _np(out.sh_frame.n)
    np.testing.assert_allclose(nn, normal, atol=1e-6)
    proj = tangent - np.sum(tangent * normal, 1, keepdims=True) * normal
    proj /= np.maximum(np.linalg.norm(proj, axis=1, keepdims=True), 1e-30)
    np.testing.assert_allclose(s[4:], proj[4:], atol=1e-5)
    np.testing.assert_allclose(np.sum(s * normal, 1), 0, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(t, np.cross(normal, s), atol=1e-5)
    np.testing.assert_allclose(np.stack([np.asarray(out.uv.x), np.asarray(out.uv.y)]), uv, atol=1e-7)
    world = _np(si.to_world(si.wi))
    back = s * np.asarray(out.wi.x)[:, None] + t * np.asarray(out.wi.y)[:, None] \
        + nn * np.asarray(out.wi.z)[:, None]
    np.testing.assert_allclose(back, world, atol=1e-5)
