"""Shared helpers of the DDM tests: a spherical cap as a mesh base, Dr.Jit vectors as NumPy."""
import numpy as np


def spherical_cap(radius=2.0):
    """A spherical cap (z > 0.3 of an icosphere) of ``radius`` with exact normals p / r and a
    one-to-one planar UV layout (x, y) / 2 + 1/2: (positions, normals, uvs, faces)."""
    import trimesh

    ico = trimesh.creation.icosphere(3)
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1, keepdims=True)
    faces = ico.faces[np.all(v[ico.faces][:, :, 2] > 0.3, axis=1)]
    used, faces = np.unique(faces, return_inverse=True)
    v = v[used]
    return radius * v, v, v[:, :2] / 2 + 0.5, faces.reshape(-1, 3)


def to_numpy(v) -> np.ndarray:
    """A Dr.Jit 3-vector -> (N, 3) NumPy."""
    return np.stack([np.asarray(c) for c in v], 1)
