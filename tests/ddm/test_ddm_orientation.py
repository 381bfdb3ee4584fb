"""Orientation of mapped tiles: mirrored UV charts, a w scale that changes sign, long
animations, and integer parameters."""
import math

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.ddm.animation import Animation
from mi_displace.ddm.model import DDMConfig, DDMModel

# two unit quads side by side in z = 0 (normal +z); the right one's UV chart is mirrored
MIRRORED = """v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0
vt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nvt 1 0\nvt 0.5 0\nvt 0.5 1\nvt 1 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\nf 5/5/1 6/6/1 7/7/1\nf 5/5/1 7/7/1 8/8/1
"""


def _np(v):
    return np.stack([np.asarray(c) for c in v], 1)


def face_normals(pos, faces):
    n = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)


@pytest.mark.parametrize("mode", ["exact", "maps"])
def test_tiles_on_a_mirrored_uv_chart_face_outwards(variant, tmp_path, mode):
    (tmp_path / "m.obj").write_text(MIRRORED)
    m = DDMModel(DDMConfig(base="mesh", filename=str(tmp_path / "m.obj"), tile="stone:1",
                           tiles_u=8, tiles_v=4, height=0.1, mode=mode, map_resolution=64,
                           normals="jacobian"))
    assert np.any(np.asarray(m.chart_orientation) < 0) and np.any(np.asarray(m.chart_orientation) > 0)
    pos, nrm, _ = (_np(x) for x in m.map())
    faces = _np(m.faces).astype(np.int64)
    up = pos[:, 2] > 0.05 * pos[:, 2].max()                      # the stones' upper parts
    assert np.mean(nrm[up, 2] > 0) > 0.97
    fn = face_normals(pos, faces)
    agree = np.einsum("ij,ij->i", fn, nrm[faces].mean(1))
    assert np.median(agree) > 0.9                                   # winding follows the normals


def test_negative_w_scale_rewinds_like_a_fresh_build(variant):
    kw = dict(type="ddm", base="sphere", tile="thorn", tiles_u=8, tiles_v=4, mode="exact")
    shape = mi.load_dict({**kw, "height": 0.2, "id": "s"})
    params = mi.traverse(shape)
    params["height"] = -0.2
    params.update()
    fresh = mi.load_dict({**kw, "height": -0.2})
    a, b = mi.traverse(shape), mi.traverse(fresh)
    assert np.array_equal(np.asarray(a["faces"]), np.asarray(b["faces"]))
    na, nb = (np.asarray(p["vertex_normals"]).reshape(-1, 3) for p in (a, b))
    assert np.allclose(na, nb, atol=1e-6)
    # and a w factor that turns negative during the animation (w_amplitude > 1)
    m = DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=8, tiles_v=4, mode="exact",
                           height=0.2, animation=Animation(w_amplitude=2.0, w_frequency=1.0)))
    scale = 0.2 * m.cfg.animation.w_factor(0.75)                   # 0.2 * (1 - 2) < 0
    _, n_anim, _ = m.map(t=0.75)
    ref = DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=8, tiles_v=4, mode="exact",
                             height=scale))
    _, n_ref, _ = ref.map()
    assert np.allclose(_np(n_anim), _np(n_ref), atol=1e-5)
    assert np.array_equal(_np(m.faces), _np(ref.faces))


def test_rotation_turns_tiles_about_their_centre(variant):
    cfg = dict(base="plane", tile="hexagon", tiles_u=1, tiles_v=1, height=0.1, mode="exact")
    still = DDMModel(DDMConfig(**cfg))
    turning = DDMModel(DDMConfig(**cfg, animation=Animation(rotation_rate=math.pi / 2)))
    p0, p1 = _np(still.map()[0]), _np(turning.map(t=1.0)[0])
    c = p0[:, :2].mean(0)
    rotated = (p0[:, :2] - c) @ np.array([[0, 1], [-1, 0]]) + c     # +90 degrees
    assert np.allclose(p1[:, :2], rotated, atol=1e-5) and np.allclose(p1[:, 2], p0[:, 2])


def test_long_animations_keep_float32_precision_on_periodic_bases(variant):
    m = DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=8, tiles_v=4, height=0.2,
                           mode="maps", map_resolution=64, animation=Animation(velocity_u=1.0)))
    early, late = _np(m.map(t=0.25)[0]), _np(m.map(t=1e6 + 0.25)[0])
    assert np.abs(early - late).max() < 1e-5


@pytest.mark.parametrize("key, value", [("tiles_u", 2.5), ("tiles_v", 0), ("seed", -1),
                                        ("map_resolution", 64.7)])
def test_integer_parameters_are_not_truncated(variant, key, value):
    with pytest.raises(Exception, match=f"ddm: parameter '{key}' must (be an integer|lie in)"):
        mi.load_dict({"type": "ddm", "base": "plane", "tile": "hexagon", key: value})


def test_non_finite_time_is_refused(variant):
    m = DDMModel(DDMConfig(base="plane", tile="hexagon", tiles_u=2, tiles_v=2))
    with pytest.raises(ValueError, match="'time' must be finite"):
        m.map(t=math.inf)
