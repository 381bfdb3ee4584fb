"""Rasterisation of the low-poly in UV space (§3.2 step 2a: the projection that maps each
low-poly triangle onto its s,t texture area), done by Mitsuba's ray tracer.

The low-poly is laid flat in its UV layout as a second ``mi.Mesh``: triangle i becomes the
triangle (u, v, z_i) with its own three vertices and z_i = (i + 1) / (F + 1) (stacked
layers).  A ray along -z through a texel's sample point returns the covering triangle and its
barycentrics, vectorised, for any triangle count.  Because every triangle has its own height,
the ray from above hits the *highest-index* triangle and a ray from below the *lowest*: where
they differ, two UV triangles overlap (the texture mapping is not "strictly unambiguous",
§3.1) — counted by :func:`overlap_texels`.

Sample points: the texel centre, or an N x N regular grid of sub-samples (anti-aliasing, §4).
Conservative coverage: every uncovered texel next to a covered one (8-neighbourhood) also
tries its four corners (inset by 1e-3 texel); a hit there assigns that triangle, evaluated at
the texel centre's barycentrics clamped onto the triangle.  So triangle borders and thin
triangles that miss every centre still get their texels; triangles that cover no texel at all
are counted (``triangles_without_texels``).

Texel (col c, row r) of a W x H map has its centre at u = (c + 0.5) / W, v = 1 - (r + 0.5) / H
(row 0 at the top, v up; :mod:`mi_displace.bake.meshdata`).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.meshdata import MeshData

CORNER_INSET = 1e-3  # texels: corner probes stay inside their own texel


class UVLayout:
    """The low-poly's UV layout as a flat, stacked ``mi.Mesh`` inside its own ``mi.Scene``."""

    def __init__(self, low: MeshData):
        if low.uvs is None:
            raise ValueError("low-poly: UV rasterisation needs texture coordinates (unwrap first)")
        F = len(low.faces)
        uv = low.uvs[low.faces].astype(np.float32)                          # (F, 3, 2)
        z = np.broadcast_to(((np.arange(F) + 1.0) / (F + 1.0))[:, None, None], (F, 3, 1))
        verts = np.concatenate([uv, z.astype(np.float32)], axis=2).reshape(-1, 3)
        mesh = mi.Mesh("uv_layout", 3 * F, F, has_vertex_normals=False, has_vertex_texcoords=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(np.ascontiguousarray(verts.ravel()))
        params["faces"] = mi.UInt32(np.arange(3 * F, dtype=np.uint32))
        params.update()
        self.scene = mi.load_dict({"type": "scene", "layout": mesh})
        self.uv = [mi.Point2f(mi.Float(uv[:, k, 0].copy()), mi.Float(uv[:, k, 1].copy()))
                   for k in range(3)]
        self.face_count = F


@dataclass
class Samples:
    """Covered sample points of one block of texel rows (Dr.Jit arrays, n samples).

    Attributes:
        texel: mi.UInt32 (n,) texel index inside the block (row-major, row - row0).
        prim: mi.UInt32 (n,) low-poly triangle.
        b1, b2: mi.Float (n,) barycentrics of vertices 1 and 2 (b0 = 1 - b1 - b2).
        sub: mi.UInt32 (n,) sub-sample of the texel's aa x aa grid (aa * aa for a corner
            probe's sample): with the global texel index a key unique in the whole map.
        conservative: number of samples added by the corner probes.
    """

    texel: mi.UInt32
    prim: mi.UInt32
    b1: mi.Float
    b2: mi.Float
    sub: mi.UInt32
    conservative: int


def _cast(layout: UVLayout, u: mi.Float, v: mi.Float, up: bool = False):
    """Preliminary intersection of vertical rays through (u, v) with the layout."""
    o = mi.Point3f(u, v, -1.0 if up else 2.0)
    ray = mi.Ray3f(o, mi.Vector3f(0.0, 0.0, 1.0 if up else -1.0), 4.0, 0.0, [])
    pi = layout.scene.ray_intersect_preliminary(ray, coherent=True)
    # one kernel for every field: evaluated separately, each would trace the rays again
    dr.eval(pi.t, pi.prim_index, pi.prim_uv, pi.valid)
    return pi


def rasterize_rows(layout: UVLayout, width: int, height: int, row0: int, rows: int,
                   aa: int = 1, conservative: bool = True) -> Samples:
    """Samples of texel rows [row0, row0 + rows) of a width x height map, aa x aa per texel.

    The sizes enter the kernels as opaque values, not literals: one set of kernels serves
    every block, resolution and aa (a first bake compiles them once, later ones reuse them).
    """
    n_tex = rows * width
    n_samples = n_tex * aa * aa
    W, H = dr.opaque(mi.UInt32, width), dr.opaque(mi.Float, height)
    A, R0, ROWS = dr.opaque(mi.UInt32, aa), dr.opaque(mi.UInt32, row0), dr.opaque(mi.Int32, rows)
    Wf, Af = mi.Float(W), mi.Float(A)
    idx = dr.arange(mi.UInt32, n_samples)
    texel, sub = idx // (A * A), idx % (A * A)
    col, row = texel % W, texel // W + R0
    u = (mi.Float(col) + (mi.Float(sub % A) + 0.5) / Af) / Wf
    v = 1.0 - (mi.Float(row) + (mi.Float(sub // A) + 0.5) / Af) / H
    pi = _cast(layout, u, v)
    hit = dr.compress(pi.is_valid())
    # = texel[hit] (a gather from the counter would bake its size into the kernel)
    texel_h = hit // (A * A) if dr.width(hit) else dr.zeros(mi.UInt32, 0)
    sub_h = hit % (A * A) if dr.width(hit) else dr.zeros(mi.UInt32, 0)
    prim = dr.gather(mi.UInt32, pi.prim_index, hit)
    b1 = dr.gather(mi.Float, pi.prim_uv.x, hit)
    b2 = dr.gather(mi.Float, pi.prim_uv.y, hit)
    added = 0
    if conservative:
        covered = dr.zeros(mi.UInt32, n_tex)
        if dr.width(texel_h):
            dr.scatter(covered, 1, texel_h)
        t = dr.arange(mi.UInt32, n_tex)
        Wi = mi.Int32(W)
        c, r = mi.Int32(t % W), mi.Int32(t // W)
        near = mi.Bool(False)
        for dc in (-1, 0, 1):
            for dv in (-1, 0, 1):
                cc, rr = c + dc, r + dv
                ok = (cc >= 0) & (cc < Wi) & (rr >= 0) & (rr < ROWS) & ((dc != 0) | (dv != 0))
                near |= ok & (dr.gather(mi.UInt32, covered, mi.UInt32(rr * Wi + cc), ok) > 0)
        band = dr.compress(near & (covered == 0))
        if dr.width(band):
            bc = mi.Float(band % W)     # band indexes the counter t directly
            br = mi.Float(band // W + R0)
            found = dr.zeros(mi.Bool, dr.width(band))
            tri = dr.zeros(mi.UInt32, dr.width(band))
            for fx, fy in ((0, 0), (1, 0), (0, 1), (1, 1)):  # the four corners
                ox = CORNER_INSET + fx * (1 - 2 * CORNER_INSET)
                oy = CORNER_INSET + fy * (1 - 2 * CORNER_INSET)
                pc = _cast(layout, (bc + ox) / Wf, 1.0 - (br + oy) / H)
                take = pc.is_valid() & ~found
                tri = dr.select(take, pc.prim_index, tri)
                found |= take
            keep = dr.compress(found)
            added = dr.width(keep)
        if added:  # band texels whose corner probes found a triangle
            tri = dr.gather(mi.UInt32, tri, keep)
            centre = mi.Point2f((dr.gather(mi.Float, bc, keep) + 0.5) / Wf,
                                1.0 - (dr.gather(mi.Float, br, keep) + 0.5) / H)
            cb1, cb2 = _clamped_barycentrics(layout, tri, centre)
            texel_h = _append(texel_h, dr.gather(mi.UInt32, band, keep))
            sub_h = _append(sub_h, dr.full(mi.UInt32, 1, added) * (A * A))
            prim = _append(prim, tri)
            b1, b2 = _append(b1, cb1), _append(b2, cb2)
    return Samples(texel_h, prim, b1, b2, sub_h, int(added))


def _append(a, b):
    """a followed by b (dr.concat would bake len(a) into the kernel as a literal)."""
    out = dr.empty(type(a), dr.width(a) + dr.width(b))
    dr.scatter(out, a, dr.arange(mi.UInt32, dr.width(a)))
    dr.scatter(out, b, dr.arange(mi.UInt32, dr.width(b)) + dr.opaque(mi.UInt32, dr.width(a)))
    return out


def _clamped_barycentrics(layout: UVLayout, tri: mi.UInt32, p: mi.Point2f):
    """Barycentrics (b1, b2) of UV point p in triangle ``tri``, clamped onto the triangle."""
    a, b, c = (mi.Point2f(dr.gather(mi.Float, layout.uv[k].x, tri),
                          dr.gather(mi.Float, layout.uv[k].y, tri)) for k in range(3))
    e1, e2, d = b - a, c - a, p - a
    det = e1.x * e2.y - e1.y * e2.x
    inv = dr.select(dr.abs(det) > 0, dr.rcp(det), 0.0)
    w1 = (d.x * e2.y - d.y * e2.x) * inv
    w2 = (e1.x * d.y - e1.y * d.x) * inv
    w0 = dr.maximum(1.0 - w1 - w2, 0.0)
    w1, w2 = dr.maximum(w1, 0.0), dr.maximum(w2, 0.0)
    total = w0 + w1 + w2
    ok = total > 0
    return dr.select(ok, w1 / total, 1.0 / 3.0), dr.select(ok, w2 / total, 1.0 / 3.0)


OVERLAP_RESOLUTION = 256
OVERLAP_EPSILON = 1e-4  # barycentric margin: points on shared edges are not overlaps


def overlap_texels(layout: UVLayout, res: int) -> int:
    """Texel centres of a res x res grid covered by two or more UV triangles.

    The ray from above hits the highest stacked triangle, the ray from below the lowest; a
    difference means overlap.  It is a property of the layout, measured once per bake at
    ``min(res, OVERLAP_RESOLUTION)`` (so it costs 2 x 256^2 rays at most).
    """
    idx = dr.arange(mi.UInt32, res * res)
    u = (mi.Float(idx % res) + 0.5) / res
    v = 1.0 - (mi.Float(idx // res) + 0.5) / res
    top, bottom = _cast(layout, u, v), _cast(layout, u, v, up=True)

    def inside(pi):  # strictly inside (not on an edge shared by neighbouring triangles)
        b1, b2 = pi.prim_uv.x, pi.prim_uv.y
        return dr.minimum(dr.minimum(b1, b2), 1.0 - b1 - b2) > OVERLAP_EPSILON

    both = (top.is_valid() & bottom.is_valid() & (top.prim_index != bottom.prim_index)
            & inside(top) & inside(bottom))
    return int(dr.count(both)[0] if hasattr(dr.count(both), "__len__") else dr.count(both))
