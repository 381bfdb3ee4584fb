"""The Mitsuba scene fragments a bake writes: each loads in a scene and renders; the
``displaced`` one carries the scale / midlevel that put the surface on the high-poly."""
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.bake.baker import bake
from mi_displace.bake.mitsuba_frames import prepare_scene
from mi_displace.evaluate.metrics import point_mesh_distance

SCENE = """<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0.5, 1, 3.5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film>
    </sensor>
    <emitter type="directional"><vector name="direction" value="-1, -1, -1"/></emitter>
    <include filename="{fragment}"/>
</scene>"""


@pytest.fixture
def baked(sphere_pair, built_once, tmp_path_factory):
    """(high, low, bake result, its folder): the sphere pair baked at 64² once per run (read
    only)."""
    def build():
        high, low = sphere_pair
        out = tmp_path_factory.mktemp("bake_out")
        return high, low, bake(high, low, res=64, out_dir=out, max_distance=0.2), out

    return built_once("fragments", build)


def _render(fragment: Path):
    scene = mi.load_string(SCENE.format(fragment=fragment))
    prepare_scene(scene)
    image = np.asarray(mi.render(scene, spp=4))
    return scene, image


@pytest.mark.parametrize("name", ["mitsuba_displaced.xml", "mitsuba_restored.xml",
                                  "mitsuba_normalmap.xml", "mitsuba_normalmap_stock.xml"])
def test_every_fragment_loads_and_renders(baked, name):
    _, _, r, out = baked
    assert name in r.record["files"]
    scene, image = _render(out / name)
    assert np.all(np.isfinite(image)) and image.mean() > 0.02, name
    assert len(scene.shapes()) == 1


def test_displaced_fragment_puts_the_surface_on_the_high_poly(baked):
    """scale = 65535 s and midlevel = -offset / scale (d16): the displaced vertices lie on the
    high-poly, far closer than the low-poly's own vertices do."""
    high, low, _, out = baked
    scene, _ = _render(out / "mitsuba_displaced.xml")
    shape = scene.shapes()[0]
    p = np.asarray(mi.traverse(shape)["vertex_positions"]).reshape(-1, 3)
    assert len(p) > 4 * len(low.positions)
    tm = high.to_trimesh()
    on_high = point_mesh_distance(p.astype(np.float64), tm)
    low_gap = point_mesh_distance(low.positions.astype(np.float64), tm)
    assert np.all(np.isfinite(on_high))
    assert on_high.mean() < 0.1 * low_gap.mean() and on_high.max() < 0.3 * low_gap.max()


def test_bake_preview_renders_every_fragment_and_decodes_the_normal_maps(sphere_pair, tmp_path, capsys):
    """``bake --preview``: preview.png (high-poly + six ways, their FLIP maps) and
    preview.json; both exact normal-map decodes within the 8-bit step of the object-space
    bake at every texel centre, the stock decode of the MikkTSpace map not."""
    import json

    from mi_displace.bake.meshdata import save_obj
    from mi_displace.cli import main

    high, low = sphere_pair
    save_obj(tmp_path / "high.obj", high.positions, high.faces)
    save_obj(tmp_path / "low.obj", low.positions, low.faces, low.uvs)
    assert main(["bake", "--high", str(tmp_path / "high.obj"), "--res", "64", "--target-faces",
                 "400", "--out", str(tmp_path / "b"), "--max-distance", "0.2", "--preview"]) == 0
    assert "preview (FLIP" in capsys.readouterr().out
    numbers = json.loads((tmp_path / "b" / "preview.json").read_text())
    ways = ["displaced", "restored", "mikk", "stock", "stock_on_mikk", "no_map"]
    assert numbers["columns"] == ["high-poly", *ways]
    for way in ways:
        assert 0 < numbers[way]["flip"] < 1 and np.isfinite(numbers[way]["flip_border"])
    image = np.asarray(mi.Bitmap(str(tmp_path / "b" / "preview.png")))
    assert image.shape[:2] == (2 * 256, 7 * 256) and image.max() > 0
    decode = numbers["decode"]
    assert decode["mikk"]["max_deg"] < 1 and decode["stock"]["max_deg"] < 1
    assert decode["stock_on_mikk"]["over_1deg"] > 0.05 * decode["stock_on_mikk"]["texels"]
