"""Image and mesh error metrics.

Images are NumPy arrays ``(H, W, 3)`` of *linear* RGB (what Mitsuba renders).  Which
encoding each metric sees is part of its definition:

==========  ===========================================  =====================================
metric      input                                        definition
==========  ===========================================  =====================================
FLIP        sRGB-encoded, clipped to [0, 1] (LDR)        NVIDIA ꟻLIP, ``flip_evaluator``, 67 ppd
relMSE      linear HDR                                   mean over pixels and channels of
                                                         (test - ref)² / (ref² + eps)
PSNR        sRGB-encoded, clipped to [0, 1]              10 log10(1 / MSE) in dB
SSIM        sRGB-encoded, clipped to [0, 1]              ``skimage.metrics.structural_similarity``
==========  ===========================================  =====================================

Mesh distances (:func:`mesh_distance`) are exact point-to-triangle distances from
area-uniform surface samples, in both directions, in scene units and relative to the
bounding-box diagonal of the first mesh.
"""
from __future__ import annotations

import numpy as np

from mi_displace.core.io import as_rgb, to_srgb


def assert_finite(array, name: str) -> np.ndarray:
    """Return ``array`` as a NumPy array; raise ``ValueError`` naming it if any entry is NaN/Inf.

    Args:
        array: anything ``np.asarray`` accepts (NumPy, Dr.Jit / Mitsuba arrays and tensors).
        name: what the array is, used in the message (e.g. ``"reference image"``).
    """
    a = np.asarray(array)
    if np.issubdtype(a.dtype, np.inexact):
        bad = ~np.isfinite(a)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"{name}: {int(np.isnan(a).sum())} NaN and {int(np.isinf(a).sum())} Inf values "
                f"out of {a.size} (first at index {first})"
            )
    return a


def _image_pair(reference, test) -> tuple[np.ndarray, np.ndarray]:
    """Both images as finite float32 ``(H, W, 3)`` arrays of the same shape."""
    ref = assert_finite(as_rgb(reference, "reference"), "reference")
    tst = assert_finite(as_rgb(test, "test"), "test")
    if ref.shape != tst.shape:
        raise ValueError(f"reference and test differ in shape: {ref.shape} vs {tst.shape}")
    return ref, tst


def flip(reference, test, ppd: float | None = None) -> tuple[float, np.ndarray]:
    """LDR ꟻLIP between two linear images (both are clipped and sRGB-encoded first).

    Args:
        reference, test: linear RGB ``(H, W, 3)``.
        ppd: pixels per degree of visual angle; ``None`` uses FLIP's default (67).

    Returns:
        ``(mean, error_map)``: the mean FLIP error in ``[0, 1]`` (0 = identical) and the
        per-pixel error map, float32 ``(H, W)``.
    """
    import flip_evaluator

    ref, tst = _image_pair(reference, test)
    parameters = {} if ppd is None else {"ppd": float(ppd)}
    error_map, mean, _ = flip_evaluator.evaluate(
        to_srgb(ref), to_srgb(tst), "LDR", applyMagma=False, parameters=parameters
    )
    return float(mean), np.asarray(error_map, dtype=np.float32).reshape(ref.shape[:2])


def relmse(reference, test, eps: float = 1e-2) -> float:
    """Relative mean squared error on linear HDR values.

    ``mean((test - ref)² / (ref² + eps))`` over all pixels and channels; ``eps`` (in the
    squared units of the image) keeps dark pixels from dominating.
    """
    if not eps > 0:
        raise ValueError(f"eps: must be > 0, got {eps!r}")
    ref, tst = _image_pair(reference, test)
    ref64, tst64 = ref.astype(np.float64), tst.astype(np.float64)
    return float(np.mean((tst64 - ref64) ** 2 / (ref64 ** 2 + eps)))


def psnr(reference, test) -> float:
    """Peak signal-to-noise ratio in dB of the sRGB-encoded, clipped images (peak 1).

    Returns ``inf`` for identical images.
    """
    ref, tst = _image_pair(reference, test)
    mse = float(np.mean((to_srgb(tst).astype(np.float64) - to_srgb(ref)) ** 2))
    return float("inf") if mse == 0.0 else float(10.0 * np.log10(1.0 / mse))


