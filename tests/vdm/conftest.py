"""Shared helpers of the VDM tests."""
import numpy as np
import pytest


def bilinear_periodic(heights: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a periodic (res, res) grid with texel centres at (i + 0.5) / res
    (NumPy; the second implementation the Dr.Jit code is tested against)."""
    res = heights.shape[0]
    gx, gy = px * res - 0.5, py * res - 0.5
    i0, j0 = np.floor(gx).astype(int), np.floor(gy).astype(int)
    fx, fy = gx - i0, gy - j0
    h = lambda i, j: heights[j % res, i % res]
    return ((1 - fx) * (1 - fy) * h(i0, j0) + fx * (1 - fy) * h(i0 + 1, j0)
            + (1 - fx) * fy * h(i0, j0 + 1) + fx * fy * h(i0 + 1, j0 + 1))


@pytest.fixture
def bilinear():
    return bilinear_periodic
