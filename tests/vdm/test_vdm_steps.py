"""The per-pixel steps of VDM (§3.2) on a constant-depth floor, where every step has a
closed form (issue 19: mutants of vdm/steps.py)."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.vdm import assets, build, lookup, steps

H, D, RES, TILING = 0.4, 0.2, 8, 2.0


def _constant_texture(value):
    return mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.full((2, 2, 1), value, np.float32)),
                         "raw": True})


@pytest.fixture
def floor(variant, tmp_path, monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    data = build.build(np.full((RES, RES), H, np.float32),
                       build.VDMSpec(res=RES, n_theta=8, n_phi=8, depth=D), use_cache=False)
    return lookup.VDMLookup(data, 2, 1)


def _plane(n, rng, theta_max=1.3):
    """n interactions on the plane z = 0, uv in [0, 1)^2, one tile per world unit
    (dp/du = dp/dv = TILING along x, y), views up to theta_max from the normal."""
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    uv = rng.random((2, n))
    si.uv = mi.Point2f(*uv)
    si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
    si.dp_du, si.dp_dv = mi.Vector3f(TILING, 0, 0), mi.Vector3f(0, TILING, 0)
    theta, phi = rng.uniform(0.0, theta_max, n), rng.uniform(0, 2 * math.pi, n)
    si.wi = mi.Vector3f(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta))
    return si, uv, theta, phi


@pytest.mark.parametrize("refine", [0, 8])
def test_footprint_on_a_constant_floor(floor, refine):
    """T' = T - D (1 - H) tan(theta_V) (cos phi_V, sin phi_V): the view ray meets the floor."""
    vdm = steps.VDMSteps(floor, _constant_texture(H), D, 1.0, (TILING, TILING), False,
                         refine_steps=refine)
    rng = np.random.default_rng(0)
    si, uv, theta, phi = _plane(500, rng)
    fp = vdm.footprint(si, mi.Bool(True))
    assert not np.any(np.asarray(fp.silhouette))           # flat: every ray hits
    off = D * (1 - H) * np.tan(theta)
    T = uv * TILING
    expected = T - off * np.stack([np.cos(phi), np.sin(phi)])
    got = np.stack([np.asarray(fp.T.x), np.asarray(fp.T.y)])
    np.testing.assert_allclose(got, expected, atol=2e-3 * (1 + off.max()))
    np.testing.assert_allclose(np.stack([np.asarray(fp.uv.x), np.asarray(fp.uv.y)]), got / TILING,
                               atol=1e-6)
    np.testing.assert_allclose(np.asarray(fp.h), D * (1 - H), atol=1e-6)
    np.testing.assert_allclose(np.asarray(fp.tile), 1.0)
    n = np.stack([np.asarray(fp.normal.x), np.asarray(fp.normal.y), np.asarray(fp.normal.z)], 1)
    np.testing.assert_allclose(n, np.broadcast_to([0, 0, 1], n.shape), atol=1e-5)
    # the shading interaction sits at T' with the floor's normal and the same view
    out = vdm.shading(si, fp)
    np.testing.assert_allclose(np.asarray(out.uv.x), np.asarray(fp.uv.x))
    np.testing.assert_allclose(np.asarray(out.sh_frame.n.z), 1, atol=1e-6)
    np.testing.assert_allclose(np.asarray(out.wi.z), np.cos(theta), atol=1e-5)


def test_a_constant_floor_is_lit_from_above_only(floor):
    vdm = steps.VDMSteps(floor, _constant_texture(H), D, 1.0, (TILING, TILING), False)
    rng = np.random.default_rng(1)
    si, *_ = _plane(400, rng)
    fp = vdm.footprint(si, mi.Bool(True))
    t, p = rng.uniform(0.0, 1.45, 400), rng.uniform(0, 2 * math.pi, 400)
    above = mi.Vector3f(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t))
    assert np.all(np.asarray(vdm.lit(fp, above)))          # nothing above the floor
    below = mi.Vector3f(above.x, above.y, -above.z)
    assert not np.any(np.asarray(vdm.lit(fp, below)))
    # without shadows, or at depth 0, everything is lit (step 3 skipped)
    off = steps.VDMSteps(floor, _constant_texture(H), D, 1.0, (TILING, TILING), False, shadows=False)
    assert np.all(np.asarray(off.lit(fp, below)))


