"""Fixtures of the baker tests (the meshes themselves: :mod:`bake_meshes`)."""
import pytest

from bake_meshes import AMPLITUDE, _sphere_mesh


@pytest.fixture
def sphere_pair(variant):
    """(high, low): the unit sphere displaced by AMPLITUDE * sphere_height (256 x 128 grid) and
    the plain unit sphere (48 x 24 grid, with UVs and seam twins)."""
    high = _sphere_mesh(256, 128, AMPLITUDE)
    high.uvs = None
    return high, _sphere_mesh(48, 24, 0.0)
