"""VDM on inputs the project did not choose (issue 12): per-corner normals, a real height
map at grazing views, self-shadows against a brute-force march."""
import math
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.render import scene as scenes
from mi_displace.render.raster import pixel_rays
from mi_displace.vdm import assets, methods
from mi_displace.vdm.relief import march_shadow

GRAZING = "scenes/vdm_bricks_grazing.xml"
CORNERS = "scenes/vdm_corner_normals.xml"
SMALL = {"vdm_res": "32", "svd_terms": "8", "mvm_terms": "4"}
TABLE = {"res": 16, "theta": 4, "phi": 8, "curvatures": 4, "svd_terms": 4, "mvm_terms": 2}


def _torus_obj(path, shrink=0.0):
    pos, uv, faces = assets.parametric_grid("torus", 48, major_radius=1.0, minor_radius=0.4)
    if shrink:  # a triangle soup: every face pulled towards its centre, nothing shared
        pos, uv = pos[faces.ravel()], uv[faces.ravel()]
        centre = pos.reshape(-1, 3, 3).mean(1).repeat(3, 0)
        pos = pos + shrink * (centre - pos)
        faces = np.arange(len(pos)).reshape(-1, 3)
    return str(assets.write_corner_normal_obj(path, pos, uv, faces))


def _vdm_mesh(filename, **kw):
    height = {"type": "cells", "to_uv": mi.ScalarTransform4f().scale([6, 2, 1])}
    bsdf = dict({"type": "vdm", "height": height, "depth": 0.05, "tiling_u": 6,
                 "tiling_v": 2}, **TABLE)
    return dict({"type": "vdm_mesh", "filename": filename, "bsdf": bsdf}, **kw)


def test_per_corner_normals_give_the_torus_curvature(variant, tmp_path):
    path = _torus_obj(tmp_path / "corners.obj")
    shape = mi.load_dict(_vdm_mesh(path))
    faces = shape.face_count()
    assert shape.vertex_count() == 3 * faces          # the loader split every vertex
    # analytic principal curvatures of the torus: -1 / (R - r) ... 1 / r
    lo, hi = shape.build_stats["curvature_min"], shape.build_stats["curvature_max"]
    np.testing.assert_allclose([lo, hi], [-1 / 0.6, 1 / 0.4], rtol=0.2)
    stats = shape.bsdf().stats
    assert stats["n_curvatures"] == TABLE["curvatures"]
    assert shape.curvature_warning is None
    # the same torus from the parametric base (shared vertices, analytic normals)
    grid = mi.load_dict({"type": "vdm_mesh", "base": "torus", "major_radius": 1.0,
                         "minor_radius": 0.4, "resolution": 48, "bsdf": _vdm_mesh("")["bsdf"]})
    np.testing.assert_allclose([lo, hi], [grid.build_stats["curvature_min"],
                                          grid.build_stats["curvature_max"]], rtol=0.1)


def test_zero_curvature_on_a_curved_mesh_warns(variant, tmp_path):
    soup = _torus_obj(tmp_path / "soup.obj", shrink=1e-3)
    with pytest.warns(UserWarning, match="curvature estimate is zero everywhere"):
        shape = mi.load_dict(_vdm_mesh(soup))
    assert shape.build_stats["curvature_max"] == 0 and shape.curvature_warning
    with warnings.catch_warnings():                   # a plane is flat: no warning
        warnings.simplefilter("error")
        plane = mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolution": 4,
                              "bsdf": _vdm_mesh("")["bsdf"]})
    assert plane.curvature_warning is None


def _backfacing(scene) -> float:
    """Fraction of the pixels VDM shades whose mesostructure normal faces away from the
    viewer (impossible for a visible point)."""
    ray, _, _, _ = pixel_rays(scene.sensors()[0], 1)
    si = scene.ray_intersect(ray)
    active = si.is_valid()
    _, blocked, si2 = scene.shapes()[0].bsdf()._prepare(si, active)
    shaded = active & ~blocked
    away = shaded & (dr.dot(si2.sh_frame.n, -ray.d) < 0)
    return float(np.asarray(away).sum()) / max(1, int(np.asarray(shaded).sum()))


