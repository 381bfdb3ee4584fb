"""Tiles over a polygonal base's UV layout (HDDM §4.1), decided on the exact base.

Which tiles a mesh base keeps must not depend on the approximation's ``map_resolution``
(the exact reference would move with the knob being measured), so it is decided from the
mesh itself: each placed tile is probed at up to :data:`MAX_PROBES` points of its own
footprint (the distinct (x, y) of its vertices and its centre) located exactly on the UV
layout; a tile none of whose probes lands on the layout is pruned (the paper's "tiles that
are totally outside the valid region are purged").
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

#: probes per tile kind (distinct vertex (x, y), evenly subsampled, plus the centre)
MAX_PROBES = 64


def probe_points(tile) -> np.ndarray:
    """(P, 2) canonical (x, y) probes of a tile: distinct vertex footprints + bbox centre."""
    xy = np.unique(np.round(tile.positions[:, :2].astype(np.float64), 5), axis=0)
    if len(xy) > MAX_PROBES - 1:
        xy = xy[np.linspace(0, len(xy) - 1, MAX_PROBES - 1).round().astype(np.int64)]
    centre = 0.5 * (tile.positions[:, :2].min(0) + tile.positions[:, :2].max(0))
    return np.concatenate([xy, centre[None].astype(np.float64)])


def probe_layout(layout, tiles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every probe of every placed tile: ``(instance, u, v)``, (N,) arrays (NumPy)."""
    probes = [probe_points(t) for t in tiles]
    su, sv = layout.size
    inst, us, vs = [], [], []
    for k, pts in enumerate(probes):
        where = np.flatnonzero(layout.tile_index == k)
        if not len(where):
            continue
        off = layout.offsets[where]
        inst.append(np.repeat(where, len(pts)))
        us.append((off[:, None, 0] + su * pts[None, :, 0]).ravel())
        vs.append((off[:, None, 1] + sv * pts[None, :, 1]).ravel())
    return np.concatenate(inst), np.concatenate(us), np.concatenate(vs)


def prune_on_mesh(layout, tiles, base):
    """Drop the tiles none of whose probes lies on the base mesh's UV layout.

    Returns:
        ``(kept_layout, pruned_count)``; independent of any map resolution.
    """
    inst, u, v = probe_layout(layout, tiles)
    valid, _, _, _ = base.locate(mi.Float(u.astype(np.float32)), mi.Float(v.astype(np.float32)))
    hits = np.bincount(inst, weights=np.asarray(valid).astype(np.float64), minlength=layout.count)
    keep = hits > 0
    return layout.subset(keep), int((~keep).sum())
