"""Fault injection (issue 19 item 6): each check of the bake tests fails with its fault patched in.

* the restoration check rejects a sphere restored at 0.5x or 1.5x the true amplitude;
* the quantised-format checks reject a quantisation step 10x too coarse (their tolerance
  comes from the bit depth and the data, not from the sidecar the code wrote);
* the 16-bit PNG check rejects a d16 map written with 8 bits.
"""
import numpy as np
import pytest
from test_bake_formats import check_d16_is_16_bit, check_round_trip
from test_bake_restore import check_sphere_restoration
from test_bake_sphere import check_quantised_restore

from mi_displace.bake import formats
from mi_displace.bake.baker import bake
from mi_displace.bake.restore import restore


@pytest.fixture
def baked(sphere_pair, tmp_path):
    high, low = sphere_pair
    r = bake(high, low, res=64, out_dir=tmp_path, map_formats=["float", "d16", "d8"], max_distance=0.2)
    return tmp_path, r, high


def test_restoration_check_rejects_a_wrong_amplitude(baked):
    tmp_path, _, _ = baked
    p = restore(tmp_path / "low.obj", tmp_path / "d16.png", levels=2).positions.astype(np.float64)
    check_sphere_restoration(p)                                   # the true amplitude passes
    radius = np.linalg.norm(p, axis=1, keepdims=True)
    for s in (0.5, 1.5):
        with pytest.raises(AssertionError):
            check_sphere_restoration(p / radius * (1 + s * (radius - 1)))


def _coarse(quantise):
    def coarse(d, offset, span, bits):          # the fault: a step 10x too coarse
        return quantise(d, offset, 10 * span, bits)
    return coarse


def test_quantised_checks_reject_a_coarse_step(baked, monkeypatch):
    tmp_path, r, high = baked
    check_quantised_restore(tmp_path, r)                          # the right step passes
    (tmp_path / "ok").mkdir()
    check_round_trip(tmp_path / "ok", "d16")
    monkeypatch.setattr(formats, "_quantise", _coarse(formats._quantise))
    bake_out = tmp_path / "coarse"
    faulty = bake(high, r.low, res=64, out_dir=bake_out, map_formats=["float", "d16", "d8"],
                  max_distance=0.2)
    with pytest.raises(AssertionError):
        check_quantised_restore(bake_out, faulty)
    for fmt in ("d8", "d16", "dir16_d16", "d8_n24"):
        (tmp_path / fmt).mkdir()
        with pytest.raises(AssertionError):
            check_round_trip(tmp_path / fmt, fmt)


def test_bit_depth_check_rejects_an_8_bit_d16(tmp_path, variant, monkeypatch):
    check_d16_is_16_bit(tmp_path)
    write = formats.write_png_raw

    def eight_bit(path, data):                  # the fault: 16-bit data stored in 8 bits
        write(path, (data >> 8).astype(np.uint8) if data.dtype == np.uint16 else data)
    monkeypatch.setattr(formats, "write_png_raw", eight_bit)
    (tmp_path / "f").mkdir()
    with pytest.raises(AssertionError):
        check_d16_is_16_bit(tmp_path / "f")
