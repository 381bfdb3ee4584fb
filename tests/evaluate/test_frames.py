"""Frames of traverse edits: the values per frame, identical frames however they are chunked,
and the technique commands (ddm-animate, volume-animate) as aliases of animate."""
import json

import pytest

from mi_displace.core.resources import scene_path
from mi_displace.evaluate import frames

SCENE = scene_path("tradeoff", "bumpy_sphere.xml")
RASTER = {"mode": "approximation", "integrator": "raster"}


def test_frame_values():
    assert frames.parse_edit("ball.scale=0:0.2") == ("ball.scale", 0.0, 0.2)
    values = frames.frame_edits([("a.x", 0.0, 1.0), ("b.y", 2.0, 0.0)], 4)
    assert values == [{"a.x": 0.0, "b.y": 2.0}, {"a.x": 0.25, "b.y": 1.5},
                      {"a.x": 0.5, "b.y": 1.0}, {"a.x": 0.75, "b.y": 0.5}]
    for bad in ("scale=0:1", "ball.scale=0", "ball.scale=a:1", "ball.scale=0:inf"):
        with pytest.raises(ValueError, match="--edit"):
            frames.parse_edit(bad)
    with pytest.raises(ValueError, match="--frames"):
        frames.frame_edits([("a.x", 0, 1)], 0)
    # endpoint: first and last frame at START and STOP (a progressing cut)
    assert frames.frame_edits([("a.x", 0.0, 1.0)], 3, endpoint=True) == [
        {"a.x": 0.0}, {"a.x": 0.5}, {"a.x": 1.0}]
    assert frames.frame_edits([("a.x", 2.0, 1.0)], 1, endpoint=True) == [{"a.x": 2.0}]


def test_chunking_does_not_change_frames(variant_llvm, tmp_path):
    edit = [frames.parse_edit("ball.scale=0:0.3")]
    one = frames.animate(SCENE, edit, 4, tmp_path / "one", params=RASTER, chunk=4)
    two = frames.animate(SCENE, edit, 4, tmp_path / "two", params=RASTER, chunk=1)
    assert not one["failed"] and not two["failed"]
    pngs = [p.read_bytes() for p in one["frames"]]
    assert pngs == [p.read_bytes() for p in two["frames"]]
    assert len(set(pngs)) == 4  # the edit really changes the picture
    # a frame depends on its own value only: a one-frame run at frame 0's value agrees
    ref = frames.animate(SCENE, [frames.parse_edit("ball.scale=0:0")], 1, tmp_path / "ref",
                         params=RASTER)
    assert ref["frames"][0].read_bytes() == pngs[0]


def test_unknown_key_refused_before_jobs(variant_llvm, tmp_path, monkeypatch):
    monkeypatch.setattr(frames, "run_jobs", lambda *a, **k: pytest.fail("jobs ran"))
    with pytest.raises(ValueError, match="bal.scale"):
        frames.animate(SCENE, [frames.parse_edit("bal.scale=0:1")], 2, tmp_path, params=RASTER)


def test_volume_animate_is_animate_with_endpoint(variant_llvm, tmp_path):
    """volume-animate writes what animate --endpoint --spp 1 writes, image for image."""
    from mi_displace import cli

    common = ["-D", "mode=approximation", "-D", "integrator=raster", "--frames", "3"]
    assert cli.main(["volume-animate", str(SCENE), "--param", "ball.scale", "--start", "0",
                     "--stop", "0.3", *common, "--out", str(tmp_path / "alias")]) == 0
    assert cli.main(["animate", str(SCENE), "--edit", "ball.scale=0:0.3", "--endpoint",
                     "--spp", "1", *common, "--out", str(tmp_path / "generic")]) == 0
    record = json.loads((tmp_path / "alias" / "frames.json").read_text())
    assert [f["edits"]["ball.scale"] for f in record["frames"]] == pytest.approx([0, 0.15, 0.3])
    assert all(f["render_s"] > 0 and f["host"] for f in record["frames"])
    for i in range(3):
        name = f"frame_{i:04d}.png"
        assert (tmp_path / "alias" / name).read_bytes() == (tmp_path / "generic" / name).read_bytes()


def test_volume_animate_bad_param_exits_2(variant_llvm, tmp_path, capsys):
    from mi_displace import cli

    with pytest.raises(SystemExit) as e:
        cli.main(["volume-animate", str(SCENE), "--param", "ball.scal", "--start", "0",
                  "--stop", "1", "-D", "mode=approximation", "-D", "integrator=raster",
                  "--out", str(tmp_path)])
    assert e.value.code == 2 and "ball.scal" in capsys.readouterr().err