@pytest.mark.parametrize("angle", [45, 70, 82, 85])
def test_grazing_views_shade_points_that_face_the_viewer(variant, angle):
    scene, _ = scenes.load(GRAZING, mode="approximation", integrator="raster", res="48",
                           angle=str(angle), **SMALL)
    image, _ = scenes.render(scene)
    assert np.all(np.isfinite(image))
    assert _backfacing(scene) < 0.02, angle
    if angle >= 82:
        # the paper's plain lookup (no refinement of T'): the cause, measured
        scene.shapes()[0].bsdf().steps.refine_steps = 0
        assert _backfacing(scene) > 0.08, angle


def _shadow_verdicts(**kw):
    """VDM's lit test and a 2048-step march of the true height field at 20k random
    (T, view, light) on a flat plane with steep ripples (D = 0.3 tiles)."""
    shape = mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolution": 2, "bsdf": dict(
        {"type": "vdm", "height": {"type": "ripples"}, "depth": 0.3, "tiling": 2, "res": 64}, **kw)})
    steps = shape.bsdf().steps
    n, rng = 20000, np.random.default_rng(0)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.uv = mi.Point2f(rng.random(n), rng.random(n))
    si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
    si.dp_du, si.dp_dv = mi.Vector3f(2, 0, 0), mi.Vector3f(0, 2, 0)
    si.shape = mi.ShapePtr(shape)

    def directions(lo, hi):
        t, p = rng.uniform(lo, hi, n), rng.uniform(0, 2 * math.pi, n)
        return mi.Vector3f(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t))

    si.wi = directions(0.0, 1.3)
    fp = steps.footprint(si, mi.Bool(True))
    light = directions(0.2, 1.45)
    lit = steps.lit(fp, light)
    ct, _, _, step = fp.frame.direction(light)
    truth = ~march_shadow(steps.height, fp.T, fp.h, ct, step * steps.tile_size, steps.depth, 2048)
    keep = np.asarray(~fp.silhouette)
    lit, truth = np.asarray(lit)[keep], np.asarray(truth)[keep]
    return float(np.mean(~lit & truth)), float(np.mean(lit & ~truth)), float(np.mean(~truth))


def test_self_shadows_against_a_brute_force_march(variant):
    false_shadow, leak, shadowed = _shadow_verdicts()
    assert 0.3 < shadowed < 0.7
    # the checked test: (almost) no false shadows, fewer leaks than the old tolerance test
    old_false, old_leak, _ = _shadow_verdicts(shadow_verify=0, shadow_slack=1, shadow_bias=1)
    raw_false, _, _ = _shadow_verdicts(shadow_verify=0)
    assert false_shadow < 0.002 and raw_false > 0.05, (false_shadow, raw_false)
    assert leak < 0.9 * old_leak, (leak, old_leak)
    assert false_shadow < old_false


@pytest.mark.slow
def test_unseen_scenes_rank_vdm_honestly(variant):
    small = {"res": "96", "vdm_res": "64"}
    graze = {r["method"]: r for r in methods.methods_table(
        GRAZING, dict(small, angle="82", resolution="1024"), repeats=1)["rows"]}
    # at a grazing view on a real height map VDM beats bump mapping, in shadows too
    assert graze["approximation"]["flip"] < graze["bump"]["flip"]
    assert graze["approximation"]["flip_shadow"] < graze["bump"]["flip_shadow"]
    corners = methods.methods_table(CORNERS, dict(small, resolution="1536"), repeats=1)
    assert corners["mask_pixels"]["silhouette"] > 0
    rows = {r["method"]: r for r in corners["rows"]}
    for r in rows.values():
        assert np.isfinite(r["flip"])
