"""Inverse displacement on the bunny (the baker's pair): the baked map read in the model's
units, and (slow) a short recovery from renders of the scan."""
import numpy as np
import pytest

from mi_displace.inverse import bunny


def test_baked_map_in_model_units_restores_closer_to_the_scan(variant):
    # independent truth: the scan itself; the baked map must bring the displaced low-poly
    # closer to it than the bare low-poly (a wrong unit, sign or v flip would not)
    baked, valid, scale = bunny.baked_map(64)
    assert baked.shape == valid.shape == (64, 64) and valid.mean() > 0.3 and scale > 0
    assert np.all(np.isfinite(baked))
    flat = bunny.restoration_error(np.full_like(baked, 0.5), scale, samples=5000)
    restored = bunny.restoration_error(baked, scale, samples=5000)
    flipped = bunny.restoration_error(baked[::-1].copy(), scale, samples=5000)
    assert restored["rms_rel"] < 0.9 * flat["rms_rel"], (restored, flat)
    assert restored["rms_rel"] < flipped["rms_rel"], (restored, flipped)


def test_baked_map_size_must_divide_the_map(variant):
    with pytest.raises(ValueError, match="size"):
        bunny.baked_map(100)


@pytest.mark.slow
def test_bunny_recovery_lowers_the_image_loss(variant):
    rec = bunny.recover_bunny(map_size=32, iterations=6, views=3, image_size=48)
    assert np.all(np.isfinite(rec.estimate)) and np.all(np.isfinite(rec.loss))
    losses = rec.settings["image_loss"]
    assert losses["optimised"] < losses["low_poly"], losses
