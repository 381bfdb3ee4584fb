"""The low-poly's UV layout rasterised into texels (bake/uv_raster.py): the anti-aliasing grid,
the conservative band around a chart, slivers without texels, overlapping triangles counted."""
import re

import numpy as np
import pytest
from bake_meshes import plane, tilted_plane

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData


def test_uv_warning_is_the_whole_sentence(variant):
    low = plane(n=2)
    low.uvs[4] = low.uvs[0]
    with pytest.warns(UserWarning) as w:
        r = bake(plane(z=0.01, n=4), low, res=32, max_distance=0.1)
    n_deg, n_over = r.record["low"]["uv_degenerate_triangles"], r.record["counts"]["uv_overlap_texels"]
    assert re.fullmatch(rf"low-poly UVs: {n_deg} degenerate triangles, {n_over} texels covered by "
                        r"overlapping triangles \(texture mapping not unambiguous, §3\.1\)",
                        str(w[0].message))


@pytest.mark.parametrize("aa", [1, 2, 3])
def test_texel_value_is_the_mean_over_its_aa_grid(variant, aa):
    # d is linear in x, so the mean over any symmetric aa x aa grid is its value at the
    # texel centre u = (c + 0.5) / W (formats.UV_CONVENTION)
    W = 8
    r = bake(tilted_plane(), plane(n=2), res=W, aa=aa, max_distance=0.2, pad=0)
    x = (np.arange(W) + 0.5) / W
    assert np.allclose(r.maps["displacement"], 0.02 + 0.1 * x[None, :], atol=2e-6)


def test_conservative_band_texels_take_a_chart_point_of_their_own_footprint(variant):
    # the chart covers u, v in [0.02, 0.478] (not on texel edges): the texels around it whose
    # centres miss but whose corners overlap it are added, valued at a point of the chart
    # (the centre's barycentrics clamped onto a triangle its corners found) that lies within
    # the texel's own footprint; inside, every texel is its centre's value
    W, lo, span = 32, 0.02, 0.458
    low = plane(n=2)
    low = MeshData(low.positions, low.faces, (low.uvs * span + lo).astype(np.float32))
    r = bake(tilted_plane(), low, res=W, max_distance=0.2, pad=0)
    u = (np.arange(W) + 0.5) / W
    inside = (u > lo) & (u < lo + span)
    band = ~inside & (u + 0.5 / W > lo) & (u - 0.5 / W < lo + span)
    assert band.sum() == 2 and r.record["counts"]["conservative_samples"] > 0
    rows = np.nonzero(r.covered.any(1))[0]
    assert len(rows) == (inside | band).sum() and r.covered[rows][:, inside | band].all()
    assert r.covered.sum() == (inside | band).sum() ** 2
    mid = rows[1:-1]                                    # rows whose centres are inside
    x_of = lambda uu: (np.clip(uu, lo, lo + span) - lo) / span   # chart x of a UV u
    d = r.maps["displacement"][mid]
    assert np.allclose(d[:, inside], 0.02 + 0.1 * x_of(u[inside]), atol=2e-6)
    x = (d[:, band] - 0.02) / 0.1
    assert np.all(x >= x_of(u[band] - 0.5 / W) - 1e-5) and np.all(x <= x_of(u[band] + 0.5 / W) + 1e-5)


def test_an_isolated_sliver_chart_gets_no_texels_and_is_counted(variant):
    # uv_raster docstring: only uncovered texels next to a covered one try their corners, so a
    # UV island thinner than a texel and far from every covered texel gets none, and is
    # reported in triangles_without_texels (the main chart gets all its texels)
    low = plane(n=2)
    pos = np.concatenate([low.positions, low.positions[low.faces[0]]])
    uvs = np.concatenate([low.uvs * np.float32(0.5),
                          np.float32([[0.80, 0.70], [0.80 + 0.3 / 16, 0.70], [0.80, 0.90]])])
    faces = low.faces.copy()
    faces[0] = [9, 10, 11]
    r = bake(plane(z=0.02, n=4), MeshData(pos, faces, uvs.astype(np.float32)), res=16,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["triangles_without_texels"] == 1
    assert not r.covered[:, 11:].any() and r.covered[8:, :8].sum() > 0.6 * 64   # face 0 moved


def test_overlap_is_measured_at_most_at_256(variant):
    # "it costs 2 x 256^2 rays at most" (overlap_texels): the record says at what resolution
    r = bake(plane(z=0.02, n=2), plane(n=1), res=300, max_distance=0.05, pad=0)
    assert r.record["counts"]["uv_overlap_resolution"] == 256
    r = bake(plane(z=0.02, n=2), plane(n=1), res=(40, 20), max_distance=0.05, pad=0)
    assert r.record["counts"]["uv_overlap_resolution"] == 40


def test_overlap_count_is_the_texel_centres_inside_both_triangles(variant):
    # a two-triangle low-poly whose second triangle's UVs are moved onto the first one: the
    # overlap reaches below the map's bottom row; overlap_texels counts the grid centres
    # strictly inside both (margin 1e-4 in barycentrics), as a NumPy point-in-triangle test does
    from mi_displace.bake.uv_raster import UVLayout, overlap_texels

    pos = np.float32([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0]])
    uvs = np.float32([[0.05, -0.2], [0.9, -0.1], [0.3, 0.85], [0.2, -0.3], [0.8, 0.7], [0.1, 0.6]])
    low = MeshData(pos, np.array([[0, 1, 2], [3, 4, 5]]), uvs)
    res = 64
    c = (np.arange(res) + 0.5) / res
    u, v = np.meshgrid(c, 1 - c, indexing="xy")
    pts = np.stack([u.ravel(), v.ravel()], 1)

    def inside(tri):
        a, b, cc = uvs[tri]
        m = np.linalg.inv(np.stack([b - a, cc - a], 1))
        w = (pts - a) @ m.T
        return np.minimum(np.minimum(w[:, 0], w[:, 1]), 1 - w.sum(1)) > 1e-4

    both = inside([0, 1, 2]) & inside([3, 4, 5])
    expected = int(both.sum())
    assert expected > 100 and both.reshape(res, res)[-1].any()   # the bottom row too
    assert overlap_texels(UVLayout(low), res) == expected
