"""EXR / PNG input and output, sRGB encoding."""
import numpy as np
import pytest

from mi_displace.core import io


def test_srgb_transfer_function_values():
    linear = np.array([0.0, 0.0031308, 0.5, 1.0, 2.0, -1.0])
    expected = [0.0, 12.92 * 0.0031308, 1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0, 1.0, 0.0]
    np.testing.assert_allclose(io.to_srgb(linear), expected, atol=1e-6)
    np.testing.assert_allclose(io.from_srgb(io.to_srgb(linear[:4])), linear[:4], atol=1e-6)


def test_exr_round_trip_is_exact_hdr(tmp_path):
    image = np.random.default_rng(0).uniform(0, 50, (5, 7, 3)).astype(np.float32)
    path = io.write_image(tmp_path / "sub" / "a.exr", image)
    back = io.read_image(path)
    assert back.dtype == np.float32 and back.shape == (5, 7, 3)
    np.testing.assert_array_equal(back, image)


@pytest.mark.parametrize("bits, step", [(8, 1 / 255), (16, 1 / 65535)])
def test_png_round_trip_within_one_quantisation_step(tmp_path, bits, step):
    image = np.random.default_rng(1).uniform(0, 1.5, (6, 4, 3)).astype(np.float32)
    back = io.read_image(io.write_image(tmp_path / "a.png", image, bits=bits))
    assert back.shape == (6, 4, 3)
    err = np.abs(io.to_srgb(back) - io.to_srgb(image)).max()
    assert err <= 0.5 * step + 1e-6


def test_grey_images_become_rgb(tmp_path):
    grey = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4)
    back = io.read_image(io.write_image(tmp_path / "g.exr", grey))
    np.testing.assert_array_equal(back, np.repeat(grey[..., None], 3, axis=2))


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match=r"unknown image format '\.jpg'"):
        io.write_image(tmp_path / "a.jpg", np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match=r"shape \(H, W, 3\), got shape \(2, 2, 2\)"):
        io.write_image(tmp_path / "a.exr", np.zeros((2, 2, 2)))
    with pytest.raises(FileNotFoundError, match="missing.exr"):
        io.read_image(tmp_path / "missing.exr")
    with pytest.raises(ValueError, match="NaN"):
        io.write_image(tmp_path / "n.png", np.full((2, 2, 3), np.nan))
    with pytest.raises(ValueError, match="bits"):
        io.write_image(tmp_path / "a.png", np.zeros((2, 2, 3)), bits=12)
    assert not any(tmp_path.iterdir())
