"""Tests written for mutants of slicing/ that survived the suite (issue 19; docs/testing.md,
"Bake, volume and slicing modules").  Each asserts numbers against an independent truth."""
import numpy as np
import pytest


@pytest.mark.parametrize("n", [1, 5])
def test_a_plane_base_is_boxed_by_twelve_wall_triangles(variant, n):
    # the unit-square base (two triangles): its displacement volume is a box, top and bottom
    # two triangles each and a quad on each of the four open edges; n aligned slices are n
    # copies of the base
    import mitsuba as mi

    from mi_displace.slicing import geometry as geo
    from mi_displace.slicing.sliced import SlicedVolume

    bm = geo.make_base_mesh("plane", {}, None, 1, np.eye(4))
    assert len(bm.faces) == 2 and len(geo.boundary_edges(bm)) == 4
    vol = SlicedVolume(bm, mi.load_dict({"type": "uniform", "value": 0.5}), 0.2, n, "a", "basic")
    assert vol.stats["wall_triangles"] == 12 and vol.walls_scene.triangles == 12
    assert vol.stats["slice_triangles"] == 2 * n and vol.stats["base_faces"] == 2
    walls = geo.volume_walls(bm, 0.2)
    z = walls.positions[:, 2]
    assert z.min() < 0 < 0.2 < z.max() < 0.2 * 1.01     # -eps below, 1 + eps above (h x scale)
