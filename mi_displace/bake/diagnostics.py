"""Diagnostics mode (§3.1): where the projection failed, as an image and as counts.

Texel status (worst of its samples, :mod:`mi_displace.bake.trace`): ``empty`` (no UV
triangle), ``ok``, ``ambiguous`` (the normal line crosses the high-poly more than once within
+-max_distance: height-field assumption broken), ``backface`` (only a back-facing high-poly
face was in reach), ``beyond`` (the high-poly is farther than ``max_distance``), ``miss``
(no high-poly along the line at all).
"""
from __future__ import annotations

import numpy as np

from mi_displace.bake.trace import STATUS_NAMES

#: sRGB 8-bit colour of each status in the diagnostics image.
COLOURS = {0: (0, 0, 0), 1: (90, 90, 90), 2: (255, 200, 0), 3: (200, 0, 255),
           4: (255, 60, 0), 5: (0, 160, 255)}


def counts(status: np.ndarray) -> dict:
    """Texel count of every status name (``status``: (H, W) uint8 codes)."""
    hist = np.bincount(status.ravel(), minlength=len(STATUS_NAMES))
    return {STATUS_NAMES[k]: int(hist[k]) for k in STATUS_NAMES}


def image(status: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 colour-coded status image (legend: :data:`COLOURS`)."""
    lut = np.array([COLOURS[k] for k in sorted(COLOURS)], np.uint8)
    return lut[status]
