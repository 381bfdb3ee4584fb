"""Meshes shared by the baker tests, imported by name (a helper module, not ``conftest``:
``from conftest import`` resolves to whichever conftest pytest imported last when it is given
files from several folders): an analytic displaced sphere and small planes."""
import numpy as np

AMPLITUDE = 0.05


def sphere_height(p: np.ndarray) -> np.ndarray:
    """The known displacement function of the unit sphere (direction p, (N, 3)) in [-1, 1]."""
    d = p / np.linalg.norm(p, axis=-1, keepdims=True)
    return d[..., 0] * d[..., 1] * 2.0 + 0.5 * d[..., 2] ** 2 - 0.25


def _sphere_mesh(nu, nv, amplitude):
    import drjit as dr
    import mitsuba as mi

    from mi_displace.bake.meshdata import MeshData
    from mi_displace.core import surfaces, tessellate

    base = surfaces.make_base("sphere", radius=1.0)

    def height(uv):
        s = base.sample(uv.x, uv.y)
        x, y, z = s.p.x, s.p.y, s.p.z
        r = dr.sqrt(x * x + y * y + z * z)
        h = 2.0 * x * y / (r * r) + 0.5 * z * z / (r * r) - 0.25
        return h, mi.Vector2f(0.0, 0.0)

    t = tessellate.displace_parametric(base, height if amplitude else None, amplitude, 0.0, nu, nv)
    pos = np.stack([np.asarray(c) for c in t.positions], 1)
    uv = np.stack([np.asarray(c) for c in t.texcoords], 1)
    faces = np.stack([np.asarray(c) for c in t.faces], 1).astype(np.int64)
    return MeshData(pos.astype(np.float32), faces, uv.astype(np.float32), name="sphere")


def plane(size=1.0, z=0.0, n=1, uv=True, flip=False):
    """A square [0, size]^2 at height z, n x n quads, UVs = (x, y) / size."""
    from mi_displace.bake.meshdata import MeshData

    g = np.linspace(0, size, n + 1)
    x, y = np.meshgrid(g, g, indexing="xy")
    pos = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], 1).astype(np.float32)
    i = np.arange(n * n)
    a = (i // n) * (n + 1) + i % n
    faces = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    if flip:
        faces = faces[:, ::-1]
    return MeshData(pos, faces.astype(np.int64), (pos[:, :2] / size).astype(np.float32) if uv else None)


def tilted_plane(n=8, z0=0.02, slope=0.1, slope_y=0.0):
    """A plane z = z0 + slope * x + slope_y * y (n x n quads) over [-0.1, 1.1]^2: the rays
    along the low-poly's +z normal measure d = z0 + slope * x + slope_y * y exactly."""
    from mi_displace.bake.meshdata import MeshData

    p = plane(size=1.2, n=n)
    pos = p.positions - np.float32([0.1, 0.1, 0.0])
    pos[:, 2] = z0 + slope * pos[:, 0] + slope_y * pos[:, 1]
    return MeshData(pos, p.faces, None)
