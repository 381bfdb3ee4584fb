"""Image and mesh metrics against hand-computed values."""
import re

import numpy as np
import pytest
import trimesh
from trimesh.triangles import closest_point

from mi_displace.evaluate import metrics

SRGB_HALF = ((0.5 + 0.055) / 1.055) ** 2.4  # linear value that sRGB-encodes to exactly 0.5


def test_assert_finite_names_the_array():
    a = np.ones((4, 4, 3), dtype=np.float32)
    assert metrics.assert_finite(a, "ok") is not None
    a[1, 2, 0] = np.nan
    a[3, 3, 2] = np.inf
    with pytest.raises(ValueError, match=r"approximation image: 1 NaN and 1 Inf .*\(1, 2, 0\)"):
        metrics.assert_finite(a, "approximation image")


def test_flip_identical_is_zero_and_grows_with_the_difference():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
    mean, error_map = metrics.flip(ref, ref.copy())
    assert mean == 0.0 and error_map.shape == (32, 32) and error_map.max() == 0.0
    small, _ = metrics.flip(ref, ref * 0.9)
    large, _ = metrics.flip(ref, ref * 0.5)
    assert 0.0 < small < large <= 1.0


def test_flip_sees_ldr_values_clipped():
    # linear 1.0 and 3.0 both encode to sRGB 1.0: no visible difference in LDR
    mean, _ = metrics.flip(np.ones((16, 16, 3)), np.full((16, 16, 3), 3.0))
    assert mean == 0.0


def test_flip_rejects_mismatched_and_non_finite_images():
    with pytest.raises(ValueError, match="differ in shape"):
        metrics.flip(np.zeros((8, 8, 3)), np.zeros((8, 9, 3)))
    bad = np.zeros((8, 8, 3))
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="test: 1 NaN"):
        metrics.flip(np.zeros((8, 8, 3)), bad)


def test_relmse_by_hand():
    ref = np.ones((4, 4, 3))
    test = np.full((4, 4, 3), 1.1)
    assert metrics.relmse(ref, test) == pytest.approx(0.01 / 1.01, rel=1e-6)
    # dark pixels: eps dominates; half the pixels at ref 0 / test 0.1, half exact
    ref = np.zeros((2, 2, 3))
    test = np.zeros((2, 2, 3))
    test[0] = 0.1
    assert metrics.relmse(ref, test, eps=0.01) == pytest.approx(0.5 * 0.01 / 0.01, rel=1e-6)
    with pytest.raises(ValueError, match="eps"):
        metrics.relmse(ref, test, eps=0.0)


def test_psnr_by_hand():
    ref = np.zeros((8, 8, 3))
    test = np.full((8, 8, 3), SRGB_HALF)  # sRGB 0.5: MSE 0.25, PSNR 10 log10(4)
    assert metrics.psnr(ref, test) == pytest.approx(10 * np.log10(4.0), abs=1e-4)
    assert metrics.psnr(ref, ref) == float("inf")


def test_ssim_identical_is_one_noise_lowers_it_and_tiny_images_are_refused():
    rng = np.random.default_rng(2)
    ref = rng.uniform(0, 1, (24, 24, 3))
    assert metrics.ssim(ref, ref) == pytest.approx(1.0)
    assert metrics.ssim(ref, np.clip(ref + rng.normal(0, 0.1, ref.shape), 0, 1)) < 0.95
    assert metrics.ssim(ref[:5, :5], ref[:5, :5]) == pytest.approx(1.0)  # window shrunk to 5
    with pytest.raises(ValueError, match="at least 3x3"):
        metrics.ssim(ref[:2, :2], ref[:2, :2])


def _grid(n, z=0.0):
    """Unit square at height z, n x n cells, two triangles each."""
    g = np.linspace(0, 1, n + 1)
    x, y = np.meshgrid(g, g)
    vertices = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    v = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    faces = np.concatenate([np.stack([v, v + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + n + 1], 1)])
    return trimesh.Trimesh(vertices, faces, process=False)


