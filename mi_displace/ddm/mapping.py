"""The DDM / HDDM mapping of tile vertices (eq. 1-2, §3.2) in Dr.Jit.

Every vertex V = (x, y, z) of every placed tile maps to

    (u, v) = (u0, v0) + (su, sv) * (A (x, y) + b)        (layout offset, texture transform)
    w      = height_t * z + w_offset
    T(V)   = S(u, v) + n(u, v) w                          (eq. 1, mode ``exact``: DDM)
    T(V)   = P(u, v) + N(u, v) w                          (eq. 2, mode ``maps``: HDDM, the
                                                           bilinear geometry-image lookup)

One kernel maps all tiles: output vertex i belongs to tile instance i // V_k of its tile
group k (tiles of one kind are contiguous) and is vertex i mod V_k of that tile.  Normals:
:mod:`mi_displace.ddm.normals`.  Faces are built once (:func:`instance_faces`).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.tessellate import MAX_VERTICES, gather
from mi_displace.ddm import normals as nrm
from mi_displace.ddm.tiles import Tile

MODES = ("exact", "maps")
MODE_ALIASES = {"reference": "exact", "approximation": "maps"}


def _vec(a: np.ndarray) -> mi.Vector3f:
    return mi.Vector3f(*(mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)))


@dataclass
class TileBuffers:
    """Dr.Jit copies of the tile set, concatenated (group k at ``vertex_offset[k]``)."""

    positions: mi.Vector3f
    normals: mi.Vector3f
    t1: mi.Vector3f
    t2: mi.Vector3f
    vertex_offset: list
    vertex_count: list

    @staticmethod
    def from_tiles(tiles: list[Tile]) -> "TileBuffers":
        return TileBuffers(
            positions=_vec(np.concatenate([t.positions for t in tiles])),
            normals=_vec(np.concatenate([t.normals for t in tiles])),
            t1=_vec(np.concatenate([t.tangents[:, 0] for t in tiles])),
            t2=_vec(np.concatenate([t.tangents[:, 1] for t in tiles])),
            vertex_offset=list(np.cumsum([0] + [t.vertex_count for t in tiles[:-1]])),
            vertex_count=[t.vertex_count for t in tiles])


class ExactEvaluator:
    """S, n and derivatives straight from the base (DDM, eq. 1).  On a mesh base with UV
    charts each point stays in the chart its tile belongs to (``chart``, mi.UInt32 per
    point)."""

    def __init__(self, base):
        self.base = base

    def __call__(self, u, v, derivatives: bool, chart=None):
        s = self.base.sample(u, v) if chart is None else self.base.sample_chart(u, v, chart)
        if not derivatives:
            return mi.Vector3f(s.p), s.n
        return mi.Vector3f(s.p), s.n, (s.dp_du, s.dp_dv, s.dn_du, s.dn_dv)


class MapsEvaluator:
    """P, N and derivatives from the geometry image (HDDM, eq. 2, §3.2 lookup); per-chart
    maps (:class:`~mi_displace.ddm.charts.ChartMaps`) read the tile's own chart."""

    def __init__(self, maps):
        self.maps = maps

    def __call__(self, u, v, derivatives: bool, chart=None):
        if chart is None:
            return self.maps.lookup(u, v, derivatives)
        return self.maps.lookup(u, v, derivatives, chart)


@dataclass
class Placement:
    """Where the tiles go: per-instance offsets (sorted by tile group) and group table.

    Attributes:
        offsets: mi.Point2f (I,) (u0, v0) per instance, group by group.
        groups: list of (first_instance, instance_count, tile_group) per non-empty group.
        size: (su, sv).
    """

    offsets: mi.Point2f
    groups: list
    size: tuple
    chart: mi.UInt32 | None = None

    @staticmethod
    def from_layout(layout, n_tiles: int) -> "Placement":
        order = np.argsort(layout.tile_index, kind="stable")
        idx = layout.tile_index[order]
        off = layout.offsets[order]
        groups, first = [], 0
        for k in range(n_tiles):
            count = int(np.sum(idx == k))
            if count:
                groups.append((first, count, k))
            first += count
        chart = None if layout.chart is None else mi.UInt32(layout.chart[order].astype(np.uint32))
        return Placement(mi.Point2f(mi.Float(off[:, 0].astype(np.float32)),
                                    mi.Float(off[:, 1].astype(np.float32))),
                         groups, tuple(float(s) for s in layout.size), chart)

    def instance_chart(self, inst: mi.UInt32):
        """The UV chart of each point's tile instance (mi.UInt32), None without charts."""
        return None if self.chart is None else dr.gather(mi.UInt32, self.chart, inst)

    def vertex_total(self, buffers: TileBuffers) -> int:
        return sum(c * buffers.vertex_count[k] for _, c, k in self.groups)


