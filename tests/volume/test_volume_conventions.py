"""The conventions of docs/volume.md ("Conventions"), each against an independent NumPy /
SciPy computation: object placement, voxel-centred sampling and the outside of the box, value
normalisation, the transfer ramp, the Gaussian's renormalisation and fade, the slab map above
its top slab, the D_k bit depths, and the placement M of ``map<i>_to_world`` — the last ones
end to end through the ``displaced_volume`` plugin."""
import json

import mitsuba as mi
import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from volume_helpers import points as _p, to_numpy as _np


def _trilinear(data, lo, hi, p):
    """Voxel-centred trilinear O(p) of ``data`` (z, y, x) filling the box [lo, hi], clamped
    to the edge voxels inside the box and 0 outside it (SciPy, float64)."""
    n = np.array(data.shape[::-1], float)
    t = (p - lo) / (hi - lo) * n - 0.5                   # voxel i's centre at t = i
    value = map_coordinates(data.astype(np.float64), t[:, ::-1].T, order=1, mode="nearest")
    inside = ((p >= lo) & (p <= hi)).all(1)
    return np.where(inside, value, 0.0)


def _gaussian_d(l, amount, sigma):
    """D_z of the Gaussian pull (eq. 8) at local points (N, 3): g renormalised to 1 at the
    centre and 0 on the cube's sides, times z in [0, 1] and 2 - z in [1, 2] (the fade)."""
    x, y, z = l.T
    s2 = 2 * sigma ** 2
    edge = np.exp(-0.25 / s2)
    g = (np.exp(-((x - 0.5) ** 2 + (y - 0.5) ** 2) / s2) - edge) / (1 - edge)
    g = np.where((x >= 0) & (x <= 1) & (y >= 0) & (y <= 1), np.maximum(g, 0.0), 0.0)
    return -amount * np.clip(np.minimum(z, 2.0 - z), 0.0, 1.0) * g


def _write_raw(tmp_path, data, meta):
    path = tmp_path / "obj.raw"
    data.tofile(path)
    (tmp_path / "obj.json").write_text(json.dumps({"dims": list(data.shape[::-1]), **meta}))
    return path


def test_raw_object_is_centred_with_its_longest_side_one(variant, tmp_path, rng):
    """dims × spacing gives the aspect; the box is centred at the origin, longest side 1."""
    from mi_displace.volume.objects import load_raw

    data = rng.integers(0, 1000, (3, 4, 10)).astype(np.uint16)      # nz, ny, nx
    vol = load_raw(_write_raw(tmp_path, data, {"dtype": "uint16", "spacing": [0.5, 2.0, 3.0]}))
    size = np.array([10 * 0.5, 4 * 2.0, 3 * 3.0])                    # x, y, z extents: 5, 8, 9
    np.testing.assert_allclose(vol.bbox_max, 0.5 * size / 9.0)
    np.testing.assert_allclose(vol.bbox_min, -0.5 * size / 9.0)


def test_object_is_voxel_centred_trilinear_and_zero_outside_its_box(variant, rng):
    """A voxel's centre reads its stored value; between centres O is trilinear; in the outer
    half voxel it is the edge voxel's value (clamp); outside the box it is 0."""
    from mi_displace.volume.objects import ObjectVolume

    data = rng.random((5, 7, 6)).astype(np.float32)
    lo, hi = np.array([-0.3, -0.2, 0.1]), np.array([0.9, 0.5, 0.6])
    vol = ObjectVolume(data, lo, hi, value_range=(0.0, 1.0))
    h = (hi - lo) / np.array([6, 7, 5])
    k = np.stack(np.meshgrid(np.arange(6), np.arange(7), np.arange(5), indexing="ij"), -1).reshape(-1, 3)
    centres = lo + (k + 0.5) * h
    np.testing.assert_allclose(np.array(vol.density(_p(centres))), data[k[:, 2], k[:, 1], k[:, 0]], atol=2e-6)
    p = rng.uniform(lo - 0.1, hi + 0.1, (20000, 3))
    keep = (np.abs(p - lo) > 1e-5).all(1) & (np.abs(p - hi) > 1e-5).all(1)   # not on a face's rounding
    got, truth = np.array(vol.density(_p(p))), _trilinear(data, lo, hi, p)
    np.testing.assert_allclose(got[keep], truth[keep], atol=2e-6)
    # points on a face belong to the box: the edge voxels' values
    faces = lo + rng.random((600, 3)) * (hi - lo)
    axis, side = rng.integers(0, 3, 600), rng.random(600) < 0.5
    faces[np.arange(600), axis] = np.where(side, lo[axis], hi[axis])
    on_face = np.array(vol.density(_p(faces)))
    assert on_face.min() > 0
    np.testing.assert_allclose(on_face, _trilinear(data, lo, hi, faces), atol=2e-6)
    outside = ((p < lo) | (p > hi)).any(1)
    assert outside.sum() > 5000 and (got[outside] == 0).all()
    # in the outer half voxel (between a face and the first centres) the edge voxels' values
    border = ((p - lo < 0.5 * h) | (hi - p < 0.5 * h)).any(1) & ~outside & keep
    assert border.sum() > 1000
    np.testing.assert_allclose(got[border], truth[border], atol=2e-6)


