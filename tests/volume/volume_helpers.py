"""Small helpers shared by the volume tests: NumPy <-> Dr.Jit points."""
import mitsuba as mi
import numpy as np


def points(xyz):
    """(N, 3) NumPy -> mi.Point3f."""
    xyz = np.atleast_2d(np.asarray(xyz, float))
    return mi.Point3f(*(mi.Float(xyz[:, i]) for i in range(3)))


def to_numpy(v) -> np.ndarray:
    """A Dr.Jit 3-vector -> (N, 3) NumPy."""
    return np.stack([np.array(c) for c in v], axis=-1)