def orientation(exact: ExactEvaluator, placement: "Placement") -> mi.Float:
    """Per placed tile: +1 where the base's parametrisation keeps the tile's orientation, -1
    where it mirrors it — the sign of (S_u x S_v) . n at the tile's centre (on the exact
    base, in the tile's own chart).  Analytic bases give one sign; a mesh base's UV charts
    may be mirrored one by one.

    Returns:
        mi.Float (I,), one sign per instance (placement order).
    """
    su, sv = placement.size
    _, n, (s_u, s_v, _, _) = exact(placement.offsets.x + 0.5 * su, placement.offsets.y + 0.5 * sv,
                                   True, placement.chart)
    det = dr.dot(dr.cross(s_u, s_v), n)
    sign = dr.select(det >= 0, 1.0, -1.0)
    dr.eval(sign)
    return sign


def check_size(vertices: int, faces: int, what: str = "tiles_u x tiles_v") -> int:
    """Bytes of the explicit mapped mesh; ValueError *before allocating* if it cannot fit
    (index range or half the machine's physical memory)."""
    nbytes = vertices * (3 + 3 + 2) * 4 + faces * 3 * 4
    try:
        import os

        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        physical = 16 << 30
    if vertices > MAX_VERTICES or 3 * faces > 2**32 - 1 or 3 * nbytes > physical // 2:
        raise ValueError(
            f"ddm: {what} gives {vertices:,} vertices and {faces:,} triangles "
            f"({nbytes / 2**30:.1f} GiB for the mapped mesh, ~3x that while building), "
            f"more than fits (limit {MAX_VERTICES:,} vertices, half of "
            f"{physical / 2**30:.0f} GiB memory); use fewer tiles or a smaller tile")
    return nbytes


def instance_faces(placement: Placement, buffers: TileBuffers, tile_faces: list,
                   flip: mi.Bool | None = None) -> mi.Vector3u:
    """Triangles of all placed tiles: tile faces offset by each instance's first vertex
    (winding reversed where ``flip``, mi.Bool (I,) per instance: orientation-reversing
    mappings)."""
    vbase = 0
    face_sets = [mi.Vector3u(*(mi.UInt32(np.ascontiguousarray(f[:, k])) for k in range(3)))
                 for f in tile_faces]
    out = []
    for first, count, k in placement.groups:
        nf, nv = len(tile_faces[k]), buffers.vertex_count[k]
        j = dr.arange(mi.UInt32, count * nf)
        inst, local = j // nf, j % nf
        shift = vbase + inst * nv
        c0, c1, c2 = (dr.gather(mi.UInt32, face_sets[k][c], local) + shift for c in range(3))
        if flip is not None:
            f = dr.gather(mi.Bool, flip, first + inst)
            c1, c2 = dr.select(f, c2, c1), dr.select(f, c1, c2)
        out.append(mi.Vector3u(c0, c1, c2))
        vbase += count * nv
    if len(out) == 1:
        return out[0]
    return mi.Vector3u(*(dr.concat([o[c] for o in out]) for c in range(3)))


def instance_vertex(placement: Placement, buffers: TileBuffers):
    """Per output vertex: (instance index, tile vertex index), one Dr.Jit expression."""
    total = placement.vertex_total(buffers)
    i = dr.arange(mi.UInt32, total)
    if len(placement.groups) == 1:
        first, _, k = placement.groups[0]
        nv = int(buffers.vertex_count[k])       # a literal: division by a constant
        return first + i // nv, int(buffers.vertex_offset[k]) + i % nv
    starts, vstart = [], 0
    for first, count, k in placement.groups:
        starts.append((vstart, first, buffers.vertex_count[k], buffers.vertex_offset[k]))
        vstart += count * buffers.vertex_count[k]
    v0, f0, nv, off = (mi.UInt32(starts[0][c]) for c in range(4))
    for s in starts[1:]:
        here = i >= s[0]
        v0, f0 = dr.select(here, s[0], v0), dr.select(here, s[1], f0)
        nv, off = dr.select(here, s[2], nv), dr.select(here, s[3], off)
    local = i - v0
    return f0 + local // nv, off + local % nv


