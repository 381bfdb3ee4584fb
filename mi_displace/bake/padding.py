"""Edge padding (§4: "edge line extension ... to avoid unpleasant effects of texture filtering").

Texels outside the UV charts but within ``k`` texels of a covered texel take the value of
their nearest covered texel, so bilinear filtering and mip-mapping near chart borders do not
pull in background.  Distance is the chessboard metric, so padding by k equals k rounds of
8-neighbour dilation; the nearest covered texel is found in one vectorised pass by SciPy's
chamfer distance transform (``distance_transform_cdt``, 2.5x faster than the Euclidean one).
"""
from __future__ import annotations

import numpy as np


def pad(image: np.ndarray, covered: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Dilate ``image`` by ``k`` texels from the ``covered`` mask, in place.

    Args:
        image: (H, W) or (H, W, C) array (all channels padded together).
        covered: (H, W) bool, texels that hold baked values.
        k: padding radius in texels (0 = none, ``inf`` = fill the whole map).

    Returns:
        (image, (H, W) bool mask of texels that now hold a value).
    """
    from scipy.ndimage import distance_transform_cdt

    if not (k >= 0):
        raise ValueError(f"padding: must be >= 0 texels, got {k!r}")
    if k == 0 or covered.all() or not covered.any():
        return image, covered.copy()
    dist, (ri, ci) = distance_transform_cdt(~covered, metric="chessboard", return_indices=True)
    fill = (dist <= k) & ~covered
    image[fill] = image[ri[fill], ci[fill]]
    return image, covered | fill
