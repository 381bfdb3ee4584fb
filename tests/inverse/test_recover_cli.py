"""``mi-displace recover``: a tiny run writes its JSON and figures; bad arguments exit 2."""
import json

import numpy as np
import pytest

from mi_displace import cli


def test_recover_writes_json_and_figures(variant, tmp_path):
    assert cli.main(["--variant", variant, "recover", "--out", str(tmp_path), "--iterations", "2",
                     "--map-size", "8", "--image-size", "16", "--views", "1", "--lights", "1",
                     "--spp", "2", "--integrator", "direct_projective"]) == 0
    record = json.loads((tmp_path / "recovery.json").read_text())
    assert len(record["loss"]) == 2 and len(record["rms"]) == 3
    assert np.all(np.isfinite(record["loss"])) and np.all(np.isfinite(record["rms"]))
    for name in ("recovery_curves.png", "recovery_maps.png"):
        assert (tmp_path / name).stat().st_size > 1000


@pytest.mark.parametrize("argv", [["--iterations", "0"], ["--lights", "3"],
                                  ["--integrator", "path"], ["--learning-rate", "-1"]])
def test_recover_bad_arguments_exit_2(tmp_path, argv):
    with pytest.raises(SystemExit) as exc:
        cli.main(["recover", "--out", str(tmp_path), *argv])
    assert exc.value.code == 2
