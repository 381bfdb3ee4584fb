"""`best` on a mesh base sized from the scene: the orthogonal families b / c are bounded by
what the referenced sensor resolves (at most 2 slices per pixel of the base's length along
u / v at the volume's nearest point), the slice buffers by ``max_memory_mb`` (predicted per
family and refused before anything is built), and ``build_stats["families"]`` reports each
family's slices, triangles, bytes and build time."""
import math

import mitsuba as mi
import numpy as np
import pytest

from tests.plugins.test_displaced_seams import write_obj

FOV, RES, HEIGHT = 40.0, 32, 4.0   # camera straight above the grid's centre


def grid_obj(path, n=8):
    """[-1, 1]^2 at z = 0 in n x n quads, uv = (x + 1) / 2 as the parametric plane's (Mitsuba's
    OBJ loader flips v: vt.y = 1 - v): the world length along u and v is 2."""
    x = np.linspace(-1, 1, n + 1)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    pos = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], 1)
    uvs = (pos[:, :2] + 1) / 2
    uvs[:, 1] = 1 - uvs[:, 1]
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = i.ravel(), i.ravel() + n + 1, i.ravel() + n + 2, i.ravel() + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return write_obj(path, pos, uvs, np.stack([faces, faces], -1))


def sensor():
    return {"type": "perspective", "fov": FOV, "id": "cam",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, HEIGHT], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"}}}


def shape(path, slices, scale, **kw):
    return {"type": "slicing", "base": "mesh", "filename": path, "slices": slices, "scale": scale,
            "direction": "best", "height": {"type": "bricks", "rows": 4, "columns": 2}, **kw}


def load(path, slices, scale, with_sensor=True, **kw):
    cam = sensor()
    d = {"type": "scene", "sensor": cam, "integrator": {"type": "raster"},
         "amb": {"type": "constant", "radiance": 1.0},
         "obj": shape(path, slices, scale, **({"sensor": mi.load_dict(cam)} if with_sensor else {}), **kw)}
    scene = mi.load_dict(d)
    return scene, next(s for s in scene.shapes() if hasattr(s, "build_stats"))


def test_sensor_bounds_the_orthogonal_families_and_memory_is_reported(variant, tmp_path):
    path = grid_obj(tmp_path / "grid.obj")
    slices, scale = 8, 0.1
    _, obj = load(path, slices, scale)
    fams = obj.build_stats["families"]
    # independent truth: the length 2 at the volume's top (depth HEIGHT - scale), seen
    # face-on, spans 2 f / depth pixels (f = RES / (2 tan(fov / 2)))
    pixels = 2 * RES / (2 * math.tan(math.radians(FOV / 2))) / (HEIGHT - scale)
    ratio = math.ceil(slices * 2 / scale)   # §3.4: the aligned spacing scale / N
    bound = math.ceil(2 * pixels)
    assert bound < ratio   # the sensor is what bounds them here
    for fam in "bc":
        assert abs(fams[fam]["slices"] - bound) <= 1, (fam, fams[fam], bound)
    assert fams["a"]["slices"] == slices
    # a b / c slice crosses both triangles of each of the 8 cells it passes: 16 quads of 2
    # triangles (one lying on a grid line may lose its segments); direction a is 8 copies
    # of the 128 base triangles
    assert fams["a"]["triangles"] == slices * 128
    for fam in "bc":
        assert 0.9 * 32 * fams[fam]["slices"] <= fams[fam]["triangles"] <= 32 * fams[fam]["slices"]
        assert fams[fam]["bytes"] > 0 and fams[fam]["build_s"] >= 0
    total = sum(f["bytes"] for f in fams.values())
    assert total <= obj.build_stats["bytes"] <= 512e6   # the default bound holds
    # without the sensor the ratio count stands
    _, free = load(path, slices, scale, with_sensor=False)
    assert free.build_stats["families"]["b"]["slices"] == ratio


def test_max_memory_refuses_before_building(variant, tmp_path, monkeypatch):
    from mi_displace.slicing import geometry as geo

    path = grid_obj(tmp_path / "grid.obj")
    _, obj = load(path, 8, 0.1)
    need = sum(f["bytes"] for f in obj.build_stats["families"].values()) / 1e6

    def never(*a, **k):
        raise AssertionError("a slice family was built")

    for name in ("orthogonal_slices", "aligned_slices", "volume_walls"):
        monkeypatch.setattr(geo, name, never)
    with pytest.raises((RuntimeError, ValueError), match=r"slicing: the slices would need .* MB .*max_memory_mb=") as err:
        load(path, 8, 0.1, max_memory_mb=need / 2)
    # the predicted size it names is the built one's (an upper bound within 1 %)
    named = float(str(err.value).split("would need ")[1].split(" MB")[0].replace(",", ""))
    assert need * 0.99 - 1 <= named <= need * 1.01 + 1


def test_image_unchanged_where_the_rule_keeps_everything(variant, tmp_path):
    path = grid_obj(tmp_path / "grid.obj")
    # scale 0.5: the ratio count (4 x 2 / 0.5 = 16) is below the sensor's bound
    scene_a, a = load(path, 4, 0.5, max_memory_mb=100)
    scene_b, b = load(path, 4, 0.5, with_sensor=False)
    assert a.build_stats["families"]["b"]["slices"] == b.build_stats["families"]["b"]["slices"] == 16
    img_a, img_b = (np.array(mi.render(s, spp=1)) for s in (scene_a, scene_b))
    assert np.all(np.isfinite(img_a)) and np.mean(img_a) > 0.05
    assert np.array_equal(img_a, img_b)


