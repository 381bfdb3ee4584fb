"""Shared helpers of the VDM tests, and one table cache for the run."""
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


@pytest.fixture(scope="session")
def table_cache(tmp_path_factory):
    """The VDM table cache folder of this test run (``$MI_DISPLACE_CACHE``; vdm/cache.py): a
    table is built once per run and read back by every later test that needs the same one
    (the cache keys each entry by everything that determines it), and never comes from, or
    goes to, the user's cache."""
    return tmp_path_factory.mktemp("table_cache")


@pytest.fixture(autouse=True)
def _table_cache(table_cache, monkeypatch):
    """Every VDM test reads and writes the run's table cache; a test of the cache itself sets
    its own folder (its ``monkeypatch.setenv`` comes after this one)."""
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(table_cache))
