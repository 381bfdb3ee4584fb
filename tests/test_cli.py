"""The mi-displace command line: render, compare, showcase, bench, and its error handling."""
import json
import shutil
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from mi_displace import cli
from mi_displace.core.io import read_image

DATA = Path(__file__).resolve().parent / "data" / "compare"
SCENE = str(DATA / "two_spheres.xml")


def _fails_with_2(capsys, argv, message):
    """``main(argv)`` exits with status 2 and prints one line naming the problem."""
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    return err


def test_render_writes_a_finite_exr(variant, tmp_path, capsys):
    out = tmp_path / "img.exr"
    assert cli.main(["--variant", variant, "render", SCENE, "-D", "res=16", "-D", "mode=approximation",
                     "--spp", "4", "--seed", "3", "--out", str(out)]) == 0
    image = read_image(out)
    assert image.shape == (16, 16, 3) and np.isfinite(image).all()
    assert 0.05 < image.mean() < 1.0
    assert "wrote" in capsys.readouterr().out


def test_render_png_16_bit(variant, tmp_path):
    out = tmp_path / "img.png"
    assert cli.main(["--variant", variant, "render", SCENE, "--bits", "16", "--out", str(out)]) == 0
    from PIL import Image

    assert Image.open(out).size == (32, 32)


def test_bad_input_exits_2_with_one_line(variant, tmp_path, capsys):
    exr = str(tmp_path / "x.exr")
    _fails_with_2(capsys, ["render", str(tmp_path / "nope.xml"), "--out", exr], "nope.xml' does not exist")
    err = _fails_with_2(capsys, ["render", SCENE, "--out", str(tmp_path / "x.jpg")], "unknown image format '.jpg'")
    assert len(err.strip().splitlines()) == 1
    _fails_with_2(capsys, ["render", SCENE, "-D", "foo=1", "--out", exr], "$foo=1")
    _fails_with_2(capsys, ["render", SCENE, "-D", "spp=x", "--out", exr], 'could not parse integer value "x"')
    _fails_with_2(capsys, ["render", SCENE, "-D", "novalue", "--out", exr], "expected name=value")
    _fails_with_2(capsys, ["render", SCENE, "--spp", "0", "--out", exr], "positive integer")
    _fails_with_2(capsys, ["--variant", "scalar_rgb", "render", SCENE, "--out", exr], "vectorised RGB variant")
    _fails_with_2(capsys, ["compare", SCENE, "--out", str(tmp_path), "-D", "integrator=path"],
                  "integrator is set by the comparison protocol")
    _fails_with_2(capsys, ["bench", "no_such_bench"], "unknown benchmark 'no_such_bench'")
    _fails_with_2(capsys, ["showcase", "--out", str(tmp_path), "--scenes", str(tmp_path / "none")],
                  "does not exist")
    _fails_with_2(capsys, ["showcase", "--out", str(tmp_path), "--scenes", str(DATA)],
                  "is marked <!-- showcase -->")
    assert not (tmp_path / "x.exr").exists()


def test_compare_prints_a_summary(variant, tmp_path, capsys):
    assert cli.main(["--variant", variant, "compare", SCENE, "--out", str(tmp_path), "-D", "res=16",
                     "--max-spp", "64"]) == 0
    out = capsys.readouterr().out
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert f"FLIP {saved['flip_mean']:.4f}" in out and "speed-up" in out
    assert saved["width"] == 16 and saved["reference_spp"] <= 64


def test_showcase_compares_marked_scenes(variant, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    shutil.copytree(DATA, scenes)
    marked = scenes / "two_spheres.xml"
    marked.write_text(marked.read_text().replace('<scene version="3.0.0">',
                                                 '<scene version="3.0.0">\n    <!-- showcase -->'))
    shutil.copy(marked, scenes / "also_marked.xml")
    out = tmp_path / "out"
    assert cli.main(["--variant", variant, "showcase", "--out", str(out), "--scenes", str(scenes),
                     "--quick"]) == 0
    summary = (out / "summary.md").read_text()
    rows = [line for line in summary.splitlines() if line.startswith("| ") and "---" not in line]
    assert [r.split("|")[1].strip() for r in rows] == ["scene", "also_marked", "two_spheres"]
    for name in ("also_marked", "two_spheres"):
        saved = json.loads((out / name / "metrics.json").read_text())
        assert saved["reference_spp"] <= cli.QUICK_MAX_SPP
        assert f"{saved['flip_mean']:.4g}" in summary
        assert (out / name / "panel.png").is_file()
    assert "| two_spheres |" in capsys.readouterr().out


def test_bench_dispatches_to_the_module(variant, monkeypatch):
    calls = []
    fake = types.ModuleType("mi_displace.bench.fake")
    fake.main = lambda json=None: calls.append(json)
    monkeypatch.setitem(sys.modules, "mi_displace.bench.fake", fake)
    monkeypatch.setattr(cli, "bench_names", lambda: ["fake"])
    assert cli.main(["--variant", variant, "bench", "fake", "--json"]) == 0
    assert cli.main(["--variant", variant, "bench", "fake"]) == 0
    assert calls == [True, False]


def test_default_scene_folder_is_the_repository_s():
    assert cli.default_scenes_dir() == Path(__file__).resolve().parents[1] / "scenes"
