"""The displaced surface's builder (mi_displace.core.displaced) used alone, without a mi.Mesh:
uniform and diced builds land at the analytic radius, and a refit rebuilds only when the
sensors changed."""
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.displaced import DisplacedSurface


def values(**given) -> dict:
    """The plugin's declared defaults with ``given`` on top (what SPEC.read returns)."""
    from mi_displace.plugins.displaced import SPEC   # a mi.Mesh subclass: needs the variant
    out = {p.name: p.default for p in SPEC.all_params()}
    out.update(given)
    return out


def radii(built, centre) -> np.ndarray:
    p = np.asarray(built.positions, np.float64).reshape(-1, 3)
    assert np.all(np.isfinite(p)) and np.all(np.isfinite(np.asarray(built.normals)))
    return np.linalg.norm(p - centre, axis=1)


def camera(distance: float):
    return mi.load_dict({"type": "perspective", "fov": 40,
                         "to_world": mi.ScalarTransform4f().look_at([0, -distance, 0], [0, 0, 0], [0, 0, 1]),
                         "film": {"type": "hdrfilm", "width": 64, "height": 64}})


def test_uniform_build_is_the_displaced_sphere_in_world_space(variant):
    """Sphere radius 2, constant height 0.75, midlevel 0.25, scale 0.2, moved by (1, 2, 3):
    every vertex at distance 2 + 0.2 (0.75 - 0.25) = 2.1 from (1, 2, 3), unit normals along
    the radius, the counts in build_stats those of the buffers."""
    height = mi.load_dict({"type": "uniform", "value": 0.75})
    surface = DisplacedSurface(values(base="sphere", radius=2.0, height=height, scale=0.2,
                                      midlevel=0.25, resolution=16), {"resolution"}, [],
                               mi.ScalarTransform4f().translate([1, 2, 3]), "ball")
    built = surface.build_mesh()
    centre = np.array([1, 2, 3])
    assert np.allclose(radii(built, centre), 2.1, atol=1e-5)
    p = np.asarray(built.positions).reshape(-1, 3) - centre
    n = np.asarray(built.normals).reshape(-1, 3)
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
    assert np.allclose(np.sum(n * p, axis=1) / 2.1, 1, atol=1e-3)
    assert built.vertex_count == len(p) == built.stats["vertices"]
    assert built.face_count == len(np.asarray(built.faces)) // 3 == built.stats["faces"]
    assert built.stats["mode"] == "uniform" and built.stats["crossing_vertices"] == 0


def test_dicing_refits_only_when_the_sensors_change(variant):
    """Without sensors the build is coarse and warns; the first fit dices finer, an identical
    refit rebuilds nothing, a camera twice as close dices finer still; all at radius
    1 + 0.1 (0.5 - 0)."""
    height = mi.load_dict({"type": "uniform", "value": 0.5})
    surface = DisplacedSurface(values(base="sphere", height=height, dicing_rate=2.0),
                               {"dicing_rate"}, [], mi.ScalarTransform4f(), "ball")
    with pytest.warns(UserWarning, match="needs a sensor"):
        coarse = surface.build_mesh()
    far = surface.fit_to_sensors([camera(6.0)])
    assert far is not None and far.stats["sensors"] == 1 and far.face_count > coarse.face_count
    assert surface.fit_to_sensors([camera(6.0)]) is None
    near = surface.fit_to_sensors([camera(3.0)])
    assert near is not None and near.face_count > far.face_count
    for built in (coarse, far, near):
        assert np.allclose(radii(built, 0), 1.05, atol=1e-5)