def ssim(reference, test) -> float:
    """Structural similarity (1 = identical) of the sRGB-encoded, clipped images.

    Uses scikit-image's default uniform 7×7 window, shrunk to the largest odd size
    that fits images smaller than 7 pixels; images under 3 pixels raise ``ValueError``.
    """
    from skimage.metrics import structural_similarity

    ref, tst = _image_pair(reference, test)
    side = min(ref.shape[:2])
    win = min(7, side if side % 2 else side - 1)
    if win < 3:
        raise ValueError(f"ssim: images must be at least 3x3 pixels, got {ref.shape[:2]}")
    return float(
        structural_similarity(
            to_srgb(ref), to_srgb(tst), data_range=1.0, channel_axis=-1, win_size=win
        )
    )


# ----------------------------------------------------------------------------- meshes


def _as_trimesh(mesh, name: str):
    """A ``trimesh.Trimesh`` from a Trimesh or a ``(vertices (V,3), faces (F,3))`` pair."""
    import trimesh

    if isinstance(mesh, trimesh.Trimesh):
        vertices, faces = mesh.vertices, mesh.faces
    else:
        try:
            vertices, faces = mesh
        except (TypeError, ValueError) as e:
            raise ValueError(f"{name}: expected a trimesh.Trimesh or (vertices, faces)") from e
    vertices = assert_finite(np.asarray(vertices, dtype=np.float64), f"{name} vertices")
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"{name}: vertices must have shape (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ValueError(f"{name}: faces must have shape (F, 3) with F > 0, got {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer) or faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f"{name}: faces must be integer indices in [0, {len(vertices)})")
    result = trimesh.Trimesh(vertices, faces, process=False)
    if not result.area > 0:
        raise ValueError(f"{name}: the mesh has zero surface area")
    return result


def point_mesh_distance(points, mesh) -> np.ndarray:
    """Exact distance from each point to the closest point of a triangle mesh (libigl's
    AABB tree, ``igl.point_mesh_squared_distance``).

    Args:
        points: ``(N, 3)`` query points.
        mesh: ``trimesh.Trimesh``.

    Returns:
        float64 ``(N,)`` distances in the mesh's units.
    """
    import igl

    squared, _, _ = igl.point_mesh_squared_distance(
        np.asarray(points, dtype=np.float64), np.asarray(mesh.vertices, dtype=np.float64),
        np.asarray(mesh.faces, dtype=np.int64))
    return np.sqrt(squared)


def mesh_distance(a, b, samples: int = 100_000, seed: int = 0) -> dict:
    """Symmetric surface distance between two triangle meshes.

    ``samples`` area-uniform points are drawn on each surface and their exact distance to
    the other surface is computed (:func:`point_mesh_distance`).

    Args:
        a, b: ``trimesh.Trimesh`` or ``(vertices (V, 3), faces (F, 3))``.  ``a`` is the
            reference: relative values divide by the diagonal of its bounding box.
        samples: points per direction (> 0).
        seed: seed of the surface sampling.

    Returns:
        dict with, in scene units, ``rms`` (root mean square over both directions' samples),
        ``mean``, ``hausdorff`` (largest distance either way), ``rms_ab`` / ``rms_ba`` and
        ``hausdorff_ab`` / ``hausdorff_ba`` (one direction each), the relative
        ``rms_rel`` and ``hausdorff_rel``, ``diagonal`` and ``samples``.
    """
    from trimesh.sample import sample_surface

    if not isinstance(samples, (int, np.integer)) or samples <= 0:
        raise ValueError(f"samples: must be a positive integer, got {samples!r}")
    mesh_a, mesh_b = _as_trimesh(a, "mesh a"), _as_trimesh(b, "mesh b")
    points_a, _ = sample_surface(mesh_a, int(samples), seed=seed)
    points_b, _ = sample_surface(mesh_b, int(samples), seed=seed + 1)
    d_ab = point_mesh_distance(points_a, mesh_b)
    d_ba = point_mesh_distance(points_b, mesh_a)
    both = np.concatenate([d_ab, d_ba])
    diagonal = float(np.linalg.norm(mesh_a.bounds[1] - mesh_a.bounds[0]))
    if not diagonal > 0:
        raise ValueError("mesh a: bounding box has zero diagonal")
    rms = float(np.sqrt(np.mean(both ** 2)))
    hausdorff = float(both.max())
    return {
        "rms": rms,
        "mean": float(both.mean()),
        "hausdorff": hausdorff,
        "rms_ab": float(np.sqrt(np.mean(d_ab ** 2))),
        "rms_ba": float(np.sqrt(np.mean(d_ba ** 2))),
        "hausdorff_ab": float(d_ab.max()),
        "hausdorff_ba": float(d_ba.max()),
        "rms_rel": rms / diagonal,
        "hausdorff_rel": hausdorff / diagonal,
        "diagonal": diagonal,
        "samples": int(samples),
    }
