"""Differentiable HDDM (issue 14, ddm part): ``height``, ``time`` and the tile's own vertex
positions, through mi.traverse, in both modes, against central finite differences of the
same scalar function of the mapped mesh (a fixed random weighting of vertex_positions)."""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

GENUS1 = str(Path(__file__).resolve().parents[2] / "scenes" / "parts" / "ddm_genus1" / "genus1.obj")
# on the mesh, tiles do not move in uv (no velocity / rotation; tile vertices perturbed in
# z only): a vertex off its chart is clamped to the chart's nearest boundary point, which
# jumps across the medial axis of the region off the chart — there the map is discontinuous
# and a finite difference measures the jump, not the derivative
BASES = {
    "sphere": dict(base="sphere", tile="thorn", tiles_u=4, tiles_v=2, height=0.2,
                   velocity_u=0.3, rotation_rate=0.5),
    "mesh": dict(base="mesh", filename=GENUS1, tile="stone", tiles_u=6, tiles_v=6, height=0.05),
}


def _setup(base, mode):
    shape = {"type": "ddm", **BASES[base], "mode": mode, "map_resolution": 64, "w_amplitude": 0.2}
    scene = mi.load_dict({"type": "scene", "s": shape})
    params = mi.traverse(scene)
    n = dr.width(params["s.vertex_positions"])
    weights = mi.Float(np.random.default_rng(1).standard_normal(n).astype(np.float32))
    return params, weights


def _loss(params, weights):
    return dr.sum(params["s.vertex_positions"] * weights)


@pytest.mark.parametrize("base", list(BASES))
@pytest.mark.parametrize("mode", ["exact", "maps"])
def test_height_time_and_tile_vertices_have_finite_difference_gradients(variant, base, mode):
    params, weights = _setup(base, mode)
    tile0 = mi.Vector3f(params["s.tile_positions"])
    delta = mi.Vector3f(*(mi.Float(np.random.default_rng(k).standard_normal(
        dr.width(tile0)).astype(np.float32) * (1.0 if base == "sphere" or k == 2 else 0.0))
        for k in range(3)))

    def value_at(key, x):
        params[key] = x
        params.update()
        out = float(_loss(params, weights)[0])
        assert np.all(np.isfinite(np.asarray(params["s.vertex_positions"])))
        return out

    # steps: large enough that float32 rounding of the loss (~1e-3 here) stays far below
    # the difference, small enough for the curvature of the map (height and tile z enter
    # linearly; time through sin, tile x, y through S)
    cases = [("s.height", mi.Float(BASES[base]["height"]), mi.Float(1.0), 1e-2),
             ("s.time", mi.Float(0.1), mi.Float(1.0), 1e-2),
             ("s.tile_positions", tile0, delta, 1e-2)]
    for key, x0, direction, h in cases:
        x = type(x0)(x0)
        dr.enable_grad(x)
        params[key] = x
        params.update()
        dr.backward(_loss(params, weights))
        grad = dr.grad(params[key])
        ad = float(dr.sum(dr.sum(grad * direction))[0]) if key.endswith("positions") else float(grad[0])
        fd = (value_at(key, x0 + h * direction) - value_at(key, x0 - h * direction)) / (2 * h)
        value_at(key, type(x0)(x0))
        assert np.isfinite(ad) and ad != 0.0, (key, ad)
        assert abs(ad - fd) <= 0.03 * abs(fd) + 1e-3, (key, ad, fd)


def test_metamorphosis_is_differentiable_in_time(variant):
    scene = mi.load_dict({"type": "scene", "s": {
        "type": "ddm", "base": "sphere", "tile": "thorn", "tile_target": "flower", "tiles_u": 4,
        "tiles_v": 2, "alpha_rate": 1.0, "mode": "maps", "map_resolution": 32}})
    params = mi.traverse(scene)
    weights = mi.Float(np.random.default_rng(0).standard_normal(
        dr.width(params["s.vertex_positions"])).astype(np.float32))

    def value(t):
        params["s.time"] = mi.Float(t)
        params.update()
        return float(_loss(params, weights)[0])

    x = mi.Float(0.4)
    dr.enable_grad(x)
    params["s.time"] = x
    params.update()
    dr.backward(_loss(params, weights))
    ad, fd = float(dr.grad(params["s.time"])[0]), (value(0.41) - value(0.39)) / 0.02
    assert ad != 0.0 and abs(ad - fd) <= 0.03 * abs(fd)
