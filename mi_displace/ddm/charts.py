"""Tiles over a polygonal base's UV charts (HDDM §4.1, extended).

The paper fills the invalid texels of one pair of maps by diffusion and accepts that
"where two propagating fronts collide, the maps could be discontinuous, and tiles might be
arbitrarily stretched" — and the four texels of a lookup can belong to two charts that lie
side by side in the layout but far apart on the surface.  We keep every tile in one chart:

* :func:`assign_charts` — each placed tile is probed at up to :data:`MAX_PROBES` points of
  its own footprint (the distinct (x, y) of its vertices and its centre), located exactly
  on the mesh's UV layout.  A tile whose probes all miss is pruned; otherwise it belongs to
  the chart most of its probes hit.  Tiles whose probes hit two or more charts *straddle a
  chart border*; ``chart_border="drop"`` drops them, ``"clamp"`` (default) keeps them.
  All of this is decided on the exact mesh, so it does not depend on ``map_resolution``
  and both modes place the same tiles.
* :class:`ChartGrid` — per chart, a window of the global r x r texel grid (the chart's
  UV bounding box grown by the tiles' reach).
* :class:`ChartMaps` — the geometry images (P, N) on those windows: a texel holds its
  chart's S and n, clamped to the chart's nearest location where the texel centre lies
  off the chart (the chart's own extrapolation); a tile's lookup reads its own chart's
  window, so the bilinear interpolation never mixes two charts.  The exact mode clamps
  the same way, per vertex (:meth:`~mi_displace.ddm.mesh_base.MeshBase.sample_chart`).
"""
from __future__ import annotations

import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.ddm.base_maps import bilinear

#: probes per tile kind (distinct vertex (x, y), evenly subsampled, plus the centre)
MAX_PROBES = 64
CHART_BORDERS = ("clamp", "drop")


def uv_charts(positions: np.ndarray, uvs: np.ndarray, faces: np.ndarray):
    """UV charts: connected pieces of the layout, vertices welded where position *and* uv
    agree (per-corner normals split a mesh's vertices without cutting its layout).

    Returns:
        ``(face_chart (F,) int64, chart_count, welded_faces (F, 3) int64)``.
    """
    import scipy.sparse as sparse
    from scipy.sparse.csgraph import connected_components

    key = np.concatenate([np.asarray(positions, np.float32), np.asarray(uvs, np.float32)], 1)
    _, weld = np.unique(key, axis=0, return_inverse=True)
    f = weld.ravel()[np.asarray(faces, np.int64)]
    n = int(f.max()) + 1
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    graph = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    # renumber by first appearance over the faces (stable, independent of scipy's order)
    labels, first, inverse = np.unique(label[f[:, 0]], return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))
    return rank[inverse.ravel()].astype(np.int64), int(count), f


def chart_boundaries(welded_faces: np.ndarray, face_chart: np.ndarray, chart_count: int):
    """Boundary edges of the UV layout (edges of one face only), grouped by chart.

    Returns:
        ``(face, corner0, corner1, first)``: per edge its face and the face's two corner
        slots (0..2); ``first`` (C + 1,) the range of each chart's edges.
    """
    f = welded_faces
    corners = np.array([[0, 1], [1, 2], [2, 0]])
    face = np.repeat(np.arange(len(f)), 3)
    c0, c1 = np.tile(corners[:, 0], len(f)), np.tile(corners[:, 1], len(f))
    a, b = f[face, c0], f[face, c1]
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], 1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    edge = counts[inverse.ravel()] == 1
    face, c0, c1 = face[edge], c0[edge], c1[edge]
    order = np.argsort(face_chart[face], kind="stable")
    face, c0, c1 = face[order], c0[order], c1[order]
    first = np.searchsorted(face_chart[face], np.arange(chart_count + 1))
    return face, c0, c1, first


def probe_points(tile) -> np.ndarray:
    """(P, 2) canonical (x, y) probes of a tile: distinct vertex footprints + bbox centre."""
    xy = np.unique(np.round(tile.positions[:, :2].astype(np.float64), 5), axis=0)
    if len(xy) > MAX_PROBES - 1:
        xy = xy[np.linspace(0, len(xy) - 1, MAX_PROBES - 1).round().astype(np.int64)]
    centre = 0.5 * (tile.positions[:, :2].min(0) + tile.positions[:, :2].max(0))
    return np.concatenate([xy, centre[None].astype(np.float64)])


