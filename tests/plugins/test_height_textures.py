"""The ``ripples`` / ``bricks`` / ``cells`` texture plugins: loading, agreement with the core
patterns, ``to_uv`` chain rule, traversal, validation, and use inside ``bumpmap``.

``variant`` (tests/conftest.py) sets each available variant and registers the plugins."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

NAMES = ["ripples", "bricks", "cells"]


def interaction(u, v):
    si = dr.zeros(mi.SurfaceInteraction3f, len(u))
    si.uv = mi.Point2f(u, v)
    return si


def points(n=2000, seed=5):
    rng = np.random.default_rng(seed)
    return rng.random(n), rng.random(n)


def core(name, u, v, **params):
    from mi_displace.core import heightfield as hf
    h, g = hf.evaluate(name, mi.Point2f(u, v), **params)
    return h.numpy(), g.numpy()


@pytest.mark.parametrize("name, props, params", [
    ("ripples", dict(frequency=3.0, frequency_v=2.0, phase=0.5),
     dict(frequency=(3, 2), phase=0.5)),
    ("bricks", dict(rows=6, columns=3, mortar=0.05, bevel=0.2),
     dict(rows=6, columns=3, mortar=0.05, bevel=0.2)),
    ("cells", dict(cells=5, radius=0.7, jitter=0.5, seed=9),
     dict(cells=5, radius=0.7, jitter=0.5, seed=9)),
])
def test_plugin_matches_core(variant, name, props, params):
    tex = mi.load_dict({"type": name, **props})
    u, v = points()
    si = interaction(u, v)
    h0, g0 = core(name, u, v, **params)
    np.testing.assert_array_equal(tex.eval_1(si).numpy(), h0)
    np.testing.assert_array_equal(tex.eval_1_grad(si).numpy(), g0)
    rgb = tex.eval(si).numpy()
    assert rgb.shape == (3, len(u))
    np.testing.assert_array_equal(rgb, np.broadcast_to(h0, rgb.shape))
    np.testing.assert_array_equal(tex.eval_3(si).numpy(), rgb)
    assert tex.is_spatially_varying()
    assert name.capitalize() in str(tex)


def test_defaults_and_mean(variant):
    from mi_displace.core import heightfield as hf
    for name in NAMES:
        tex = mi.load_dict({"type": name})
        expected = hf.PATTERNS[name][2](**hf.pattern_defaults(name))
        assert float(tex.mean()[0]) == pytest.approx(expected, rel=1e-6)
        # mean() agrees with a midpoint-rule average of eval_1 itself
        m = 1024
        t = (np.arange(m) + 0.5) / m
        u, v = (x.ravel() for x in np.meshgrid(t, t))
        assert float(np.mean(tex.eval_1(interaction(u, v)).numpy())) == pytest.approx(
            expected, abs=2e-3)


def test_xml_with_to_uv_scale_chain_rule(variant):
    xml = """<texture version="3.0.0" type="{name}">
        <transform name="to_uv"><scale x="2" y="2"/></transform>
    </texture>"""
    u, v = points(seed=11)
    for name in NAMES:
        tex = mi.load_string(xml.format(name=name))
        si = interaction(u, v)
        h0, g0 = core(name, 2 * u, 2 * v)
        np.testing.assert_allclose(tex.eval_1(si).numpy(), h0, atol=1e-6)
        np.testing.assert_allclose(tex.eval_1_grad(si).numpy(), 2 * g0, rtol=1e-5, atol=1e-4)


def test_to_uv_affine_gradient_by_finite_differences(variant):
    # rotation + anisotropic scale + translation: the gradient needs A^T, not A
    to_uv = (mi.ScalarTransform4f().translate([0.3, -0.2, 0])
             @ mi.ScalarTransform4f().rotate([0, 0, 1], 30)
             @ mi.ScalarTransform4f().scale([2, 1, 1]))
    tex = mi.load_dict({"type": "ripples", "frequency": 2, "to_uv": to_uv})
    u, v = points(seed=2)
    g = tex.eval_1_grad(interaction(u, v)).numpy()
    eps = 1e-3
    fd = [(tex.eval_1(interaction(u + du, v + dv)).numpy().astype(np.float64)
           - tex.eval_1(interaction(u - du, v - dv)).numpy()) / (2 * eps)
          for du, dv in [(eps, 0), (0, eps)]]
    # |A| <= 2, f = 2: |d^3 h| <= 1/2 (2 pi 2 * 2)^3 -> eps^2/6 bound 1.3e-2; rounding ~ 2e-3
    np.testing.assert_allclose(np.array(fd), g, atol=2e-2)
    assert np.abs(g).max() > 10


def test_traverse_and_update(variant):
    tex = mi.load_dict({"type": "ripples", "frequency": 2})
    params = mi.traverse(tex)
    assert set(params.keys()) == {"frequency_u", "frequency_v", "phase", "to_uv"}
    u, v = points(seed=3)
    params["frequency_u"] = 5.0
    params["to_uv"] = mi.ScalarTransform3f().scale(3.0)
    params.update()
    h0, g0 = core("ripples", 3 * u, 3 * v, frequency=(5, 2))
    si = interaction(u, v)
    # 3u rounds differently in float32 (plugin) and float64 (here): G * 3 * 2^-24 ~ 3e-6
    np.testing.assert_allclose(tex.eval_1(si).numpy(), h0, atol=2e-5)
    np.testing.assert_allclose(tex.eval_1_grad(si).numpy(), 3 * g0, rtol=1e-4, atol=2e-3)
    params["frequency_v"] = -1.0
    with pytest.raises(ValueError, match="ripples: parameter 'frequency_v'"):
        params.update()


@pytest.mark.parametrize("name, props, match", [
    ("ripples", dict(frequency=-2.0), "'frequency'"),
    ("ripples", dict(frequency_v=0.0), "'frequency_v'"),
    ("ripples", dict(phase="east"), "'phase'"),
    ("bricks", dict(rows=0), "'rows'"),
    ("bricks", dict(columns=2.5), "'columns'"),
    ("bricks", dict(mortar=0.6), "'mortar'"),
    ("bricks", dict(bevel=-0.1), "'bevel'"),
    ("cells", dict(cells=0), "'cells'"),
    ("cells", dict(radius=0.0), "'radius'"),
    ("cells", dict(jitter=2.0), "'jitter'"),
    ("cells", dict(seed=0.5), "'seed'"),
    ("cells", dict(to_uv=lambda: mi.ScalarTransform4f().scale([math.inf, 1, 1])), "'to_uv'"),
])
def test_bad_properties(variant, name, props, match):
    props = {k: v() if callable(v) else v for k, v in props.items()}  # built after the variant
    # Mitsuba's loader wraps the plugin's ValueError in a RuntimeError that quotes it.
    with pytest.raises(RuntimeError, match=f"ValueError: {name}: parameter {match}"):
        mi.load_dict({"type": name, **props})
    # Read and built directly, the ValueError itself propagates.
    from mi_displace.plugins import bricks, cells, ripples
    module = {"ripples": ripples, "bricks": bricks, "cells": cells}[name]
    cls = getattr(module, name.capitalize())
    p = mi.Properties(name)
    for key, value in props.items():
        p[key] = value
    with pytest.raises(ValueError, match=f"{name}: parameter {match}"):
        cls(p, module.SPEC.read(p))


def test_unknown_property_is_rejected(variant):
    with pytest.raises(RuntimeError, match="frequncy"):
        mi.load_dict({"type": "ripples", "frequncy": 3.0})


def render_sphere(texture, size=24):
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.7}}
    if texture is not None:
        bsdf = {"type": "bumpmap", "height": texture, "bsdf": bsdf}
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "sun": {"type": "directional", "direction": [1, -1, -1], "irradiance": 3.0},
    })
    return np.asarray(mi.render(scene, seed=0))


def bitmap_of(texture, n=512):
    """Mitsuba's own ``bitmap`` texture (bilinear, raw) holding ``texture`` sampled at the
    centres of an n x n grid (row j at v = (j + 0.5) / n, Mitsuba's convention): its
    ``eval_1_grad`` is Mitsuba's derivative of the bilinear interpolant, an independent
    gradient of the same heights."""
    centres = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(centres, centres)
    heights = texture.eval_1(interaction(u.ravel(), v.ravel())).numpy().reshape(n, n, 1)
    return mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(heights.astype(np.float32)),
                         "raw": True, "filter_type": "bilinear"})


def bump_agreement(texture):
    """``(|ours - bitmap|, |bitmap - plain|)``: mean pixel differences of the bump-mapped
    sphere shaded with ``texture``'s analytic gradient and with Mitsuba's bitmap of it,
    and of that bitmap rendering against the plain sphere (the size of the bump effect)."""
    plain = render_sphere(None)
    ours = render_sphere(texture)
    reference = render_sphere(bitmap_of(texture))
    for image in (plain, ours, reference):
        assert np.all(np.isfinite(image)) and image.max() > 0.1
    return np.abs(ours - reference).mean(), np.abs(reference - plain).mean()


BUMP_TOLERANCE = 0.15  # |ours - bitmap| as a fraction of the bump effect |bitmap - plain|
# patterns coarse enough that the pixels resolve each bump: a finer one averages its lit and
# unlit sides inside a pixel, and the sign of the gradient no longer shows
COARSE = {"ripples": {"frequency": 3.0}, "bricks": {"rows": 4, "columns": 2}, "cells": {"cells": 3}}


@pytest.mark.parametrize("name", NAMES)
def test_bumpmap_shading_matches_mitsubas_bitmap_gradient(variant, name):
    """Same seed and samples: the only difference between the renderings is the shading
    normal, i.e. the gradient (measured: 0.3-3.4 % of the bump effect; the bitmap's texel-wise
    bilinear derivative is not exactly the analytic one)."""
    difference, effect = bump_agreement(mi.load_dict({"type": name, **COARSE[name]}))
    assert effect > 0.02 and difference < BUMP_TOLERANCE * effect, (difference, effect)


@pytest.mark.parametrize("name", NAMES)
def test_bumpmap_check_fails_for_a_gradient_of_the_wrong_sign(variant, name):
    """Fault injection: the same texture with its gradient negated fails the check above
    (measured: 43-77 % of the bump effect)."""
    import importlib

    module = importlib.import_module(f"mi_displace.plugins.{name}")

    class Flipped(getattr(module, name.capitalize())):
        def eval_1_grad(self, si, active=True):
            return -super().eval_1_grad(si, active)

    mi.register_texture(f"test_flipped_{name}", lambda props: Flipped(props, module.SPEC.read(props)))
    difference, effect = bump_agreement(
        mi.load_dict({"type": f"test_flipped_{name}", **COARSE[name]}))
    assert difference > BUMP_TOLERANCE * effect, (difference, effect)
