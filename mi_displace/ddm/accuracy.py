"""Measured accuracy of HDDM: geometry (``maps`` at R against ``exact``) and the three normal
methods.

* :func:`geometric_accuracy` — the same tiles mapped by DDM (exact S, n; ``jacobian``
  normals as the truth) and by HDDM at each map resolution: RMS and max vertex distance
  relative to the bounding-box diagonal, mean / max normal angle error [degrees].
* :func:`normal_methods` — ``tangent`` / ``naive`` against ``jacobian`` on ``exact``;
  :func:`epsilon_sweep` — the tangent points' ε against the same truth.

The tables, plots and the image sweep over ``map_resolution`` of docs/ddm.md are
:mod:`mi_displace.figures.ddm` (``mi-displace figures ddm``).
"""
from __future__ import annotations

import numpy as np

from mi_displace.ddm import base_maps, mapping
from mi_displace.ddm import normals as nrm
from mi_displace.ddm.model import DDMConfig, DDMModel

RESOLUTIONS = (32, 64, 128, 256, 512, 1024)
#: the thorns-on-sphere set-up of scenes/ddm_thorns_sphere.xml
THORNS_SPHERE = dict(base="sphere", base_params={"radius": 1.0}, tile="thorn", tiles_u=32,
                     tiles_v=16, height=0.3)


def to_numpy3(v) -> np.ndarray:
    """A Dr.Jit 3-vector of n entries as an (n, 3) NumPy array."""
    return np.stack([np.asarray(c) for c in v], 1)


def geometric_accuracy(cfg: DDMConfig, resolutions=RESOLUTIONS, method: str | None = None) -> list[dict]:
    """``maps`` at each resolution against ``exact`` on the same placed tiles.

    Returns:
        One dict per resolution: ``resolution``, ``rms_error_rel``, ``max_error_rel``
        (vertex distance / bbox diagonal), ``normal_mean_deg``, ``normal_max_deg``
        (against exact ``jacobian`` normals), ``maps_bytes``.
    """
    cfg.mode = "exact"
    model = DDMModel(cfg)
    p_ref, n_ref, uv = model.map(method="jacobian")
    ref = to_numpy3(p_ref)
    diag = float(np.linalg.norm(ref.max(0) - ref.min(0)))
    clamped = model.clamped_mask(uv)
    rows = []
    for r in resolutions:
        maps = model.maps_at(r)
        p, n, _ = model.map(method=method, evaluator=mapping.MapsEvaluator(maps))
        p = to_numpy3(p)
        d = np.linalg.norm(p - ref, axis=1)
        ang = np.asarray(nrm.angle_error_deg(n, n_ref))
        row = {"resolution": r, "rms_error_rel": float(np.sqrt(np.mean(d * d)) / diag),
               "max_error_rel": float(d.max() / diag), "normal_mean_deg": float(ang.mean()),
               "normal_max_deg": float(ang.max()), "maps_bytes": maps.nbytes, "vertices": len(d)}
        if clamped.any():   # mesh bases: vertices on their chart vs clamped ones
            row.update(unclamped_max_rel=float(d[~clamped].max() / diag),
                       clamped_p99_rel=float(np.percentile(d[clamped], 99) / diag),
                       clamped_fraction=float(clamped.mean()),
                       **_stretch(p, model.buffers.vertex_count))
        rows.append(row)
    return rows


def _stretch(p: np.ndarray, vertex_count: list) -> dict:
    """Largest mapped tile extent (bbox diagonal) over the median, and how many tiles are
    more than 3x the median (one tile kind)."""
    if len(vertex_count) != 1:
        return {}
    extent = np.linalg.norm(np.ptp(p.reshape(-1, vertex_count[0], 3), 1), axis=1)
    med = np.median(extent)
    return {"tile_extent_max_over_median": float(extent.max() / med),
            "tiles_over_3x_median": int((extent > 3 * med).sum())}


def normal_methods(cfg: DDMConfig) -> list[dict]:
    """Angle error [degrees] of each normal method against ``jacobian``, all on ``exact``."""
    cfg.mode = "exact"
    model = DDMModel(cfg)
    _, truth, _ = model.map(method="jacobian")
    rows = []
    for method in nrm.METHODS:
        _, n, _ = model.map(method=method)
        ang = np.asarray(nrm.angle_error_deg(n, truth))
        rows.append({"method": method, "mean_deg": float(ang.mean()),
                     "p99_deg": float(np.percentile(ang, 99)), "max_deg": float(ang.max())})
    return rows


def epsilon_sweep(cfg: DDMConfig, epsilons=(1e-5, 1e-4, 1e-3, 1e-2, 1e-1)) -> list[dict]:
    """Angle error [degrees] of ``tangent`` normals against ``jacobian`` per ε (tile units),
    on ``exact`` and on ``maps`` (at ``cfg.map_resolution``): too small an ε loses float32
    precision after the mapping, too large an ε bends across the tile / map texels."""
    cfg.mode = "exact"
    model = DDMModel(cfg)
    _, truth, _ = model.map(method="jacobian")
    maps = mapping.MapsEvaluator(base_maps.build_maps(model.base, cfg.map_resolution))
    _, truth_maps, _ = model.map(method="jacobian", evaluator=maps)
    rows = []
    for eps in epsilons:
        model.cfg.epsilon = eps
        row = {"epsilon": eps}
        for name, ev, ref in (("exact", None, truth), ("maps", maps, truth_maps)):
            _, n, _ = model.map(method="tangent", evaluator=ev)
            ang = np.asarray(nrm.angle_error_deg(n, ref))
            row[f"{name}_mean_deg"], row[f"{name}_max_deg"] = float(ang.mean()), float(ang.max())
        rows.append(row)
    return rows