def test_values_map_linearly_from_value_range_to_unit_and_clip(variant, tmp_path, rng):
    """Sidecar ``value_range`` (lo, hi) -> (0, 1), values beyond it clipped; without one the
    data's own min and max."""
    from mi_displace.volume.objects import load_raw

    data = rng.integers(0, 60000, (4, 5, 6)).astype(np.uint16)
    with_range = load_raw(_write_raw(tmp_path, data, {"dtype": "uint16", "value_range": [10000, 40000]}))
    np.testing.assert_allclose(with_range.data, np.clip((data - 10000.0) / 30000.0, 0, 1), atol=1e-6)
    assert (with_range.data == 0).sum() > 0 and (with_range.data == 1).sum() > 0
    own = load_raw(_write_raw(tmp_path, data, {"dtype": "uint16"}))
    np.testing.assert_allclose(own.data, (data - data.min()) / float(data.max() - data.min()), atol=1e-6)


def test_gaussian_is_renormalised_and_fades_above_the_cube(variant, rng):
    """D_z = -amount at the top centre (g renormalised to 1 there), 0 on the cube's sides,
    faded linearly from z = 1 to 2 and 0 beyond; the placement-free formula elsewhere."""
    from mi_displace.volume.displacement import PlacedMap

    amount, sigma = 0.4, 0.2
    m = PlacedMap("gaussian", {"amount": amount, "sigma": sigma})
    anchors = np.array([[0.5, 0.5, 1.0], [0.5, 0.5, 0.5], [0.5, 0.5, 1.5], [0.5, 0.5, 2.0], [0.5, 0.5, 2.5],
                        [0.0, 0.5, 0.9], [0.5, 1.0, 0.9], [1.2, 0.5, 0.9], [0.5, 0.5, -0.2]])
    d, alpha = m.exact(_p(anchors))
    np.testing.assert_allclose(_np(d)[:, 2], [-0.4, -0.2, -0.2, 0, 0, 0, 0, 0, 0], atol=1e-6)
    l = rng.uniform([-0.2, -0.2, -0.5], [1.2, 1.2, 2.5], (20000, 3))
    d, alpha = m.exact(_p(l))
    np.testing.assert_allclose(_np(d)[:, 2], _gaussian_d(l, amount, sigma), atol=1e-6)
    assert np.abs(_np(d)[:, :2]).max() == 0 and np.array(alpha).min() == 1.0


def test_slabs_above_the_top_slab_fade_back_to_rest(variant, rng):
    """Above the top slab (z' > top) the top slab's lift fades linearly to 0 over 0.5: the
    pre-image is continuous at the top and lies above the object (z > 1), so nothing is
    shown twice; from top + 0.5 up the map is the identity."""
    from mi_displace.volume.displacement import PlacedMap

    n, gap = 3, 0.2
    top = (n - 1) * (1 / n + gap) + 1 / n                       # 1.4
    m = PlacedMap("slabs", {"count": n, "gap": gap})
    z = np.concatenate([[top - 1e-4, top + 1e-4, top + 0.25, top + 0.5, top + 0.9],
                        rng.uniform(top, top + 1.0, 2000)])
    l = np.stack([np.full_like(z, 0.5), np.full_like(z, 0.5), z], 1)
    d, alpha = m.exact(_p(l))
    dz = _np(d)[:, 2]
    np.testing.assert_allclose(dz, -(n - 1) * gap * np.clip((top + 0.5 - z) / 0.5, 0, 1), atol=1e-6)
    np.testing.assert_allclose((z + dz)[:2], [1.0, 1.0], atol=1e-3)   # the object's top, both sides
    assert (z + dz)[1:].min() > 1.0 and np.array(alpha).min() == 1.0