def test_silhouette_against_the_table_mvm(variant, tmp_path, monkeypatch):
    """On a sphere-like curvature c the MVM is asin(1 - c h) (ray tangent to the floor):
    views beyond it are silhouettes (vdm_mesh's c_V replaced by a fixed c here)."""
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    c = 1.5
    data = build.build(np.full((RES, RES), H, np.float32),
                       build.VDMSpec(res=RES, n_theta=8, n_phi=8, depth=D, c_range=(c, c)),
                       use_cache=False)
    vdm = steps.VDMSteps(lookup.VDMLookup(data, 2, 1), _constant_texture(H), D, 1.0,
                         (TILING, TILING), False)
    mvm = math.asin(1 - c * D * (1 - H))
    rng = np.random.default_rng(2)
    si, _, theta, _ = _plane(400, rng, theta_max=1.55)
    # c_V = c everywhere: the table has one curvature, so any c reads that column
    got = np.asarray(vdm.silhouette(si, mi.Bool(True)))
    clear = np.abs(theta - mvm) > 1e-3
    np.testing.assert_array_equal(got[clear], (theta > mvm)[clear])
    assert got.any() and not got.all()
    assert not np.any(np.asarray(vdm.silhouette(si, mi.Bool(False))))


@pytest.mark.parametrize("radius,swap", [(1.0, False), (3.0, False), (1.0, True)])
def test_view_curvature_on_a_sphere_is_one_over_the_radius(variant, tmp_path, monkeypatch,
                                                           radius, swap):
    """c_V of a vdm_mesh sphere (an umbilic surface: the same along every view) is 1/R, in
    tile units tile / R, at any point and view (the per-face forms of tile_forms, linear in
    uv, and the placement scale).  The curvature forms vary with latitude only: the sphere
    is also loaded from a file with u and v swapped, so that both uv gradients are read."""
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    bsdf = {"type": "vdm", "height": {"type": "cells"}, "depth": 0.05, "tiling": 4, "res": 8,
            "theta": 4, "phi": 4, "curvatures": 2, "svd_terms": 2, "mvm_terms": 1}
    if swap:
        pos, uv, faces = assets.parametric_grid("sphere", 48, radius=radius)
        path = assets.write_corner_normal_obj(tmp_path / "swapped.obj", pos, uv[:, ::-1], faces)
        shape = mi.load_dict({"type": "vdm_mesh", "filename": str(path), "bsdf": bsdf})
    else:
        shape = mi.load_dict({"type": "vdm_mesh", "base": "sphere", "radius": radius,
                              "resolution": 48, "bsdf": bsdf})
    scene = mi.load_dict({"type": "scene", "s": shape})
    rng = np.random.default_rng(3)
    n = 400
    z = rng.uniform(-0.8, 0.8, n)                       # away from the poles
    a = rng.uniform(0, 2 * math.pi, n)
    p = np.stack([np.sqrt(1 - z * z) * np.cos(a), np.sqrt(1 - z * z) * np.sin(a), z])
    view = rng.normal(size=(3, n))
    view -= np.sum(view * p, 0) * p * 0.7               # views within the upper hemisphere
    view = np.where(np.sum(view * p, 0) > 0.1, view, p)
    view /= np.linalg.norm(view, axis=0)
    origin = radius * p + 3 * radius * view
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(*-view)))
    active = si.is_valid()     # (a grazing ray may pass beside the polygonal sphere)
    hit = np.asarray(active)
    assert hit.mean() > 0.9
    steps_ = shape.bsdf().steps
    _, _, _, _, c, _, tile = steps_._view(si, active)
    c, tile = np.asarray(c)[hit], np.asarray(tile)[hit]
    np.testing.assert_allclose(tile, steps_.tile_size, rtol=0.05)    # uniform placement
    # the estimate of a 48-segment mesh: 1.3 % median, 6 % at the 90th percentile (16 %
    # at worst, near the coarse rows); a uv offset read with the wrong sign is 100 % off
    err = np.abs(c / (tile / radius) - 1)
    assert np.median(err) < 0.03 and np.percentile(err, 90) < 0.1, (np.median(err), err.max())
