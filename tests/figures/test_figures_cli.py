"""``mi-displace figures TECHNIQUE``: the one entry point of the documentation's figures."""
import json

import numpy as np
import pytest

from mi_displace import cli, figures


def _png(path) -> np.ndarray:
    import mitsuba as mi

    return np.asarray(mi.Bitmap(str(path)), dtype=np.float64) / 255.0


def test_list_prints_every_technique(capsys):
    assert cli.main(["figures", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == ["ddm", "vdm", "slicing", "volume", "inverse"]
    assert list(figures.TECHNIQUES) == [line.split()[0] for line in lines]


@pytest.mark.parametrize("argv", [["figures"], ["figures", "nope"]])
def test_no_or_an_unknown_technique_exits_2_naming_the_list(argv, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and "--list" in err


@pytest.mark.parametrize("old", ["ddm-figures", "slicing-figures", "volume-figures"])
def test_the_old_figure_commands_are_gone(old, capsys):
    """Parsed only (nothing runs): no aliases are left."""
    with pytest.raises(SystemExit) as e:
        cli.build_parser().parse_args([old])
    assert e.value.code == 2 and f"invalid choice: '{old}'" in capsys.readouterr().err


def test_every_technique_has_quick_and_out():
    parser = cli.build_parser()
    for name in figures.TECHNIQUES:
        args = parser.parse_args(["figures", name, "--quick", "--out", "somewhere"])
        assert args.quick and str(args.out) == "somewhere" and args.technique == name


def test_inverse_quick_writes_finite_non_black_images(variant_llvm, tmp_path):
    """The cheapest technique, end to end: the recovered plane at --quick sizes."""
    assert cli.main(["--quiet", "figures", "inverse", "--quick", "--only", "plane",
                     "--out", str(tmp_path)]) == 0
    pngs = sorted(p.name for p in (tmp_path / "recovery").glob("*.png"))
    assert pngs == ["recovery_curves.png", "recovery_maps.png"]
    for name in pngs:
        img = _png(tmp_path / "recovery" / name)
        assert img.ndim == 3 and min(img.shape[:2]) > 100
        assert np.all(np.isfinite(img)) and img.mean() > 0.2 and img.std() > 0.01, name
    record = json.loads((tmp_path / "recovery" / "recovery.json").read_text())
    assert len(record["loss"]) == 2 and np.all(np.isfinite(record["rms"]))


@pytest.mark.slow
def test_ddm_quick(variant_llvm, tmp_path):
    assert cli.main(["figures", "ddm", "--quick", "--out", str(tmp_path)]) == 0
    for name in ("ddm_accuracy.png", "ddm_sweep.png", "ddm_maps.png"):
        img = _png(tmp_path / name)
        assert np.all(np.isfinite(img)) and img.mean() > 0.2, name
    assert (tmp_path / "ddm_figures.md").is_file()
    record = json.loads((tmp_path / "ddm_figures.json").read_text())
    rms = [r["rms_error_rel"] for r in record["accuracy"]]
    assert rms == sorted(rms, reverse=True)