@pytest.mark.parametrize("bits", [8, 16, 32])
def test_d_k_stores_snorm_displacement_and_unorm_alpha(variant, bits):
    """At 8/16 bit, D is stored as k · max|D| / (2^(bits-1) - 1) (0 and ±max|D| exact) and
    1 - α_s as k / (2^bits - 1); at 32 bit, D is the exact map at the nodes (float32)."""
    from mi_displace.volume.displacement import PlacedMap

    m = PlacedMap("seam", {"amount": 0.2}, resolution=(12, 10, 9))
    s = m.sampled(bits, 1.5)
    assert s.disp.stored == [0, 3]                              # D_x and 1 - α (the others are 0)
    stored = np.array(s.disp.texture.tensor())                  # (z, y, x, 2)
    axes = [np.linspace(s.lo[i], s.hi[i], s.res[i]) for i in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    exact = np.array(m.exact(_p(np.stack([x, y, z], -1).reshape(-1, 3)))[0][0]).reshape(z.shape)
    scale = np.abs(exact).max()
    if bits == 32:
        np.testing.assert_allclose(stored[..., 0], exact, atol=1e-7)
        return
    steps = 2 ** (bits - 1) - 1
    np.testing.assert_allclose(stored[..., 0], np.round(exact / scale * steps) / steps * scale, atol=1e-7)
    assert (stored[..., 0][exact == 0] == 0).all() and np.abs(stored[..., 0]).max() == np.float32(scale)
    a = stored[..., 1] * (2 ** bits - 1)
    np.testing.assert_allclose(a, np.round(a), atol=1e-3 if bits == 8 else 1e-2)   # float32 of k / (2^bits - 1)
    assert a.min() == 0 and 0 < a.max() <= 2 ** bits - 1


def test_plugin_density_is_the_documented_chain(variant, tmp_path, rng):
    """sigma_t of ``displaced_volume`` (reference mode) at world points p' against NumPy:
    p = p' + L D(M⁻¹ p') with M from ``map0_to_world`` (L its linear part), O(p) voxel-centred
    in the centred, longest-side-1 box of the raw file (0 outside), τ the tf_low/tf_high
    ramp, times density_scale."""
    data = rng.integers(0, 50000, (8, 10, 12)).astype(np.uint16)
    raw = _write_raw(tmp_path, data, {"dtype": "uint16", "spacing": [1.0, 1.0, 1.5], "value_range": [5000, 45000]})
    M = np.array([[0.8, 0, 0, -0.4], [0, 0.6, 0, -0.3], [0, 0, 0.5, -0.45], [0, 0, 0, 1]])
    to_world = mi.ScalarTransform4f().translate([-0.4, -0.3, -0.45]).scale([0.8, 0.6, 0.5])
    np.testing.assert_allclose(np.array(to_world.matrix), M, atol=1e-7)
    tf_low, tf_high, scale, amount, sigma = 0.2, 0.7, 7.0, 0.6, 0.25
    vol = mi.load_dict({"type": "displaced_volume", "filename": str(raw), "mode": "reference",
                        "tf_low": tf_low, "tf_high": tf_high, "density_scale": scale,
                        "map0_type": "gaussian", "map0_amount": amount, "map0_sigma": sigma,
                        "map0_to_world": to_world})
    pp = rng.uniform(-0.7, 0.7, (30000, 3))
    it = mi.Interaction3f()
    it.p = _p(pp)
    got = np.array(vol.eval_1(it))
    # NumPy truth
    lo = -0.5 * np.array([12, 10, 12.0]) / 12
    obj = np.clip((data - 5000.0) / 40000.0, 0, 1)
    local = (pp - M[:3, 3]) @ np.linalg.inv(M[:3, :3]).T
    pre = pp + np.stack([0 * pp[:, 0], 0 * pp[:, 0], _gaussian_d(local, amount, sigma)], 1) @ M[:3, :3].T
    truth = scale * np.clip((_trilinear(obj, lo, -lo, pre) - tf_low) / (tf_high - tf_low), 0, 1)
    keep = (np.abs(np.abs(pre) + lo).min(1) > 1e-4)             # not on a face of the box (rounding)
    assert keep.mean() > 0.99 and (truth > 0).mean() > 0.2 and (truth == 0).mean() > 0.2
    np.testing.assert_allclose(got[keep], truth[keep], atol=2e-3)
    moved = np.abs(pre - pp).max(1) > 0.05                      # where the pull moves matter
    assert moved.sum() > 1000 and np.abs(got - scale * np.clip(
        (_trilinear(obj, lo, -lo, pp) - tf_low) / (tf_high - tf_low), 0, 1))[moved].max() > 1.0


@pytest.mark.parametrize("tf_low", [-0.1, 1.0])
def test_tf_low_outside_the_normalised_range_is_refused(variant, tf_low):
    """τ(0) = clip(-tf_low / (tf_high - tf_low), 0, 1) is 0 only for tf_low >= 0: below, every
    empty voxel and all space outside the object's box would get density (2.9 / unit at
    tf_low -0.1, tf_high 0.6, density_scale 20); from 1 on, no voxel has any.  Refused at
    load, naming tf_low."""
    with pytest.raises(RuntimeError, match=r"parameter 'tf_low' must lie in \[0, 1\), got " + str(tf_low)):
        mi.load_dict({"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16,
                      "tf_low": tf_low, "tf_high": 1.5})
    empty = mi.load_dict({"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16,
                          "tf_low": 0.0, "tf_high": 0.6})
    k = np.argwhere(empty.volume.obj.data == 0)[:, ::-1]        # empty voxels (x, y, z)
    centres = -0.5 + (k + 0.5) / 16
    assert len(k) > 100 and np.array(empty.volume.sigma_t(_p(centres))).max() == 0
    assert np.array(empty.volume.sigma_t(_p([[5.0, 5.0, 5.0]]))).tolist() == [0.0]   # outside the box