def probe_layout(layout, tiles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every probe of every placed tile: ``(instance, u, v)``, (N,) arrays (NumPy)."""
    su, sv = layout.size
    inst, us, vs = [], [], []
    for k, tile in enumerate(tiles):
        where = np.flatnonzero(layout.tile_index == k)
        if not len(where):
            continue
        pts = probe_points(tile)
        off = layout.offsets[where]
        inst.append(np.repeat(where, len(pts)))
        us.append((off[:, None, 0] + su * pts[None, :, 0]).ravel())
        vs.append((off[:, None, 1] + sv * pts[None, :, 1]).ravel())
    return np.concatenate(inst), np.concatenate(us), np.concatenate(vs)


def assign_charts(layout, tiles, base, border: str = "clamp"):
    """Prune, assign a chart to and (``border="drop"``) drop straddling tiles, on the mesh.

    Returns:
        ``(kept_layout with .chart, stats)``; stats: ``tiles_pruned`` (no probe on the
        layout), ``tiles_straddling`` (probes on two or more charts, among those placed
        or dropped), ``tiles_dropped`` (straddling tiles removed by ``drop``).
    """
    if border not in CHART_BORDERS:
        raise ValueError(f"ddm: unknown 'chart_border' {border!r}; expected clamp or drop")
    inst, u, v = probe_layout(layout, tiles)
    valid, prim, _, _ = base.locate(mi.Float(u.astype(np.float32)), mi.Float(v.astype(np.float32)))
    ok = np.asarray(valid)
    c = base.chart_count
    chart = base.face_chart[np.asarray(prim)[ok]]
    counts = np.bincount(inst[ok] * c + chart, minlength=layout.count * c).reshape(layout.count, c)
    on = counts.sum(1) > 0
    straddle = on & ((counts > 0).sum(1) > 1)
    keep = on & ~straddle if border == "drop" else on
    kept = layout.subset(keep)
    kept.chart = counts.argmax(1)[keep]
    return kept, {"tiles_pruned": int((~on).sum()), "tiles_straddling": int(straddle.sum()),
                  "tiles_dropped": int((straddle & ~keep).sum()), "charts": c}


def tile_reach(tiles, size) -> float:
    """How far (uv units) a tile's vertices reach from its cell: the margin every chart
    window needs around the chart's bounding box."""
    lo = np.min([t.positions[:, :2].min(0) for t in tiles], 0)
    hi = np.max([t.positions[:, :2].max(0) for t in tiles], 0)
    span = np.maximum(hi, 1.0) - np.minimum(lo, 0.0)
    return float(max(size[0] * span[0], size[1] * span[1]))


class ChartGrid:
    """Per-chart windows of the uniform r x r texel grid (texel i at u = i / (r - 1)):
    each chart's UV bounding box grown by ``margin`` (uv units), at least 2 x 2 texels.

    Attributes:
        r: texels per side of the global grid.
        lo_u, lo_v, width, height, offset: (C,) int64 window of each chart (global texel
            index of its first column / row, size, first stored texel).
        chart_of, u, v: (T,) per stored texel: its chart and its (u, v).
    """

    def __init__(self, base, r: int, margin: float):
        if r < 2:
            raise ValueError(f"ddm: per-chart maps need at least 2 texels per side, got {r}")
        self.r = int(r)
        h = r - 1
        b = base.chart_bounds
        lo = np.clip(np.floor((b[:, :2] - margin) * h), 0, h).astype(np.int64)
        hi = np.clip(np.ceil((b[:, 2:] + margin) * h), 0, h).astype(np.int64)
        size = np.maximum(hi - lo + 1, 2)
        lo = np.minimum(lo, r - size)
        self.lo_u, self.lo_v = lo[:, 0], lo[:, 1]
        self.width, self.height = size[:, 0], size[:, 1]
        count = self.width * self.height
        self.offset = np.concatenate([[0], np.cumsum(count)[:-1]])
        self.chart_of = np.repeat(np.arange(len(count)), count)
        local = np.arange(count.sum()) - self.offset[self.chart_of]
        w = self.width[self.chart_of]
        self.u = (self.lo_u[self.chart_of] + local % w) / h
        self.v = (self.lo_v[self.chart_of] + local // w) / h
        self._table = [mi.Int32(a.astype(np.int32)) for a in
                       (self.lo_u, self.lo_v, self.width, self.height, self.offset)]

    @property
    def texels(self) -> int:
        return len(self.u)

    def _coordinate(self, x, lo, n):
        """Position in texels inside the window along one axis, clamped to it."""
        return dr.clip(dr.clip(x, 0.0, 1.0) * (self.r - 1) - mi.Float(lo), 0.0, mi.Float(n - 1))

    def bilinear_indices(self, u, v, chart):
        """Stored indices of the four texels around each (u, v) in its chart's window and
        the bilinear fractions: ``((k00, k10, k01, k11), wu, wv)``."""
        lo_u, lo_v, w, h, off = (dr.gather(mi.Int32, a, chart) for a in self._table)
        su, sv = self._coordinate(u, lo_u, w), self._coordinate(v, lo_v, h)
        i0 = dr.minimum(mi.Int32(dr.floor(su)), w - 2)
        j0 = dr.minimum(mi.Int32(dr.floor(sv)), h - 2)
        k = off + j0 * w + i0
        idx = tuple(mi.UInt32(x) for x in (k, k + 1, k + w, k + w + 1))
        return idx, su - mi.Float(i0), sv - mi.Float(j0)


class ChartMaps:
    """Geometry images (P, N) on the chart windows of a :class:`ChartGrid` (eq. 2 with the
    §3.2 lookup inside the tile's own chart).  A texel holds S and n of its chart at the
    texel centre, clamped to the chart's nearest location where the centre lies off it
    (:meth:`~mi_displace.ddm.mesh_base.MeshBase.sample_chart`: the §4.1 fill, exact and per
    chart).  Duck-types the parts of :class:`~mi_displace.ddm.base_maps.GeometryImage`
    the model uses."""

    periodic_u = periodic_v = False

    def __init__(self, base, r: int, margin: float):
        start = time.perf_counter()
        self.grid = g = ChartGrid(base, r, margin)
        self.ru = self.rv = g.r
        u, v = (mi.Float(x.astype(np.float32)) for x in (g.u, g.v))
        chart = mi.UInt32(g.chart_of.astype(np.uint32))
        valid, _, _, _ = base.locate(u, v, chart)
        s = base.sample_chart(u, v, chart)
        self.position, self.normal = mi.Vector3f(s.p), mi.Vector3f(s.n)
        dr.eval(self.position, self.normal)
        self.valid = np.asarray(valid)
        self.stats = {"map_build_s": time.perf_counter() - start, "map_texels": g.texels,
                      "clamped_texels": int((~self.valid).sum()), "charts": len(g.offset)}

    @property
    def nbytes(self) -> int:
        """Bytes stored: two RGB float32 maps + a validity byte per window texel, and the
        five int32 window entries per chart."""
        return self.grid.texels * (2 * 3 * 4 + 1) + len(self.grid.offset) * 5 * 4

    def lookup(self, u, v, derivatives: bool = False, chart=None):
        """Bilinear P, N (and derivatives per unit uv) in each point's chart (mi.UInt32)."""
        if chart is None:
            raise ValueError("ddm: per-chart maps need the chart of every lookup")
        idx, wu, wv = self.grid.bilinear_indices(mi.Float(u), mi.Float(v), chart)
        s = float(self.grid.r - 1)
        return bilinear(self.position, self.normal, idx, wu, wv, s, s, derivatives)


def map_error(base, maps: ChartMaps, w_max: float, samples: int = 1 << 16, seed: int = 0) -> float:
    """:func:`mi_displace.ddm.base_maps.map_error` for per-chart maps: the largest error of
    T = P + N w against S + n w (object units, w in {0, w_max}) at ``samples`` seeded random
    cell centres of the chart windows and ``samples`` seeded random (u, v), each looked up in the chart
    that covers it; points whose four lookup texels are not all on that chart (clamped
    lookups, bounded separately in docs/ddm.md) are skipped."""
    g = maps.grid
    h = 0.5 / (g.r - 1)
    rng = np.random.default_rng(seed)
    cells = rng.choice(g.texels, min(samples, g.texels), replace=False)   # cell centres
    u = np.concatenate([g.u[cells] + h, rng.random(samples)]).astype(np.float32)
    v = np.concatenate([g.v[cells] + h, rng.random(samples)]).astype(np.float32)
    uu, vv = mi.Float(u), mi.Float(v)
    hit, prim, _, _ = base.locate(uu, vv)
    chart = mi.UInt32(base.face_chart[np.asarray(prim)].astype(np.uint32))
    idx, _, _ = g.bilinear_indices(uu, vv, chart)
    valid = mi.Bool(np.ascontiguousarray(maps.valid))
    keep = hit
    for k in idx:
        keep &= dr.gather(mi.Bool, valid, k)
    keep = np.asarray(keep)
    uu, vv = mi.Float(u[keep]), mi.Float(v[keep])
    chart = mi.UInt32(base.face_chart[np.asarray(prim)[keep]].astype(np.uint32))
    s = base.sample_chart(uu, vv, chart)
    p, n = maps.lookup(uu, vv, False, chart)
    d0 = dr.norm(p - s.p)
    d1 = dr.norm(p + n * w_max - (s.p + s.n * w_max))
    return float(dr.max(dr.maximum(d0, d1))[0])