def map_tiles(evaluator, placement: Placement, buffers: TileBuffers, affine, height: float,
              w_offset: float, method: str = "tangent", eps: float = 1e-3,
              tile_override=None, orientation: mi.Float | None = None):
    """Map every placed tile vertex and its normal.

    Args:
        evaluator: :class:`ExactEvaluator` or :class:`MapsEvaluator`.
        placement: instance offsets and groups; buffers: the tile set.
        affine: ((a00, a01), (a10, a11)), (b0, b1) texture-space transform (Python floats).
        height: object units per unit of tile z (the w scale); w_offset: gap in w [object units].
        method: ``tangent`` | ``jacobian`` | ``naive`` (:mod:`mi_displace.ddm.normals`).
        eps: offset ε of the tangent / naive points [tile units].
        tile_override: optional (positions, normals, t1, t2) replacing the buffers' arrays
            (a metamorphosed tile, eq. 3).
        orientation: mi.Float (I,), per instance -1 where T reverses orientation (a base
            chart with S_u x S_v against n, times the sign of the w scale): mapped faces are
            then wound the other way (:func:`instance_faces` with ``flip``) and the cofactor
            / tangent normals negated.  None: +1 everywhere.

    Returns:
        ``(positions, normals, uv)``: mi.Point3f, unit mi.Vector3f, mi.Point2f per vertex.
    """
    if method not in nrm.METHODS:
        raise ValueError(f"ddm: unknown 'normals' {method!r}; expected one of {', '.join(nrm.METHODS)}")
    inst, k = instance_vertex(placement, buffers)
    chart = placement.instance_chart(inst)
    tp, tn, t1, t2 = tile_override or (buffers.positions, buffers.normals, buffers.t1, buffers.t2)
    vp = gather(mi.Vector3f, tp, k)
    vn = gather(mi.Vector3f, tn, k)
    offset = gather(mi.Point2f, placement.offsets, inst)
    sign = 1.0 if orientation is None else dr.gather(mi.Float, orientation, inst)
    # per-frame scalars as opaque variables: one compiled kernel serves every frame (a
    # Dr.Jit Float with a gradient is kept as it is: differentiable in time / height)
    def scalar(x):
        return x if dr.is_array_v(x) else dr.opaque(mi.Float, x)

    (a00, a01), (a10, a11) = (tuple(scalar(x) for x in row) for row in affine[0])
    b0, b1 = (scalar(x) for x in affine[1])
    height, w_offset = scalar(height), scalar(w_offset)
    su, sv = placement.size

    def place(p):
        """Tile point -> (u, v, w)."""
        u = offset.x + su * (a00 * p.x + a01 * p.y + b0)
        v = offset.y + sv * (a10 * p.x + a11 * p.y + b1)
        return u, v, height * p.z + w_offset

    def T(p):
        u, v, w = place(p)
        s, n = evaluator(u, v, False, chart)
        return s + n * w

    u, v, w = place(vp)
    if method == "jacobian":
        s, n, (s_u, s_v, n_u, n_v) = evaluator(u, v, True, chart)
        pos = s + n * w
        t_u, t_v = s_u + n_u * w, s_v + n_v * w       # dT/du, dT/dv; dT/dw = n
        a_x = (su * a00) * t_u + (sv * a10) * t_v
        a_y = (su * a01) * t_u + (sv * a11) * t_v
        normal = sign * nrm.cofactor_normal(a_x, a_y, height * n, vn)
    else:
        s, n = evaluator(u, v, False, chart)
        pos = s + n * w
        if method == "tangent":   # §3.2: map the two precomputed tangent points
            normal = sign * dr.cross(T(vp + eps * gather(mi.Vector3f, t1, k)) - pos,
                                     T(vp + eps * gather(mi.Vector3f, t2, k)) - pos)
        else:
            normal = T(vp + eps * vn) - pos
    return mi.Point3f(pos), nrm.finish(normal, dr.normalize(n)), mi.Point2f(u, v)
