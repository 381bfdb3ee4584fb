"""Object volumes: raw + sidecar, .vol, NumPy, the procedural piggy bank, the gradient texture."""
import json
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[2] / "data" / "volumes"


from volume_helpers import points as _points


def _raw(tmp_path, data, meta):
    path = tmp_path / "v.raw"
    data.tofile(path)
    (tmp_path / "v.json").write_text(json.dumps(meta))
    return path


def test_walnut_loads_as_in_provenance(variant):
    from mi_displace.volume.objects import load_raw

    vol = load_raw(DATA / "walnut_128x96x114_uint16.raw")
    raw = np.fromfile(DATA / "walnut_128x96x114_uint16.raw", "<u2").reshape(114, 96, 128)
    assert vol.shape == (114, 96, 128)
    # sidecar value_range [0, 22526] maps to [0, 1]
    np.testing.assert_allclose(vol.data, raw / 22526.0, rtol=1e-6)
    np.testing.assert_allclose(vol.bbox_max - vol.bbox_min, [1.0, 96 / 128, 114 / 128])


def test_texture_orientation_and_gradient(variant):
    from mi_displace.volume.objects import ObjectVolume

    nz, ny, nx = 6, 8, 10
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    data = (0.1 * x + 0.2 * y + 0.3 * z).astype(np.float32)
    vol = ObjectVolume(data, [0, 0, 0], [nx, ny, nz], value_range=(0, 10))
    # voxel (i, j, k) has its centre at (i + 1/2, j + 1/2, k + 1/2)
    p = _points([[3.5, 2.5, 1.5], [7.5, 5.5, 4.5]])
    expected = (0.1 * np.array([3, 7]) + 0.2 * np.array([2, 5]) + 0.3 * np.array([1, 4])) / 10
    np.testing.assert_allclose(np.array(vol.density(p)), expected, atol=1e-6)
    g = vol.gradient(p)
    np.testing.assert_allclose([np.array(c) for c in g], [[0.01] * 2, [0.02] * 2, [0.03] * 2], atol=1e-6)
    assert np.array(vol.density(_points([[-0.1, 3, 3]])))[0] == 0.0  # outside the box


def test_vol_round_trip(variant, tmp_path):
    from mi_displace.volume.objects import ObjectVolume, load_vol, write_vol

    data = np.random.default_rng(1).random((5, 6, 7)).astype(np.float32)
    vol = ObjectVolume(data, [-1, -2, -3], [1, 2, 3], value_range=(0, 1))
    back = load_vol(write_vol(tmp_path / "a.vol", vol))
    # a .vol has no value range: its own min..max maps to [0, 1]
    np.testing.assert_allclose(back.data, (data - data.min()) / (data.max() - data.min()), atol=1e-6)
    np.testing.assert_allclose(back.bbox_min, [-1, -2, -3])
    # Mitsuba itself reads the file the same way
    grid = mi.VolumeGrid(str(tmp_path / "a.vol"))
    np.testing.assert_allclose(np.array(grid).reshape(data.shape), data, atol=1e-6)


def test_raw_bad_inputs(variant, tmp_path):
    from mi_displace.volume.objects import load_raw

    data = np.zeros((4, 3, 2), np.uint16)
    meta = {"dims": [2, 3, 4], "dtype": "uint16", "byte_order": "little"}
    ok = load_raw(_raw(tmp_path, data + np.arange(24, dtype=np.uint16).reshape(4, 3, 2), meta))
    assert ok.shape == (4, 3, 2)
    with pytest.raises(ValueError, match="bytes but its sidecar says"):
        load_raw(_raw(tmp_path, data[:3], meta))                          # size vs dims
    with pytest.raises(ValueError, match="bytes but its sidecar says"):
        load_raw(_raw(tmp_path, data, {**meta, "dtype": "uint8"}))          # size vs dtype
    with pytest.raises(ValueError, match="limit"):
        load_raw(_raw(tmp_path, data, {**meta, "dims": [100000, 100000, 100000]}))
    path = _raw(tmp_path, data, meta)
    (tmp_path / "v.json").unlink()
    with pytest.raises(FileNotFoundError, match="sidecar"):
        load_raw(path)
    nan = np.full((4, 3, 2), np.nan, np.float32)
    with pytest.raises(ValueError, match="NaN"):
        load_raw(_raw(tmp_path, nan, {**meta, "dtype": "float32"}))


def test_array_bad_inputs(variant):
    from mi_displace.volume.objects import ObjectVolume

    with pytest.raises(ValueError, match="3-D"):
        ObjectVolume(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="constant"):
        ObjectVolume(np.ones((3, 3, 3)))
    with pytest.raises(ValueError, match="bbox_min"):
        ObjectVolume(np.arange(27.0).reshape(3, 3, 3), [0, 0, 0], [1, 0, 1])


def test_piggy_bank_hides_coins_inside_a_shell(variant):
    from mi_displace.volume.objects import piggy_bank

    vol = piggy_bank(64)
    # along +z through a coin centre: air, shell (0.6), empty inside, coin (1), empty, shell, air
    zs = np.linspace(-0.5, 0.5, 201)
    profile = np.array(vol.density(_points(np.stack([np.full_like(zs, 0.02), np.zeros_like(zs), zs], 1))))
    assert profile[0] == 0 and profile[-1] == 0
    shell = np.nonzero(np.isclose(profile, 0.6, atol=0.02))[0]
    coin = np.nonzero(profile > 0.9)[0]
    assert len(coin) > 0 and shell.min() < coin.min() and coin.max() < shell.max()
    between = profile[shell[shell < coin.min()].max(): coin.min()]
    assert between.min() == 0.0     # hollow: empty space between the shell and the coin


def test_grid_and_map_resolutions_have_their_own_minimum_and_limit():
    """Object grids: sizes >= 1 up to MAX_VOXELS; D_k maps: >= 2 (central differences) up to
    MAX_MAP_VOXELS; both refuse with the caller's name."""
    from mi_displace.volume import displacement, objects

    assert objects.check_resolution((1, 5, 2), "grid") == (1, 5, 2)
    assert displacement.check_resolution([2, 3, 4], "D_k") == (2, 3, 4)
    with pytest.raises(ValueError, match=r"^D_k: expected three integers >= 2, got \(1, 4, 4\)"):
        displacement.check_resolution((1, 4, 4), "D_k")
    with pytest.raises(ValueError, match=r"^grid: expected three positive sizes, got \(0, 4, 4\)"):
        objects.check_resolution((0, 4, 4), "grid")
    side = round(displacement.MAX_MAP_VOXELS ** (1 / 3))
    assert displacement.check_resolution((side,) * 3, "D_k") == (side,) * 3
    with pytest.raises(ValueError, match=f"more than the limit of {displacement.MAX_MAP_VOXELS:,}"):
        displacement.check_resolution((side + 1,) * 3, "D_k")
    assert objects.check_resolution((side + 1,) * 3, "grid") == (side + 1,) * 3
    with pytest.raises(ValueError, match=f"more than the limit of {objects.MAX_VOXELS:,}"):
        objects.check_resolution((513, 512, 512), "grid")
    with pytest.raises(ValueError, match="expected three"):
        objects.check_resolution((4, 4), "grid")
