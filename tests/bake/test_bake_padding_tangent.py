"""Edge padding against brute force; the tangent frame and tangent-space normals."""
import numpy as np
import pytest
from bake_meshes import plane

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData
from mi_displace.bake.padding import pad


def test_padding_takes_a_nearest_covered_value():
    rng = np.random.default_rng(3)
    covered = rng.random((40, 50)) < 0.05
    image = np.where(covered, rng.random((40, 50)), np.nan)[..., None].repeat(2, 2)
    out, filled = pad(image.copy(), covered, 3)
    rr, cc = np.nonzero(covered)
    for r, c in zip(*np.nonzero(filled & ~covered)):
        cheb = np.maximum(np.abs(rr - r), np.abs(cc - c))
        assert cheb.min() <= 3
        nearest = cheb == cheb.min()
        assert np.any(np.isclose(image[rr[nearest], cc[nearest], 0], out[r, c, 0]))
    far = ~filled
    r, c = np.nonzero(far)
    d = np.min(np.maximum(np.abs(rr[:, None] - r), np.abs(cc[:, None] - c)), axis=0)
    assert np.all(d > 3)
    assert np.all(out[covered] == image[covered])
    with pytest.raises(ValueError, match="padding"):
        pad(image, covered, -1)


@pytest.mark.parametrize("mirror", [False, True])
def test_tangent_space_normal_of_a_tilted_high_poly(variant, mirror):
    # high-poly: the plane tilted about the y axis; its normal is (-sin a, 0, cos a)
    a = 0.3
    hi = plane(n=4, uv=False)
    hi.positions[:, 2] = 0.05 + np.tan(a) * (hi.positions[:, 0] - 0.5)
    lo = plane(n=1)
    if mirror:
        lo = MeshData(lo.positions, lo.faces, (lo.uvs * [-1, 1] + [1, 0]).astype(np.float32))
    r = bake(hi, lo, res=16, max_distance=0.5, pad=0)
    nt = r.maps["normal_tangent"][r.covered]
    no = r.maps["normal_object"][r.covered]
    assert np.allclose(no, [-np.sin(a), 0, np.cos(a)], atol=1e-5)
    # shader rule: N = normalize(x t + y b + z n) with t = +-x, b = +y, n = +z
    sx = -1 if mirror else 1
    assert np.allclose(nt, [sx * -np.sin(a), 0, np.cos(a)], atol=1e-5)


def test_padded_texels_are_counted(variant):
    # a chart of 4 x 4 texels in an 8 x 8 map, padded by 2 texels: the 6 x 6 block around it
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, (low.uvs * np.float32(0.5)).astype(np.float32))
    r = bake(plane(z=0.02, n=4), low, res=8, max_distance=0.05, pad=2)
    c = r.record["counts"]
    assert c["covered"] == 16 and c["padded"] == int(r.maps["filled"].sum()) - 16 == 36 - 16


def test_texels_beyond_the_padding_hold_plus_z_normals(variant):
    # the chart fills the left half of each row; texels beyond the padding are empty and
    # hold displacement 0 and +z normals (baker._texel_average), never NaN
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, (low.uvs * np.float32([0.5, 1.0])).astype(np.float32))
    r = bake(plane(z=0.02, n=4), low, res=16, max_distance=0.05, pad=1)
    empty = ~r.maps["filled"]
    assert empty.sum() == 16 * 7
    for name in ("normal_object", "normal_tangent", "direction_tangent"):
        assert np.array_equal(r.maps[name][empty], np.tile(np.float32([0, 0, 1]), (int(empty.sum()), 1))), name
    assert np.all(r.maps["displacement"][empty] == 0)
