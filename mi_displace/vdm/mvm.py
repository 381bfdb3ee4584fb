"""The maximal view polar angle map (MVM, paper §3.3).

``theta_MVM(x, y, phi, c) = max theta such that d_VDM(x, y, theta, phi, c) != -1``.
Rays steeper than it hit the mesostructure, rays beyond it pass by (silhouette).  With the
MVM stored, the -1 entries of the VDM are replaced by a smooth continuation (the value at
the MVM angle) so that a low-rank SVD fit is not wrecked by the discontinuity; at render
time the silhouette test is ``theta_V > theta_MVM``.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np


def maximal_view_angle(largest_kept_theta: mi.Float, c: mi.Float, floor_depth: float) -> mi.Float:
    """MVM [rad] from the largest non-occluded bent angle theta' of each (row, c).

    For c <= 0 (flat or concave) every ray below the horizon reaches the periodic
    mesostructure: pi/2.  For c > 0 it is the larger of the largest kept theta' and the
    angle below which a ray from P certainly dives beneath the deepest mesostructure
    point (depth ``floor_depth`` = D (1 - min H)): the ray at theta from the normal comes
    within (1/c) sin(theta) of the centre of curvature, so it reaches depth
    (1 - sin theta) / c, which is >= floor_depth for sin(theta) <= 1 - c floor_depth.
    This bound tends to pi/2 as c -> 0, so the MVM is continuous at c = 0 (the sparse
    theta grid alone would put a false silhouette at grazing angles of flat regions).
    """
    guaranteed = dr.asin(dr.clip(1.0 - c * floor_depth, -1.0, 1.0))
    return dr.select(c > 0, dr.maximum(dr.maximum(largest_kept_theta, guaranteed), 0.0),
                     math.pi / 2)


def invalid_mask(theta_grid: np.ndarray, theta_mvm: np.ndarray) -> np.ndarray:
    """Boolean mask of the paper's -1 entries: theta > theta_MVM.

    Args:
        theta_grid: (n_theta,) polar angles [rad].
        theta_mvm: (..., ) MVM values [rad].

    Returns:
        (..., n_theta) bool.
    """
    return np.asarray(theta_grid)[None, :] > np.asarray(theta_mvm).reshape(-1, 1)


def with_invalid(d: np.ndarray, theta_grid: np.ndarray, theta_mvm: np.ndarray) -> np.ndarray:
    """The paper's raw VDM: ``d`` (..., n_theta) with -1 where theta > theta_MVM."""
    d = np.array(d, dtype=np.float32).reshape(-1, len(theta_grid))
    d[invalid_mask(theta_grid, theta_mvm)] = -1.0
    return d
