"""The mi-displace command line: render, compare, showcase, bench, and its error handling."""
import json
import re
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


BARE_SCENE = """<scene version="3.0.0">
    {integrator}
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <emitter type="constant"/>
    {shape}
</scene>"""


def _bare(tmp_path, shape, integrator='<integrator type="path"/>', name="s.xml"):
    path = tmp_path / name
    path.write_text(BARE_SCENE.format(integrator=integrator, shape=shape))
    return str(path)


def _one_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def test_user_errors_found_while_rendering_are_one_line(variant, tmp_path, capsys):
    exr = str(tmp_path / "x.exr")
    outside = _bare(tmp_path, '<shape type="sphere"><bsdf type="vdm">'
                              '<texture name="height" type="cells"/></bsdf></shape>')
    _one_line(_fails_with_2(capsys, ["render", outside, "--out", exr], 'inside a <shape type="vdm_mesh">'))
    no_integrator = _bare(tmp_path, '<shape type="sphere"/>', integrator="", name="n.xml")
    _one_line(_fails_with_2(capsys, ["render", no_integrator, "--out", exr], "n.xml' has no <integrator>"))
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("element, message", [
    ('<float name="scale" value="big"/>', "float 'scale': could not parse floating point value"),
    ('<integer name="resolution" value="many"/>', "integer 'resolution': could not parse integer"),
    ('<string name="scale" value="big"/>', "displaced: parameter 'scale' must be a number, got 'big'"),
    ('<string name="resolution" value="many"/>', "parameter 'resolution' must be a number, got 'many'"),
    ('<float name="midlevel" value="nan"/>', "displaced: parameter 'midlevel' must be finite, got nan"),
])
def test_bad_values_in_xml_name_the_parameter(variant, tmp_path, capsys, element, message):
    scene = _bare(tmp_path, f'<shape type="displaced"><string name="base" value="sphere"/>{element}'
                            '<texture name="height" type="cells"/></shape>')
    line = _one_line(_fails_with_2(capsys, ["render", scene, "--out", str(tmp_path / "x.exr")], message))
    assert line.startswith("mi-displace: error:") and message in line


def test_a_variant_the_machine_lacks_is_a_usage_error(tmp_path, capsys):
    import drjit as dr

    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("this machine has a CUDA GPU")
    line = _one_line(_fails_with_2(capsys, ["--variant", "cuda_ad_rgb", "render", SCENE, "--out",
                                            str(tmp_path / "x.exr")], "needs a CUDA GPU"))
    assert line.startswith("mi-displace: error:") and "cuda_ad_rgb" in line


def test_a_bug_prints_its_traceback_and_asks_for_a_report(variant, monkeypatch, capsys):
    def broken(json=None):
        return {}["no such key"]

    fake = types.ModuleType("mi_displace.bench.broken")
    fake.main = broken
    monkeypatch.setitem(sys.modules, "mi_displace.bench.broken", fake)
    monkeypatch.setattr(cli, "bench_names", lambda: ["broken"])
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--variant", variant, "bench", "broken"])
    assert exit_info.value.code == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "KeyError: 'no such key'" in err
    assert err.strip().splitlines()[-1] == cli.BUG_HINT


def test_compare_quick_caps_the_reference(variant, tmp_path, monkeypatch):
    seen = {}

    def fake_compare(scene, out, max_spp, **kw):
        seen["max_spp"] = max_spp
        return {"spp_capped": True, "flip_mean": 0.1, "noise_floor_flip": 0.05, "relmse": 0.1,
                "psnr": 20.0, "ssim": 0.9, "reference_spp": max_spp, "reference_time_s": 1.0,
                "approx_time_warm_s": 0.1, "approx_time_cold_s": 0.2, "speedup": 10.0}

    import mi_displace.evaluate.compare as compare_module

    monkeypatch.setattr(compare_module, "compare", fake_compare)
    for flags, expected in (([], cli.DEFAULT_MAX_SPP), (["--quick"], cli.QUICK_MAX_SPP),
                            (["--quick", "--max-spp", "8"], 8)):
        assert cli.main(["--variant", variant, "compare", SCENE, "--out", str(tmp_path)] + flags) == 0
        assert seen["max_spp"] == expected


@pytest.mark.parametrize("quiet, env, shown", [(False, "1", True), (True, "1", False), (False, "0", False),
                                               (False, None, False)])
def test_progress_lines_per_stage(variant, tmp_path, capsys, monkeypatch, quiet, env, shown):
    """A line per stage (scene load, the plugin's build, render) with its time; none with
    --quiet, MI_DISPLACE_PROGRESS=0, or (the default) when stderr is not a terminal."""
    if env is None:
        monkeypatch.delenv("MI_DISPLACE_PROGRESS", raising=False)
    else:
        monkeypatch.setenv("MI_DISPLACE_PROGRESS", env)
    scene = _bare(tmp_path, '<shape type="displaced" id="rock"><string name="base" value="sphere"/>'
                            '<integer name="resolution" value="16"/>'
                            '<texture name="height" type="cells"/></shape>')
    argv = ["--variant", variant] + (["--quiet"] if quiet else []) + [
        "render", scene, "--out", str(tmp_path / "x.exr")]
    try:
        assert cli.main(argv) == 0
    finally:
        cli.progress.set_enabled(None)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("[mi-displace]")]
    if not shown:
        assert lines == []
        return
    assert lines[0] == f"[mi-displace] loading {scene} ..."
    assert lines[1] == "[mi-displace]   displaced 'rock': building ..."
    import mitsuba as mi

    stats = next(s.build_stats for s in mi.load_file(scene).shapes() if s.id() == "rock")
    counts = f"{stats['faces']:,} faces, {stats['vertices']:,} vertices"
    assert re.fullmatch(rf"\[mi-displace\]   displaced 'rock': building: \d+\.\d\d s "
                        rf"\({counts}\)", lines[2]), lines[2]
    assert re.fullmatch(rf"\[mi-displace\] loading {re.escape(scene)}: \d+\.\d\d s", lines[3])
    assert lines[4].endswith("rendering s.xml ...") and re.search(r": \d+\.\d\d s$", lines[5])
