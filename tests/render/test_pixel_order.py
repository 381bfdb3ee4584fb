"""The frame's pixel order (:mod:`mi_displace.render.pixel_order`): a permutation of the
film's pixels, its inverse, tiles of 4 x 4 neighbours, and images back in rows."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.render import pixel_order


@pytest.mark.parametrize("width, height", [(1, 1), (4, 4), (8, 4), (7, 5), (13, 2), (3, 9), (64, 48)])
def test_lanes_are_a_permutation_of_the_pixels_and_lane_of_inverts_it(variant, width, height):
    n = width * height
    x, y = pixel_order.pixel_of(dr.arange(mi.UInt32, n), width, height)
    x, y = np.array(x), np.array(y)
    assert (x < width).all() and (y < height).all()
    assert len(set(zip(x.tolist(), y.tolist()))) == n             # every pixel once
    lane = np.array(pixel_order.lane_of(mi.UInt32(x), mi.UInt32(y), width, height))
    np.testing.assert_array_equal(lane, np.arange(n))


def test_a_packet_of_16_lanes_is_a_4x4_tile(variant):
    x, y = (np.array(c) for c in pixel_order.pixel_of(dr.arange(mi.UInt32, 64 * 48), 64, 48))
    for start in range(0, 64 * 48, 16):   # SIMD packets of 16 lanes
        assert np.ptp(x[start:start + 16]) == 3 and np.ptp(y[start:start + 16]) == 3


def test_image_puts_the_pixels_back_in_rows(variant):
    width, height = 7, 5
    x, y = pixel_order.pixel_of(dr.arange(mi.UInt32, width * height), width, height)
    L = mi.Color3f(mi.Float(x), mi.Float(y), 1.0)   # each lane's colour names its pixel
    img = np.array(pixel_order.image(L, width, height))
    assert img.shape == (height, width, 3)
    np.testing.assert_array_equal(img[..., 0], np.tile(np.arange(width), (height, 1)))
    np.testing.assert_array_equal(img[..., 1], np.tile(np.arange(height)[:, None], (1, width)))
