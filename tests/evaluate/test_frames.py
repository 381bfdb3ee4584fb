"""Frames of traverse edits: the values per frame, identical frames however they are chunked."""
import pytest

from mi_displace.evaluate import frames
from pathlib import Path

SCENE = Path(__file__).resolve().parents[1] / "data" / "tradeoff" / "bumpy_sphere.xml"
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
