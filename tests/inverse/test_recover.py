"""Inverse displacement (issue 14): a tiny recovery of a real height map from renders."""
import numpy as np
import pytest

from mi_displace.inverse import recover


def test_recovery_lowers_loss_and_height_error(variant):
    truth = recover.load_height_map(size=16)
    assert truth.shape == (16, 16) and 0 <= truth.min() < truth.max() <= 1
    rec = recover.recover(truth, iterations=8, views=3, lights=2, image_size=32, spp=8,
                          target_spp=64, integrator="direct_projective")
    assert np.all(np.isfinite(rec.estimate)) and np.all(np.isfinite(rec.loss))
    assert len(rec.loss) == 8 and len(rec.rms) == 9
    # the start is the flat map 0.5: its RMS is that of truth - 0.5 (independent of the code)
    assert rec.rms[0] == pytest.approx(recover.height_rms(np.full_like(truth, 0.5), truth))
    assert np.mean(rec.loss[-2:]) < 0.7 * rec.loss[0], rec.loss
    assert rec.rms[-1] < 0.8 * rec.rms[0], rec.rms
    assert rec.loss[-1] > rec.settings["loss_noise_floor"] * 0.5


def test_height_rms_is_relative_to_the_range():
    truth = np.array([[0.2, 0.6], [0.2, 0.6]])
    assert recover.height_rms(truth + 0.04, truth) == pytest.approx(0.1)


def test_bad_input_is_refused(variant, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.png"):
        recover.load_height_map(tmp_path / "nope.png")
    with pytest.raises(ValueError, match="size"):
        recover.load_height_map(size=1)
    with pytest.raises(ValueError, match="square"):
        recover.recover(np.zeros((4, 8)), iterations=1)
    with pytest.raises(ValueError, match="NaN"):
        recover.recover(np.full((4, 4), np.nan), iterations=1)
    with pytest.raises(ValueError, match="lights"):
        recover.recover(np.zeros((4, 4)), iterations=1, lights=3)
    with pytest.raises(ValueError, match="iterations"):
        recover.recover(np.zeros((4, 4)), iterations=0)
    with pytest.raises(ValueError, match="grazing_deg"):   # one view: the top one
        recover.scene_dict(np.zeros((4, 4)), views=1, grazing_deg=10.0)


def test_grazing_deg_sets_the_cameras_elevation(variant):
    d = recover.scene_dict(np.zeros((4, 4)), views=2, grazing_deg=10.0)
    for key in ("sensor0", "sensor1"):
        origin = np.asarray(d[key]["to_world"].matrix)[:3, 3]
        elevation = np.degrees(np.arcsin(origin[2] / np.linalg.norm(origin)))
        assert elevation == pytest.approx(10.0, abs=1e-3)
