"""The slicing sub-commands of mi-displace."""
import numpy as np
import pytest

from mi_displace import cli
from mi_displace.slicing import assets, depth_object


def test_cup_is_watertight_and_concave():
    mesh = assets.cup_mesh()
    assert mesh.is_watertight
    # the cavity: the volume is the outer cylinder minus the inner one (analytic lathe)
    outer = np.pi * 0.5 ** 2 * 0.8
    inner = np.pi * 0.44 ** 2 * 0.74
    assert mesh.volume == pytest.approx(outer - inner, rel=0.01)   # 96-gon vs circle


def test_capture_command_writes_readable_images(variant, tmp_path, capsys):
    assert cli.main(["slicing-capture", "cup", "--out", str(tmp_path / "cup"), "--resolution", "16"]) == 0
    images = depth_object.read(tmp_path / "cup" / "cube.json")
    assert images.resolution == 16 and images.normal is not None
    assert 0.3 < np.isfinite(images.depth).mean() < 1.0
    assert "cube.json" in capsys.readouterr().out


def test_capture_command_bad_source(variant, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["slicing-capture", str(tmp_path / "missing.obj"), "--out", str(tmp_path / "x")])
    assert e.value.code == 2 and "missing.obj" in capsys.readouterr().err
