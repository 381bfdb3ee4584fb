"""The bake CLI: progress, default formats, provenance in bake.json, the derived search distance."""
import datetime
import json

import numpy as np
import pytest
from bake_meshes import AMPLITUDE

from mi_displace.bake.baker import DISTANCE_FLOOR_REL, DISTANCE_MARGIN
from mi_displace.bake.formats import FORMATS
from mi_displace.bake.meshdata import save_obj
from mi_displace.cli import main


def test_version(capsys):
    import mi_displace

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"mi-displace {mi_displace.__version__}"


def test_bake_cli_defaults_progress_and_provenance(sphere_pair, tmp_path, capsys):
    high, low = sphere_pair
    save_obj(tmp_path / "high.obj", high.positions, high.faces)
    save_obj(tmp_path / "low.obj", low.positions, low.faces, low.uvs)
    before = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0)
    assert main(["bake", "--high", str(tmp_path / "high.obj"), "--low", str(tmp_path / "low.obj"),
                 "--res", "32", "--out", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    for stage in ("bake: inputs", "bake: search distance", "bake: acceleration", "rows 32/32",
                  "bake: padding", "bake: wrote"):
        assert stage in out, stage
    files = sorted(p.name for p in (tmp_path / "b").iterdir())
    assert files == ["bake.json", "d16.png", "d16.png.json", "low.obj", "mitsuba_displaced.xml",
                     "mitsuba_normalmap.xml", "mitsuba_normalmap_stock.xml", "mitsuba_restored.xml",
                     "normal_mitsuba.png", "normal_mitsuba.png.json", "normal_tangent.png",
                     "normal_tangent.png.json", "valid.png"]
    rec = json.loads((tmp_path / "b" / "bake.json").read_text())
    assert rec["inputs"]["high"] == str(tmp_path / "high.obj")
    assert rec["inputs"]["low"] == str(tmp_path / "low.obj")
    import mi_displace
    import mitsuba as mi

    assert rec["tool"]["mi_displace"] == mi_displace.__version__ and rec["tool"]["mitsuba"] == mi.__version__
    date = datetime.datetime.fromisoformat(rec["date"])
    assert before <= date <= datetime.datetime.now(datetime.timezone.utc)
    # the derived search distance: the low-poly sits within max |A h| = 1.25 A of the
    # high-poly, plus the chord sag of its 48 x 24 grid (< 0.01)
    rule = rec["settings"]["max_distance_rule"]
    h = rule["hausdorff_low_to_high"]
    assert 0.9 * 1.25 * AMPLITUDE < h < 1.25 * AMPLITUDE + 0.01
    assert np.isclose(rec["settings"]["max_distance"],
                      DISTANCE_MARGIN * h + DISTANCE_FLOOR_REL * rec["high"]["diagonal"])
    assert rec["counts"]["beyond"] == 0 and rec["counts"]["miss"] == 0
    assert main(["bake", "--high", str(tmp_path / "high.obj"), "--low", str(tmp_path / "low.obj"),
                 "--res", "16", "--out", str(tmp_path / "all"), "--formats", "all",
                 "--max-distance", "0.2"]) == 0
    rec = json.loads((tmp_path / "all" / "bake.json").read_text())
    # 'all' the inputs allow: the albedo formats need a colour source
    assert rec["settings"]["formats"] == [f for f in FORMATS if not f.startswith("albedo")] and rec["settings"]["max_distance_rule"]["rule"] == "given"
