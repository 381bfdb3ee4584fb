"""Adjoint transport on a curved base: ptracer converges to path for vdm, horizon and relief
on a coarse torus, whose interpolated shading normals differ from the face normals (on a
plane the two coincide and a wrong adjoint factor goes unseen).

The truth is the path render of the same scene; the tolerance is the noise measured from
two seeds (standard error of the image mean from per-pixel seed differences).  Direct
light only (``max_depth`` 2): a silhouette's null pass costs the same bounce under both
integrators, so what lies behind it is dark under both.
"""
import mitsuba as mi
import numpy as np
import pytest

MAT = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.6}}
LIGHTS = {
    "sun": {"type": "directional", "direction": [-0.5, 0.6, -0.6],
            "irradiance": {"type": "rgb", "value": 2.0}},
    "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
}


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))


def _scene(kind, integrator, light, res, max_depth=2):
    height = {"type": "cells", "cells": 2, "radius": 0.45,
              "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])}
    base = {"base": "torus", "major_radius": 1.0, "minor_radius": 0.45}
    if kind == "control":  # true displacement of the same relief
        shape = {"type": "displaced", **base, "resolution": 256, "scale": 0.06,
                 "midlevel": 1.0, "height": height, "bsdf": MAT}
    else:
        bsdf = {"type": kind, "height": height, "depth": 0.06, "tiling_u": 4, "tiling_v": 2,
                "nested": MAT}
        if kind == "vdm":
            bsdf.update(res=32, phi=16, curvatures=4)
        # 12 x 12 cells: shading normals up to ~15 degrees off the face normals
        shape = {"type": "vdm_mesh", **base, "resolution": 12, "bsdf": bsdf}
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": max_depth, "hide_emitters": True},
        "sensor": {"type": "perspective", "fov": 38, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -2.6, 2.4], target=[0, 0, 0], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
        "light": LIGHTS[light], "shape": shape})


def _renders(kind, light, spps, res, max_depth=2):
    """{(integrator, spp): (image seed 1, image seed 2)} as (res, res) channel means."""
    out = {}
    for integrator in ("path", "ptracer"):
        scene = _scene(kind, integrator, light, res, max_depth)
        for spp in spps:
            pair = tuple(np.asarray(mi.render(scene, spp=spp, seed=seed)).mean(-1)
                         for seed in (1, 2))
            for img in pair:
                assert np.isfinite(img).all(), (kind, light, integrator, spp)
            out[integrator, spp] = pair
    return out


def _error(renders, spp):
    """(ptracer mean - path mean) / path mean, its standard error, and the per-pixel
    noise of ptracer (std of one render's pixel), all from the two seeds."""
    (p1, p2), (t1, t2) = renders["path", spp], renders["ptracer", spp]
    n = p1.size
    # a pixel's variance is half that of the difference of two independent renders;
    # the mean of both seeds has a quarter of the summed variance of one render each
    var_p, var_t = np.var(p1 - p2) / 2, np.var(t1 - t2) / 2
    mean_p = (p1.mean() + p2.mean()) / 2
    err = ((t1.mean() + t2.mean()) / 2 - mean_p) / mean_p
    se = np.sqrt((var_p + var_t) / (2 * n)) / mean_p
    return float(err), float(se), float(np.sqrt(var_t))


def _check_agreement(renders, spp, label, max_pixel=True):
    err, se, pixel_noise = _error(renders, spp)
    path_max = max(img.max() for img in renders["path", spp])
    ptracer_max = max(img.max() for img in renders["ptracer", spp])
    # the numbers docs/vdm.md quotes (pytest -s)
    print(f"{label:13s} {spp:4d} spp: ptracer/path - 1 = {err:+.4f} (SE {se:.4f}); "
          f"max pixel {ptracer_max:.3f} (path {path_max:.3f}, pixel noise {pixel_noise:.3f})")
    # 4 standard errors: a false alarm 1 in 16,000
    assert abs(err) < 4 * se, f"{label} at {spp} spp: ptracer/path - 1 = {err:+.4f} (SE {se:.4f})"
    # a ptracer pixel is the path pixel plus its own noise, whose tail is heavy (the
    # adjoint weight's 1 / |wi.n_g|): 16 sigma over the brightest; measured at 512 spp
    # 3.9 sigma (sun) and 9-11 sigma (sky; true displacement 5.7); on main 47 sigma
    # (relief, sun, 64 spp)
    if max_pixel:
        assert ptracer_max < path_max + 16 * pixel_noise, (label, spp, ptracer_max, path_max,
                                                          pixel_noise)
    return err, se


def test_relief_ptracer_matches_path_under_sun(variant):
    """Fast check: relief on the coarse torus (on main +13 to +21 %, pixels up to 70x the
    path maximum)."""
    renders = _renders("relief", "sun", (64,), 32)
    _check_agreement(renders, 64, "relief/sun")


@pytest.mark.slow
@pytest.mark.parametrize("light", ["sun", "sky"])
@pytest.mark.parametrize("kind", ["control", "vdm", "horizon", "relief"])
def test_ptracer_converges_to_path(variant, kind, light):
    """Within 4 SE at 32 and 512 spp; the SE shrinks like 1/sqrt(spp) (16x the samples:
    a quarter, measured ratio within [0.15, 0.4]), so the agreement is convergence, not a
    loose tolerance.  The brightest pixel is bounded at 512 spp: under an environment a
    particle can arrive grazing the face, where the shading-normal adjoint weight
    |wi.n_m| / |wi.n_g| is unbounded (Veach 1997 §5.3); one such particle is a firefly
    that the 1 / spp splat scale brings under the noise at 512 spp, not at 32."""
    renders = _renders(kind, light, (32, 512), 48)
    _, se_low = _check_agreement(renders, 32, f"{kind}/{light}", max_pixel=False)
    _, se_high = _check_agreement(renders, 512, f"{kind}/{light}")
    assert 0.15 < se_high / se_low < 0.4, (kind, light, se_low, se_high)


@pytest.mark.slow
@pytest.mark.parametrize("kind", [
    "horizon", "relief",
    pytest.param("vdm", marks=pytest.mark.xfail(strict=True, reason=(
        "silhouettes: path sees the sky through a silhouette's null pass (hide_emitters "
        "hides depth-0 hits only), ptracer's sensor connection is a shadow ray that stops "
        "at the silhouette, so ptracer is darker there")))])
def test_ptracer_matches_path_with_interreflection(variant, kind):
    """Unlimited depth under the sky: light bounces inside the torus's hole, so the
    importance-mode ``sample`` (adjoint weight over the nested density) is exercised."""
    renders = _renders(kind, "sky", (128,), 48, max_depth=-1)
    _check_agreement(renders, 128, f"{kind}/sky/all", max_pixel=False)
