"""The surface reference: marching cubes of the exactly displaced field."""
import numpy as np
import pytest


def _ball_volume(maps=()):
    from mi_displace.volume.displacement import DisplacementChain
    from mi_displace.volume.field import DisplacedVolume
    from mi_displace.volume.objects import ObjectVolume

    n = 48
    c = (np.arange(n) + 0.5) / n - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x * x + y * y + z * z)
    obj = ObjectVolume(np.clip((0.3 - r) / 0.15, 0, 1), [-0.5] * 3, [0.5] * 3, value_range=(0, 1))
    return DisplacedVolume(obj, DisplacementChain(list(maps)), tf_low=0.0, tf_high=1.0)


def test_isosurface_of_a_ball_lies_on_its_level_set(variant):
    from mi_displace.volume.isosurface import isosurface

    verts, faces = isosurface(_ball_volume(), iso=0.5, res=96)
    radius = np.linalg.norm(verts, axis=1)
    assert np.abs(radius - 0.225).max() < 0.01          # field 0.5 at r = 0.3 - 0.075
    # faces turn outwards: the signed volume of the closed mesh is positive
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert volume == pytest.approx(4 / 3 * np.pi * 0.225 ** 3, rel=0.03)


def test_isosurface_follows_the_exact_displacement(variant):
    """A slab cut through the ball: no vertex lies inside the gap, both halves are kept."""
    from mi_displace.volume.displacement import PlacedMap
    from mi_displace.volume.isosurface import isosurface

    m = np.array([[1.0, 0, 0, -0.5], [0, 1, 0, -0.5], [0, 0, 1, -0.5], [0, 0, 0, 1]])
    vol = _ball_volume([PlacedMap("slabs", {"count": 2, "gap": 0.1}, to_world=m, resolution=(2, 2, 64))])
    verts, _ = isosurface(vol, iso=0.5, res=128)
    h = 1.3 / 127                                        # grid spacing over the proxy box
    inside_gap = (verts[:, 2] > h) & (verts[:, 2] < 0.1 - h)
    assert not inside_gap.any()
    assert verts[:, 2].max() > 0.3 and verts[:, 2].min() < -0.2   # upper half lifted by 0.1
    with pytest.raises(ValueError, match="iso"):
        isosurface(vol, iso=1.5)
