"""The `ddm` shape plugin: loading, traverse-driven animation, stats, bad input."""
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.ddm.model import DDMConfig, DDMModel

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def ddm(**kw):
    return mi.load_dict({"type": "ddm", **kw})


def buffers(shape):
    p = mi.traverse(shape)
    return (np.asarray(p["vertex_positions"]).reshape(-1, 3), np.asarray(p["faces"]).reshape(-1, 3),
            np.asarray(p["vertex_normals"]).reshape(-1, 3))


def test_both_modes_load_with_stats(variant):
    for mode in ("exact", "maps", "reference", "approximation"):
        s = ddm(base="torus", tile="hexagon", layout="hex", tiles_u=12, tiles_v=8, height=0.05,
                mode=mode, map_resolution=64)
        st = s.build_stats
        assert st["vertices"] == s.vertex_count() and st["faces"] == s.face_count()
        assert st["mesh_bytes"] > st["hddm_bytes"] - st["maps_bytes"]
        pos, faces, nrm = buffers(s)
        assert np.all(np.isfinite(pos)) and np.allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-5)
        assert "DDM[" in str(s)


def test_to_world_applies(variant):
    plain = buffers(ddm(base="sphere", tile="stone", tiles_u=6, tiles_v=3))[0]
    moved = buffers(ddm(base="sphere", tile="stone", tiles_u=6, tiles_v=3,
                        to_world=mi.ScalarTransform4f().translate([5, 0, 0]).scale(2.0)))[0]
    assert np.allclose(moved, plain * 2 + [5, 0, 0], atol=1e-5)


def test_traverse_time_and_height_remap_in_place(variant):
    kw = dict(base="sphere", tile="thorn", tile_target="flower", tiles_u=8, tiles_v=4,
              height=0.2, alpha_rate=1.0, velocity_u=0.25, mode="maps", map_resolution=32)
    scene = mi.load_dict({"type": "scene", "s": {"type": "ddm", "id": "s", **kw}})
    shape = scene.shapes()[0]
    _, faces0, _ = buffers(shape)
    params = mi.traverse(scene)
    assert "s.time" in params and "s.height" in params
    params["s.time"] = 0.75
    params["s.height"] = 0.3
    params.update()
    pos, faces, nrm = buffers(shape)
    assert np.array_equal(faces, faces0)               # no rebuild: same topology
    cfg = DDMConfig(base="sphere", tile="thorn", tile_target="flower", tiles_u=8, tiles_v=4,
                    height=0.3, time=0.75, mode="maps", map_resolution=32)
    cfg.animation.alpha_rate, cfg.animation.velocity_u = 1.0, 0.25
    p, _, _ = DDMModel(cfg).map()
    expect = np.stack([np.asarray(c) for c in p], 1)
    assert np.allclose(pos, expect, atol=1e-6)
    assert scene.bbox().max.z == pytest.approx(pos[:, 2].max(), abs=1e-4)
    params["s.time"] = float("nan")
    with pytest.raises(ValueError, match="time"):
        params.update()


def test_animate_time_writes_one_image_per_time(variant, tmp_path):
    """``ddm-animate`` is the generic ``animate`` of ``ID.time``: the tiles move per frame."""
    from mi_displace.core.io import read_png
    from mi_displace.evaluate.frames import animate

    params = {"mode": "approximation", "integrator": "raster", "res": "32"}
    r = animate(SCENES / "ddm_teapot_morph.xml", [("morph.time", 0.0, 1.5)], 3, tmp_path,
                params=params)
    imgs = [read_png(p) for p in r["frames"]]
    assert [e["morph.time"] for e in r["edits"]] == pytest.approx([0.0, 0.5, 1.0])
    assert len(imgs) == 3 and all(i.shape == (32, 32, 3) and i.mean() > 0 for i in imgs)
    assert np.abs(imgs[0] - imgs[2]).mean() > 1e-3      # the tiles moved / morphed
    with pytest.raises(ValueError, match="nope.time"):
        animate(SCENES / "ddm_teapot_morph.xml", [("nope.time", 0.0, 1.0)], 1, tmp_path,
                params=params)


@pytest.mark.parametrize("kw, match", [
    (dict(mode="fast"), "mode"),
    (dict(base="cube"), "base"),
    (dict(tile="spiky"), "tile"),
    (dict(normals="smooth"), "normals"),
    (dict(layout="spiral"), "layout"),
    (dict(map_resolution=0), "map_resolution"),
    (dict(tiles_u=0), "tiles_u"),
    (dict(height=float("inf")), "height"),
    (dict(epsilon=0.0), "epsilon"),
    (dict(base="mesh"), "filename"),
    (dict(base="sphere", radius=-1.0), "radius"),
    (dict(tile="thorn", tile_target="hair"), "compatible"),
    (dict(velocity_u=float("nan")), "velocity_u"),
])
def test_bad_input_names_the_parameter(variant, kw, match):
    with pytest.raises(Exception, match=match) as info:
        ddm(**kw)
    assert isinstance(info.value, (ValueError, RuntimeError))


def test_missing_files_are_named(variant, tmp_path):
    with pytest.raises(Exception, match="tile file .*missing.ply"):
        ddm(tile=str(tmp_path / "missing.ply"))
    with pytest.raises(Exception, match="nothing.obj"):
        ddm(base="mesh", filename=str(tmp_path / "nothing.obj"))


def test_auto_map_resolution(variant):
    s = ddm(base="sphere", tile="stone", tiles_u=8, tiles_v=4, map_resolution="auto",
            tolerance=1e-3, height=0.1)
    assert s.build_stats["map_resolution"] == 64 and len(s.build_stats["auto_trials"]) >= 2
    # mesh bases (no sensor known to a plain load): the tolerance rule on per-chart maps
    g = ddm(base="mesh", filename=str(SCENES / "parts" / "ddm_genus1" / "genus1.obj"),
            tile="chain", tiles_u=16, tiles_v=16, height=0.05, map_resolution="auto",
            tolerance=1e-3)
    st = g.build_stats
    assert st["map_resolution_rule"].startswith("auto: tolerance")
    errors = dict(st["auto_trials"])
    assert errors[st["map_resolution"]] <= 1e-3 < errors[32]
    with pytest.raises(Exception, match="map_resolution"):
        ddm(map_resolution="fine")


def test_far_from_the_origin_in_float32(variant):
    far = buffers(ddm(base="torus", tile="stone", tiles_u=12, tiles_v=6, height=0.05,
                      to_world=mi.ScalarTransform4f().translate([1e4, -2e4, 5e3])))
    near = buffers(ddm(base="torus", tile="stone", tiles_u=12, tiles_v=6, height=0.05))
    assert np.all(np.isfinite(far[0])) and np.array_equal(far[1], near[1])
    # float32 spacing at 2e4 is ~2e-3: the shape survives to that precision
    assert np.abs(far[0] - [1e4, -2e4, 5e3] - near[0]).max() < 4e-3
    assert np.allclose(far[2], near[2], atol=1e-5)
