"""The ddm sub-commands of mi-displace."""
import json
from pathlib import Path

import pytest

from mi_displace import cli

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def test_ddm_animate_writes_frames(variant_llvm, tmp_path):
    rc = cli.main(["ddm-animate", str(SCENES / "ddm_teapot_morph.xml"), "--shape", "morph",
                   "-D", "mode=approximation", "-D", "integrator=raster", "-D", "res=24",
                   "--frames", "2", "--duration", "0.5", "--out", str(tmp_path)])
    assert rc == 0 and sorted(p.name for p in tmp_path.iterdir()) == [
        "frame_0000.png", "frame_0001.png", "frames.json"]
    # an alias of the generic animate: ID.time over [0, duration)
    edits = [f["edits"] for f in json.loads((tmp_path / "frames.json").read_text())["frames"]]
    assert edits == [{"morph.time": 0.0}, {"morph.time": 0.25}]


def test_ddm_animate_bad_shape_id(variant_llvm, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["ddm-animate", str(SCENES / "ddm_teapot_morph.xml"), "--shape", "nope",
                  "-D", "res=16", "--out", str(tmp_path)])
    assert e.value.code == 2 and "nope" in capsys.readouterr().err
