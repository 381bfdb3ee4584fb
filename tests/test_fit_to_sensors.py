"""One way to fit a scene: ``mi.load_file`` + ``mi_displace.fit_to_sensors(scene)`` gives the
same build and the same image as the CLI's loader, for every shape that sizes itself from
the scene's sensors."""
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

import mi_displace
from mi_displace.render.scene import load

BUNNY_MAP = Path(__file__).resolve().parents[1] / "scenes" / "parts" / "bake_bunny" / "d16.png"

SHAPES = {
    "displaced": """<shape type="displaced" id="s"><string name="base" value="sphere"/>
        <texture type="cells" name="height"/><float name="scale" value="0.1"/>
        <float name="dicing_rate" value="4"/></shape>""",
    "ddm": """<shape type="ddm" id="s"><string name="base" value="sphere"/>
        <string name="tile" value="stone"/><integer name="tiles_u" value="8"/>
        <integer name="tiles_v" value="4"/><string name="mode" value="maps"/>
        <string name="map_resolution" value="auto"/></shape>""",
    "restored": f"""<shape type="restored" id="s"><string name="map" value="{BUNNY_MAP}"/>
        <string name="levels" value="auto"/></shape>""",
}

#: build_stats keys that depend on the sensors (the rest are timings and the like)
SIZED = {"displaced": ("faces", "vertices"), "ddm": ("map_resolution", "map_resolution_rule", "vertices"),
         "restored": ("levels", "faces", "rule")}


def _scene(tmp_path, shape: str, distance: float) -> Path:
    path = tmp_path / "scene.xml"
    path.write_text(f"""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <emitter type="constant"/>
  <sensor type="perspective"><float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0, -{distance}, 0.5" target="0, 0, 0" up="0, 0, 1"/></transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film>
  </sensor>
  {shape}
</scene>""")
    return path


@pytest.mark.parametrize("plugin", list(SHAPES))
def test_load_file_plus_fit_equals_the_cli_loader(variant, plugin, tmp_path):
    # a camera at which the fit differs from the sensor-free build
    path = _scene(tmp_path, SHAPES[plugin], 6.0 if plugin == "ddm" else 3.0)
    ours, _ = load(path)
    theirs = mi.load_file(str(path))
    before = dict(theirs.shapes()[0].build_stats)
    assert mi_displace.fit_to_sensors(theirs) == ["s"]            # it was not yet fitted
    a, b = ours.shapes()[0].build_stats, theirs.shapes()[0].build_stats
    assert any(before.get(k) != b.get(k) for k in SIZED[plugin]), (before, b)
    assert {k: a.get(k) for k in SIZED[plugin]} == {k: b.get(k) for k in SIZED[plugin]}
    img_a = np.asarray(mi.render(ours, seed=3))
    img_b = np.asarray(mi.render(theirs, seed=3))
    assert np.isfinite(img_a).all() and img_a.mean() > 0
    # the same geometry; two acceleration structures built on worker threads may split
    # ties differently, so hit points agree to float rounding, not bit for bit
    np.testing.assert_allclose(img_a, img_b, rtol=0, atol=1e-5)
    assert mi_displace.fit_to_sensors(theirs) == []               # fitted: nothing to redo