def test_mesh_distance_sphere_scaled_by_one_percent():
    a = trimesh.creation.icosphere(subdivisions=3)
    b = a.copy()
    b.apply_scale(1.01)
    d = metrics.mesh_distance(a, b, samples=20_000)
    # facets are parallel: the distance is 0.01 x (facet-plane distance from the centre)
    apothem = np.abs(np.einsum("ij,ij->i", a.face_normals, a.triangles_center)).min()
    assert 0.01 * apothem - 1e-6 <= d["rms"] <= 0.01 + 1e-6
    assert 0.01 * apothem - 1e-6 <= d["hausdorff"] <= 0.01 + 1e-6
    diagonal = np.linalg.norm(a.bounds[1] - a.bounds[0])
    assert d["diagonal"] == pytest.approx(diagonal)
    assert d["rms_rel"] == pytest.approx(d["rms"] / diagonal)
    assert d["hausdorff_rel"] == pytest.approx(d["hausdorff"] / diagonal)


def test_mesh_distance_is_exact_between_differently_tessellated_planes():
    fine, coarse = _grid(20), _grid(1, z=0.3)
    d = metrics.mesh_distance(fine, (coarse.vertices, coarse.faces), samples=5_000)
    assert d["rms"] == pytest.approx(0.3, abs=1e-9)
    assert d["hausdorff"] == pytest.approx(0.3, abs=1e-9)


def test_point_mesh_distance_matches_brute_force():
    rng = np.random.default_rng(3)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.vertices *= rng.uniform(0.5, 1.5, (len(mesh.vertices), 1))  # irregular triangles
    points = rng.uniform(-2, 2, (300, 3))
    triangles = mesh.triangles
    p = np.repeat(points, len(triangles), axis=0)
    q = closest_point(np.tile(triangles, (len(points), 1, 1)), p)
    brute = np.linalg.norm(q - p, axis=1).reshape(len(points), -1).min(axis=1)
    np.testing.assert_allclose(metrics.point_mesh_distance(points, mesh), brute, atol=1e-12)


def test_mesh_distance_bad_input():
    a = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(ValueError, match="mesh b: faces must be integer indices"):
        metrics.mesh_distance(a, (a.vertices, a.faces + 1000))
    with pytest.raises(ValueError, match="samples"):
        metrics.mesh_distance(a, a, samples=0)
    nan_vertices = a.vertices.copy()
    nan_vertices[0, 0] = np.nan
    with pytest.raises(ValueError, match="mesh a vertices: 1 NaN"):
        metrics.mesh_distance((nan_vertices, a.faces), a)


# -- mutants that survived the tests above (docs/testing.md, mutation testing) ---------------


def test_relmse_and_psnr_with_references_that_are_neither_0_nor_1():
    """relMSE divides by ref² (not ref or ref³): at ref 2 the squared error 0.04 is divided
    by 4 + eps; PSNR takes the difference (not the sum) of the encoded images."""
    ref, test = np.full((4, 4, 3), 2.0), np.full((4, 4, 3), 2.2)
    assert metrics.relmse(ref, test, eps=0.01) == pytest.approx(0.04 / 4.01, rel=1e-5)
    half, one = np.full((8, 8, 3), SRGB_HALF), np.ones((8, 8, 3))   # sRGB 0.5 and 1.0
    assert metrics.psnr(half, one) == pytest.approx(10 * np.log10(4.0), abs=1e-4)
    assert metrics.psnr(one, half) == pytest.approx(10 * np.log10(4.0), abs=1e-4)


def test_flip_passes_the_viewing_distance_to_flip():
    """``ppd`` reaches ꟻLIP: the result is flip_evaluator's own at that ppd, and a coarser
    viewing condition changes it."""
    import flip_evaluator

    rng = np.random.default_rng(3)
    ref = rng.uniform(0, 1, (24, 24, 3))
    test = np.clip(ref + rng.normal(0, 0.05, ref.shape), 0, 1)
    direct = flip_evaluator.evaluate(metrics.to_srgb(ref.astype(np.float32)),
                                     metrics.to_srgb(test.astype(np.float32)), "LDR",
                                     parameters={"ppd": 20.0})[1]
    assert metrics.flip(ref, test, ppd=20)[0] == pytest.approx(direct, rel=1e-6)
    assert abs(metrics.flip(ref, test, ppd=20)[0] - metrics.flip(ref, test)[0]) > 1e-3


@pytest.mark.parametrize("call, message", [
    (lambda: metrics.assert_finite(np.array([1.0, np.nan]), "depth map"),
     r"depth map: 1 NaN and 0 Inf values out of 2 \(first at index \(1,\)\)"),
    (lambda: metrics.flip(np.zeros((8, 8, 2)), np.zeros((8, 8, 3))),
     r"reference: expected an image of shape \(H, W, 3\), got shape \(8, 8, 2\)"),
    (lambda: metrics.flip(np.zeros((8, 8, 3)), np.zeros((8, 8, 2))),
     r"test: expected an image of shape \(H, W, 3\), got shape \(8, 8, 2\)"),
    (lambda: metrics.psnr(np.full((2, 2, 3), np.inf), np.zeros((2, 2, 3))),
     r"reference: 0 NaN and 12 Inf values out of 12 \(first at index \(0, 0, 0\)\)"),
    (lambda: metrics.psnr(np.zeros((2, 2, 3)), np.zeros((2, 3, 3))),
     r"reference and test differ in shape: \(2, 2, 3\) vs \(2, 3, 3\)"),
    (lambda: metrics.relmse(np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), eps=-1.0),
     r"eps: must be > 0, got -1.0"),
])
def test_error_messages_are_exact(call, message):
    """The whole message, start to end: it names the array or parameter first."""
    with pytest.raises(ValueError) as caught:
        call()
    assert re.fullmatch(message, str(caught.value)), str(caught.value)


@pytest.mark.parametrize("shape, window", [((24, 24, 3), 7), ((6, 9, 3), 5), ((4, 4, 3), 3),
                                           ((5, 8, 3), 5)])
def test_ssim_window_is_the_largest_odd_size_up_to_7(shape, window):
    """scikit-image's SSIM with the documented window: 7, or the largest odd size that fits."""
    from skimage.metrics import structural_similarity

    rng = np.random.default_rng(4)
    ref = rng.uniform(0, 1, shape)
    test = np.clip(ref + rng.normal(0, 0.1, shape), 0, 1)
    direct = structural_similarity(metrics.to_srgb(ref.astype(np.float32)),
                                   metrics.to_srgb(test.astype(np.float32)), data_range=1.0,
                                   channel_axis=-1, win_size=window)
    assert metrics.ssim(ref, test) == pytest.approx(direct, rel=1e-6)


@pytest.mark.parametrize("call, message", [
    (lambda: metrics.ssim(np.zeros((2, 5, 3)), np.zeros((2, 5, 3))),
     r"ssim: images must be at least 3x3 pixels, got \(2, 5\)"),
    (lambda: metrics.mesh_distance(42, (np.eye(3), [[0, 1, 2]])),
     r"mesh a: expected a trimesh.Trimesh or \(vertices, faces\)"),
    (lambda: metrics.mesh_distance((np.eye(3), [[0, 1, 2]]), (np.zeros((3, 2)), [[0, 1, 2]])),
     r"mesh b: vertices must have shape \(V, 3\), got \(3, 2\)"),
])
def test_more_error_messages_are_exact(call, message):
    with pytest.raises(ValueError) as caught:
        call()
    assert re.fullmatch(message, str(caught.value)), str(caught.value)


def _triangle():
    return np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])


@pytest.mark.parametrize("mesh, message", [
    ((_triangle()[0], np.array([[0, 1]])), r"mesh b: faces must have shape \(F, 3\) with F > 0, got \(1, 2\)"),
    ((_triangle()[0], np.array([[0, 1, 3]])), r"mesh b: faces must be integer indices in \[0, 3\)"),
    ((_triangle()[0], np.array([[0.0, 1.0, 2.0]])), r"mesh b: faces must be integer indices in \[0, 3\)"),
    ((np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]])),
     r"mesh b: the mesh has zero surface area"),
])
def test_bad_meshes_are_refused_with_exact_messages(mesh, message):
    """Index == vertex count, float indices, a 2-column face array and a degenerate
    (collinear) triangle are refused before any distance is computed."""
    with pytest.raises(ValueError) as caught:
        metrics.mesh_distance(_triangle(), mesh, samples=10)
    assert re.fullmatch(message, str(caught.value)), str(caught.value)
