"""Z-buffer visibility in Dr.Jit: triangles rasterised at sample positions, no ray tracing.

The pipeline of a GPU, written as data-parallel array code (issue 18):

1. **Geometry** (:func:`gather_geometry`): the triangles of every mesh concatenated
   (world-space vertices, global vertex indices, the shape of each triangle).
2. **View** (:class:`View`): an affine world -> view-local transform and a sample grid.
   Perspective views cast a ray from the local origin along ``D = (qx, qy, 1)``,
   orthographic views from ``(qx, qy, 0)`` along ``+z``; ``q`` is affine in the grid
   coordinate.  :func:`view_from_sensor` fits it to a Mitsuba sensor's own ``sample_ray``
   (perspective and orthographic, any fov and film crop), so the samples are exactly
   the rays of :func:`mi_displace.render.raster.pixel_rays`.
3. **Binning** (:func:`rasterise`): each triangle's screen bounding box — clipped at the
   near plane, where the polygon's crossing points replace the vertices behind it — gives
   its candidate samples.  Candidates of all triangles are enumerated in one flat range
   (an exclusive prefix sum over the per-triangle counts; each candidate finds its triangle
   by a segmented prefix sum), so a micro-triangle costs one thread and a screen-covering
   triangle spreads over as many threads as it has samples.  The range is processed in
   chunks of :data:`CHUNK` candidates (a Python loop over work batches, not triangles);
   large triangles are enumerated by box rows instead (pieces of :data:`SPAN` samples),
   one thread per piece looping over its part of the row's span (:func:`_row_span`), so
   the samples of the box outside the triangle cost nothing; slivers (:data:`TALL`) by
   one thread looping over the spans of all their rows.
4. **Inside test** (homogeneous rasterisation, Olano & Greer 1997): edge functions
   ``e_ab = (h_a x h_b) . (qx, qy, 1)`` with ``h = (x, y, z)`` (perspective) or
   ``(x, y, 1)`` (orthographic).  The same expression gives the perspective-correct
   barycentrics ``b_i = e_i / sum(e)``; triangles behind the camera or crossing the near
   plane need no geometric clipping: samples whose interpolated depth is outside
   [near, far] are rejected.  Edges are evaluated in a canonical vertex order, so the two
   triangles sharing an edge get bit-exactly opposite values: no sample falls through a
   crack (samples exactly on an edge go to both; the depth test decides).
5. **Depth test**: an atomic minimum (``dr.scatter_reduce(ReduceOp.Min)`` on UInt64, plain
   atomics: ``ReduceMode.Direct``) over keys ``(float32 bits of the view depth) << 32 |
   triangle id``.  The depth is the
   *linear* view-space z stored as a float32 (positive floats order like their bits):
   floating point keeps 24 bits of relative precision at every distance, like a log
   depth, with no [near, far] normalisation to lose precision far away.  Equal depths go
   to the smaller triangle id: the result does not depend on the order of the atomics.

The resolved visibility buffer (triangle id and barycentrics per sample) becomes a
``mi.PreliminaryIntersection3f`` whose ``compute_surface_interaction`` is Mitsuba's own,
so every BSDF and texture shades as under ray tracing.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.render import pixel_order

#: Candidate (triangle, sample) pairs per rasterisation batch.
CHUNK = 1 << 24
#: Triangles with more candidate samples than ``small`` and at most this many loop over
#: them in one thread; larger ones get one thread per candidate.
MEDIUM = 64
#: Samples of a box row one thread of a large triangle loops over (at most).
SPAN = 64
#: Large triangles whose box is at most SPAN samples wide and this many rows tall (slivers:
#: orthogonal slices, a shell's walls) are drawn by one thread each, looping over the spans
#: of their rows: the edge setup and the alpha test's reads once per triangle, not once per
#: row (the sliced donut's best frame at 512^2, AA=1 scripts/module_ab.py: 0.92-0.96x;
#: direction a, with few slivers, unchanged).
TALL = 64
#: Grid cells by which a row's span is widened (:func:`_row_span`).
SPAN_MARGIN = 0.5
#: Key of a sample that no fragment reached.
EMPTY = (1 << 64) - 1
#: Grid units by which a bounding box is widened before rounding (the exact inside test
#: decides; this only keeps float rounding of the box from dropping a boundary sample).
BOX_MARGIN = 1e-3
#: Bytes per sample of a full z-buffer render (keys, rays, interaction, shading), used
#: by :func:`check_memory` before anything is allocated.
BYTES_PER_SAMPLE = 400


def check_memory(samples: int, what: str, bytes_per_sample: int = BYTES_PER_SAMPLE) -> None:
    """Refuse a render whose per-sample buffers would not fit in the available memory.

    Raises:
        ValueError: naming ``what`` (e.g. the film size), the bytes needed and available.
    """
    need = samples * bytes_per_sample
    try:
        pages = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):
        return
    limit = int(os.environ.get("MI_DISPLACE_RASTER_MAX_BYTES", 0)) or pages // 2
    if need > limit:
        raise ValueError(
            f"raster: {what} needs ~{need / 2**30:.1f} GiB of per-sample buffers "
            f"({samples:,} samples x {bytes_per_sample} B), more than the "
            f"{limit / 2**30:.1f} GiB allowed (half the available memory, or "
            f"$MI_DISPLACE_RASTER_MAX_BYTES): lower the film size or 'aa'")


@dataclass
class Geometry:
    """Triangles of a list of meshes, concatenated.

    Attributes:
        positions: world-space vertices, (V,) Point3f.
        faces: global vertex indices, (F,) Vector3u.
        shape_of: index into ``shapes`` of each triangle, (F,) UInt32.
        first_face: global index of each shape's first triangle, (S,) UInt32.
        shapes: (S,) ShapePtr.
        alpha: per shape, whether its BSDF has a null (pass-through) component, (S,) Bool.
        alpha_any: whether any shape needs the alpha test.
        bbox: world bounding box of all shapes (ScalarBoundingBox3f).
    """
    positions: mi.Point3f
    faces: mi.Vector3u
    shape_of: mi.UInt32
    first_face: mi.UInt32
    shapes: mi.ShapePtr
    alpha: mi.Bool
    alpha_any: bool
    bbox: mi.ScalarBoundingBox3f


def _has_null(shape: mi.Shape) -> bool:
    bsdf = shape.bsdf()
    return bsdf is not None and mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null)


def gather_geometry(shapes) -> Geometry:
    """Concatenate the triangles of ``shapes`` (every one must be a ``mi.Mesh``).

    Raises:
        ValueError: for a shape that is not a triangle mesh (analytic sphere, rectangle...).
    """
    shapes = list(shapes)
    for shape in shapes:
        if not shape.is_mesh():
            raise ValueError(
                f"raster: visibility='zbuffer' rasterises triangle meshes only; shape "
                f"{shape.id() or shape.class_name()!r} ({shape.class_name()}) is not one "
                f"(use a mesh, e.g. Mitsuba's 'ply'/'obj', or visibility='raytrace')")
    v_counts = [s.vertex_count() for s in shapes]
    f_counts = [s.face_count() for s in shapes]
    v_off = np.concatenate([[0], np.cumsum(v_counts)]).astype(np.int64)
    f_off = np.concatenate([[0], np.cumsum(f_counts)]).astype(np.int64)
    positions = dr.zeros(mi.Float, 3 * int(v_off[-1]))
    faces = dr.zeros(mi.UInt32, 3 * int(f_off[-1]))
    bbox = mi.ScalarBoundingBox3f()
    for i, shape in enumerate(shapes):  # a handful of shapes, not elements
        if f_counts[i] == 0:
            continue
        dr.scatter(positions, shape.vertex_positions_buffer(),
                   dr.arange(mi.UInt32, 3 * v_counts[i]) + int(3 * v_off[i]))
        dr.scatter(faces, shape.faces_buffer() + int(v_off[i]),
                   dr.arange(mi.UInt32, 3 * f_counts[i]) + int(3 * f_off[i]))
        bbox.expand(shape.bbox())
    shape_of = dr.zeros(mi.UInt32, int(f_off[-1]))
    if len(shapes) > 1:
        starts = mi.UInt32(f_off[1:-1].astype(np.uint32))
        dr.scatter_add(shape_of, 1, starts, starts < int(f_off[-1]))
        shape_of = dr.prefix_sum(shape_of) + shape_of  # inclusive: shape of each face
    alpha = [_has_null(s) for s in shapes]
    return Geometry(
        positions=dr.unravel(mi.Point3f, positions), faces=dr.unravel(mi.Vector3u, faces),
        shape_of=shape_of, first_face=mi.UInt32(f_off[:-1].astype(np.uint32)),
        shapes=mi.ShapePtr(shapes), alpha=mi.Bool(alpha), alpha_any=any(alpha), bbox=bbox)


class ViewUniforms(NamedTuple):
    """A :class:`View`'s values as Dr.Jit scalars (float32, width 1): ``to_local`` (world ->
    view-local), ``q0``, ``dq`` (Point2f / Vector2f), ``near``, ``far`` (Float, local depth)."""
    to_local: mi.Transform4f
    q0: mi.Point2f
    dq: mi.Vector2f
    near: mi.Float
    far: mi.Float


@dataclass
class View:
    """A projection onto a ``width`` x ``height`` sample grid.

    In view-local coordinates a sample at continuous grid coordinate ``c`` (centres at
    integer + 1/2) has ``q = q0 + c * dq``; perspective: ray from the origin along
    (qx, qy, 1), orthographic: from (qx, qy, 0) along +z.  Depth is the local z.
    :attr:`to_clip` folds the q mapping into the transform: clip coordinates are
    ``((x - q0x z) / dqx, (y - q0y z) / dqy, z)`` (perspective; the grid coordinate is
    x/z, y/z) or ``((x - q0x) / dqx, (y - q0y) / dqy, z)`` (orthographic).

    Attributes:
        to_local: world -> view-local affine matrix, (4, 4) float64.
        perspective: perspective (True) or orthographic.
        q0, dq: (2,) floats, see above.
        near, far: accepted local depth range.
        width, height: grid size in samples.
    """
    to_local: np.ndarray
    perspective: bool
    q0: tuple[float, float]
    dq: tuple[float, float]
    near: float
    far: float
    width: int
    height: int

    @cached_property
    def to_clip(self) -> mi.Transform4f:
        """World -> clip transform (composed in float64, applied in float32).

        Opaque: a kernel reads it as a parameter, so views that differ only in placement
        (cube faces, shadow maps of many light points, a moving camera) share one compiled
        kernel instead of each compiling its own."""
        a = np.eye(4)
        a[0, 0], a[1, 1] = 1 / self.dq[0], 1 / self.dq[1]
        column = 2 if self.perspective else 3
        a[0, column], a[1, column] = -self.q0[0] / self.dq[0], -self.q0[1] / self.dq[1]
        transform = mi.Transform4f((a @ self.to_local).astype(np.float32))
        dr.make_opaque(transform)
        return transform

    @cached_property
    def uniforms(self) -> "ViewUniforms":
        """The per-view values kernels read (:class:`ViewUniforms`), opaque like
        :attr:`to_clip`: a new camera placement, whose inverse rounds these differently in
        the last bits, reuses the compiled kernels instead of tracing them as new literals."""
        values = ViewUniforms(mi.Transform4f(self.to_local.astype(np.float32)),
                              mi.Point2f(*self.q0), mi.Vector2f(*self.dq),
                              mi.Float(self.near), mi.Float(self.far))
        dr.make_opaque(*values)
        return values

    def homogeneous(self, p: mi.Point3f) -> mi.Vector3f:
        """h(p) of clip points: (x, y, z) in perspective, (x, y, 1) in orthographic views."""
        return mi.Vector3f(p.x, p.y, p.z if self.perspective else 1.0)

    def grid(self, p: mi.Point3f) -> tuple[mi.Float, mi.Float]:
        """Continuous grid coordinates of clip points ``p``."""
        return (p.x / p.z, p.y / p.z) if self.perspective else (p.x, p.y)

    def texel(self, z: mi.Float) -> mi.Float:
        """World size of one grid cell (along x) at local depth ``z``."""
        return abs(self.dq[0]) * (z if self.perspective else 1.0)


def view_from_sensor(sensor: mi.Sensor, aa: int = 1) -> View:
    """The :class:`View` whose grid samples are the sensor's rays through the aa x aa
    sub-cell centres of each pixel of the film's crop window.

    Raises:
        ValueError: for sensors other than ``perspective`` and ``orthographic``.
    """
    kind = sensor.class_name()
    if kind not in ("PerspectiveCamera", "OrthographicCamera"):
        raise ValueError(f"raster: visibility='zbuffer' supports 'perspective' and "
                         f"'orthographic' sensors, not {kind!r}")
    w, h = sensor.film().crop_size()
    to_world = np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)
    to_local = np.linalg.inv(to_world)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
                               mi.Point2f(0.5))
    o = np.array(ray.o, dtype=np.float64)
    d = np.array(ray.d, dtype=np.float64)
    far_p = o + d * np.array(ray.maxt, dtype=np.float64)
    o_l = to_local[:3, :3] @ o + to_local[:3, 3:4]
    d_l = to_local[:3, :3] @ d
    far_l = to_local[:3, :3] @ far_p + to_local[:3, 3:4]
    perspective = kind == "PerspectiveCamera"
    q = d_l[:2] / d_l[2] if perspective else o_l[:2]
    q0 = (float(q[0, 0]), float(q[1, 0]))
    dq = (float(q[0, 1] - q[0, 0]) / (w * aa), float(q[1, 2] - q[1, 0]) / (h * aa))
    return View(to_local=to_local, perspective=perspective, q0=q0, dq=dq,
                near=float(o_l[2, 0]), far=float(far_l[2, 0]),
                width=int(w * aa), height=int(h * aa))


def sample_index(view: View, X: mi.UInt32, Y: mi.UInt32, aa: int) -> mi.UInt32:
    """Index of grid sample (X, Y) in the order of ``raster.pixel_rays``: pixels in frame
    order (:mod:`.pixel_order`), a pixel's aa x aa sub-samples row by row."""
    lane = pixel_order.lane_of(X // aa, Y // aa, view.width // aa, view.height // aa)
    return lane * (aa * aa) + (Y % aa) * aa + X % aa


def sample_xy(view: View, index: mi.UInt32, aa: int) -> tuple[mi.UInt32, mi.UInt32]:
    """Grid sample (X, Y) of each :func:`sample_index` ``index`` (its inverse)."""
    n = aa * aa
    lane, sub = index // n, index % n
    px, py = pixel_order.pixel_of(lane, view.width // aa, view.height // aa)
    return px * aa + sub % aa, py * aa + sub // aa


#: The edges of a triangle (vertex index pairs).
TRIANGLE = ((0, 1), (1, 2), (2, 0))
#: Every pair of a prism's six vertices (layer 0: 0-2, top layer: 3-5): the edges of their
#: convex hull are among them, so cutting them all bounds the hull (:func:`rasterise_layers`).
PRISM = tuple((i, j) for i in range(6) for j in range(i + 1, 6))


def _bbox(view: View, c: list, pairs=TRIANGLE):
    """Grid bounding box of the convex hulls of clip-space points ``c`` (a list of
    Point3f: a triangle's 3 vertices, a prism's 6), clipped at the near plane (``pairs``:
    vertex pairs that include the hull's edges, whose near-plane crossings bound the
    clipped hull).

    Returns:
        (x0, y0, width, height) of the candidate sample rectangle (Int32; width or height
        0 for culled triangles).
    """
    lo = [mi.Float(dr.inf), mi.Float(dr.inf)]
    hi = [mi.Float(-dr.inf), mi.Float(-dr.inf)]

    def include(p, ok):
        gx, gy = view.grid(p)
        ok = ok & dr.isfinite(gx) & dr.isfinite(gy)
        for i, g in enumerate((gx, gy)):
            lo[i] = dr.select(ok, dr.minimum(lo[i], g), lo[i])
            hi[i] = dr.select(ok, dr.maximum(hi[i], g), hi[i])

    near, far = view.uniforms.near, view.uniforms.far
    if view.perspective:
        for p in c:  # the hull clipped at z = near: front vertices + crossings
            include(p, p.z >= near)
        for i, j in pairs:
            p, q = c[i], c[j]
            crosses = (p.z < near) != (q.z < near)
            x = dr.lerp(p, q, (near - p.z) / (q.z - p.z))
            include(mi.Point3f(x.x, x.y, near), crosses)
    else:
        for p in c:
            include(p, mi.Bool(True))
    z_lo, z_hi = _z_range(c)
    keep = (z_hi >= near) & (z_lo <= far)
    size = (view.width, view.height)
    start, count = [], []
    for i in range(2):
        first = dr.clip(dr.ceil(lo[i] - 0.5 - BOX_MARGIN), 0, size[i])
        last = dr.clip(dr.floor(hi[i] - 0.5 + BOX_MARGIN), -1, size[i] - 1)
        start.append(mi.Int32(first))
        count.append(dr.select(keep & (lo[i] <= hi[i]),
                               dr.maximum(mi.Int32(last - first) + 1, 0), 0))
    return start[0], start[1], count[0], count[1]


def _z_range(c: list) -> tuple[mi.Float, mi.Float]:
    """Smallest and largest depth of clip-space points ``c``."""
    z_lo, z_hi = c[0].z, c[0].z
    for p in c[1:]:
        z_lo, z_hi = dr.minimum(z_lo, p.z), dr.maximum(z_hi, p.z)
    return z_lo, z_hi


def screen_boxes(view: View, geom: Geometry, clip: mi.Point3f, tri: mi.UInt32):
    """Candidate sample rectangles ``(x0, y0, width, height)`` (Int32) of triangles ``tri``
    (``clip``: :func:`to_clip`), as :func:`rasterise` bins them (culling, binning)."""
    return _bbox(view, _triangles(geom, clip, tri)[1])


def _row_span(view: View, c: list, Y: mi.UInt32, x0: mi.Int32, x1: mi.Int32, pairs=TRIANGLE):
    """Samples [xs, xe) of grid row ``Y`` that the convex hulls of clip-space points ``c``
    (triangles; prisms with ``pairs`` = :data:`PRISM`) may cover, within their box columns
    [x0, x1): the row's centre line cut with the projected
    segments ``pairs`` it meets (those whose y range reaches within :data:`SPAN_MARGIN` of the line:
    each one's point nearest to the line, so a superset of the exact span, whose ends lie
    on such edges), widened by :data:`SPAN_MARGIN` (the homogeneous edge test of a sliver
    triangle can round a sample inside that lies a fraction of a cell outside its
    projection) and a relative rounding margin; the whole box row where a vertex lies
    behind the near plane.  The inside test still decides."""
    y = mi.Float(Y) + 0.5
    g = [view.grid(p) for p in c]
    lo, hi = mi.Float(dr.inf), mi.Float(-dr.inf)
    for i, j in pairs:
        (ax, ay), (bx, by) = g[i], g[j]
        flat = ay == by
        s = dr.clip((y - ay) / dr.select(flat, 1.0, by - ay), 0.0, 1.0)
        # only edges the row's line meets (within the margin) bound the span
        meets = (y >= dr.minimum(ay, by) - SPAN_MARGIN) & (y <= dr.maximum(ay, by) + SPAN_MARGIN)
        for x in (ax + s * (bx - ax), dr.select(flat, bx, ax + s * (bx - ax))):
            lo = dr.select(meets, dr.minimum(lo, x), lo)
            hi = dr.select(meets, dr.maximum(hi, x), hi)
    margin = SPAN_MARGIN + 1e-5 * (dr.abs(lo) + dr.abs(hi))
    xs = mi.Int32(dr.clip(dr.ceil(lo - 0.5 - margin), mi.Float(x0), mi.Float(x1)))
    xe = mi.Int32(dr.clip(dr.floor(hi - 0.5 + margin) + 1, mi.Float(x0), mi.Float(x1)))
    if view.perspective:
        behind = _z_range(c)[0] < view.uniforms.near
        xs, xe = dr.select(behind, x0, xs), dr.select(behind, x1, xe)
    ok = dr.isfinite(lo) & dr.isfinite(hi)
    return dr.select(ok, xs, x0), dr.select(ok, dr.maximum(xe, xs), x1)


def _edge_setup(view: View, face: mi.Vector3u, c: list):
    """Per triangle (vertex indices ``face``, clip-space vertices ``c``): the edge-function
    vectors E_i (``e_i = E_i . (qx, qy, 1)``, the edge opposite vertex i in canonical vertex
    order, sign folded in: negation is exact) and the vertex depths."""
    h = [view.homogeneous(v) for v in c]
    E = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        swap = face[j] > face[k]
        hj, hk = dr.select(swap, h[k], h[j]), dr.select(swap, h[j], h[k])
        value = dr.cross(hj, hk)
        E.append(dr.select(swap, -value, value))
    return E, (c[0].z, c[1].z, c[2].z)


def _edges_at(view: View, setup, X: mi.UInt32, Y: mi.UInt32, active: mi.Bool):
    """Inside test, barycentrics and depth at grid sample (X, Y) of triangles prepared by
    :func:`_edge_setup`: ``(inside, b1, b2, z)``."""
    E, z = setup
    q = mi.Vector3f(mi.Float(X) + 0.5, mi.Float(Y) + 0.5, 1.0)
    return _inside(view, [dr.dot(Ei, q) for Ei in E], z, active)


def _inside(view: View, e: list, z: tuple, active: mi.Bool):
    """Inside test, barycentrics and depth from the edge-function values ``e`` (3 Float)
    of a sample and the vertex depths ``z``: ``(inside, b1, b2, z)``."""
    z0, z1, z2 = z
    total = e[0] + e[1] + e[2]
    inside = active & (total != 0) & (
        ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0)))
    inv = dr.rcp(total)
    b1, b2 = e[1] * inv, e[2] * inv
    z = (1.0 - b1 - b2) * z0 + b1 * z1 + b2 * z2
    inside &= (z >= view.uniforms.near) & (z <= view.uniforms.far)
    return inside, b1, b2, z


def _edges(view: View, face: mi.Vector3u, c: list, X: mi.UInt32, Y: mi.UInt32,
           active: mi.Bool):
    """Inside test, barycentrics and depth at grid sample (X, Y) of triangles with vertex
    indices ``face`` and clip-space vertices ``c``: ``(inside, b1, b2, z)``."""
    return _edges_at(view, _edge_setup(view, face, c), X, Y, active)


def _triangles(geom: Geometry, clip: mi.Point3f, tri: mi.UInt32, active: mi.Bool = True):
    face = dr.gather(mi.Vector3u, geom.faces, tri, active)
    return face, [dr.gather(mi.Point3f, clip, face[i], active) for i in range(3)]


def fragment(view: View, clip: mi.Point3f, geom: Geometry, tri: mi.UInt32,
             X: mi.UInt32, Y: mi.UInt32, active: mi.Bool):
    """Inside test, barycentrics and depth of triangle ``tri`` at grid sample (X, Y).

    ``clip`` are the clip-space vertices (:func:`to_clip`).  Returns ``(inside, b1, b2,
    z)``, with the mesh convention p = (1 - b1 - b2) p0 + b1 p1 + b2 p2.
    """
    face, c = _triangles(geom, clip, tri, active)
    return _edges(view, face, c, X, Y, active)


def to_clip(view: View, geom: Geometry) -> mi.Point3f:
    """Clip-space vertex positions (the vertex stage: one transform per vertex), evaluated."""
    clip = view.to_clip @ geom.positions
    dr.eval(clip)
    return clip


def _behind(view: View, aa: int, keys: mi.UInt64, x0, y0, bw, bh, z_lo) -> mi.Bool:
    """Hierarchical z (Greene et al. 1993): whether triangles with sample box (x0, y0, bw,
    bh) and nearest depth ``z_lo`` lie behind every fragment already in ``keys`` there.
    A pyramid of 2x2 maxima of the stored depths (+inf where empty; grid padded to a
    power of two with -inf, where no sample lies); a box of side <= 2^L touches at most 2 x
    2 texels of level L, so four lookups bound its stored depths."""
    w, h = view.width, view.height
    size = 1 << max(int(max(w, h)) - 1, 0).bit_length()
    X, Y = sample_xy(view, dr.arange(mi.UInt32, w * h), aa)
    depth = dr.select(keys == EMPTY, dr.inf, dr.reinterpret_array(mi.Float, mi.UInt32(keys >> 32)))
    level = dr.full(mi.Float, -dr.inf, size * size)
    dr.scatter(level, depth, Y * size + X)
    levels, offsets, offset = [level], [0], size * size
    while size > 1:   # log2(size) levels
        size //= 2
        i = dr.arange(mi.UInt32, size * size)
        x, y = 2 * (i % size), 2 * (i // size)
        prev = levels[-1]
        at = lambda dx, dy: dr.gather(mi.Float, prev, (y + dy) * (2 * size) + x + dx)
        level = dr.maximum(dr.maximum(at(0, 0), at(1, 0)), dr.maximum(at(0, 1), at(1, 1)))
        dr.eval(level)
        levels.append(level)
        offsets.append(offset)
        offset += size * size
    pyramid = dr.zeros(mi.Float, offset)
    for lvl, off in zip(levels, offsets):   # log2 levels, not elements
        dr.scatter(pyramid, lvl, dr.arange(mi.UInt32, dr.width(lvl)) + off)
    side = mi.UInt32(dr.maximum(dr.maximum(bw, bh), 1))
    L = mi.UInt32(dr.ceil(dr.log2(mi.Float(side))))
    L = dr.minimum(L, len(levels) - 1)
    off = dr.gather(mi.UInt32, mi.UInt32(offsets), L)
    n = dr.gather(mi.UInt32, mi.UInt32([1 << (len(levels) - 1 - k) for k in range(len(levels))]), L)
    tx0, ty0 = mi.UInt32(dr.maximum(x0, 0)) >> L, mi.UInt32(dr.maximum(y0, 0)) >> L
    tx1 = dr.minimum(mi.UInt32(dr.maximum(x0 + bw - 1, 0)) >> L, n - 1)
    ty1 = dr.minimum(mi.UInt32(dr.maximum(y0 + bh - 1, 0)) >> L, n - 1)
    some = (bw > 0) & (bh > 0)
    far = mi.Float(-dr.inf)
    for tx, ty in ((tx0, ty0), (tx1, ty0), (tx0, ty1), (tx1, ty1)):
        far = dr.maximum(far, dr.gather(mi.Float, pyramid, off + ty * n + tx, some))
    return some & (z_lo > far)


def _row_pieces(bx0: mi.Int32, by0: mi.Int32, bw: mi.Int32, bh: mi.Int32):
    """The rows of sample boxes ``(x0, y0, width, height)`` cut into pieces of at most
    :data:`SPAN` samples, enumerated in one flat range (an exclusive prefix sum over the
    per-box counts; each piece finds its box by a segmented prefix sum).

    Yields:
        per batch of at most :data:`CHUNK` pieces, ``(k, Y, x0, x1)``: the box of each
        piece (UInt32 index into the boxes), its row and its columns [x0, x1) (Int32).
    """
    pieces = (mi.UInt32(bw) + (SPAN - 1)) // SPAN   # row pieces of at most SPAN samples
    counts = mi.UInt32(bh) * pieces
    offsets = dr.prefix_sum(mi.UInt64(counts))  # exclusive
    dr.eval(offsets, bx0, by0, bw, pieces)
    total = int(dr.sum(mi.UInt64(counts))[0])
    for begin in range(0, total, CHUNK):  # work batches, not boxes
        size = min(CHUNK, total - begin)
        # the bounds as kernel parameters (opaque), the counts added by plain atomics (the
        # default mode keeps a copy per worker at a stride of the traced size): the kernels
        # do not depend on the batch or on the piece count, which moves with the view
        start, end = dr.opaque(mi.UInt64, begin), dr.opaque(mi.UInt64, begin + size)
        seg = dr.zeros(mi.UInt32, size)
        inner = (offsets > start) & (offsets < end)
        dr.scatter_add(seg, 1, mi.UInt32(offsets - start), inner, mode=dr.ReduceMode.Direct)
        first = mi.UInt32(dr.count(offsets <= start)) - 1
        k = first + dr.prefix_sum(seg) + seg
        j = mi.UInt32(start + dr.arange(mi.UInt64, size) - dr.gather(mi.UInt64, offsets, k))
        # >= 1 also in the LLVM backend's padding lanes, where a gather yields 0 and an
        # integer division by it raises SIGFPE
        n = dr.maximum(dr.gather(mi.UInt32, pieces, k), 1)
        Y = mi.UInt32(dr.gather(mi.Int32, by0, k) + mi.Int32(j // n))
        x0 = dr.gather(mi.Int32, bx0, k) + mi.Int32(j % n) * SPAN
        x1 = dr.minimum(x0 + SPAN, dr.gather(mi.Int32, bx0, k) + dr.gather(mi.Int32, bw, k))
        yield k, Y, x0, x1


def _key(z: mi.Float, t: mi.UInt32) -> mi.UInt64:
    """Depth-test key of a fragment at view depth ``z`` of triangle ``t`` (module doc, 5)."""
    return (mi.UInt64(_depth_bits(z)) << 32) | mi.UInt64(t)


def _depth_bits(z: mi.Float) -> mi.UInt32:
    """float32 bits of a depth >= 0 (positive floats order like their bits)."""
    return dr.reinterpret_array(mi.UInt32, dr.maximum(z, 0.0))


def rasterise(view: View, geom: Geometry, with_ids: bool = True, aa: int = 1,
              small: int = 1, floor: mi.UInt64 | None = None, alpha=None, initial=None):
    """Depth-test every triangle of ``geom`` at every grid sample of ``view``.

    Triangles with at most ``small`` candidate samples (micro-triangles, the common case
    after tessellation) are tested in the same kernel that bins them, one thread per
    triangle; those with up to :data:`MEDIUM` loop over their candidates in one thread;
    slivers (a box at most :data:`SPAN` wide and :data:`TALL` tall) loop in one thread
    over the samples of each row that the row's span may cover; larger ones are spread
    over one thread per piece of :data:`SPAN` samples of a box row, each looping over the
    samples of its piece that the row's span may cover, so a screen-covering triangle is
    as parallel as many small ones.  Every path makes the same fragments.

    Args:
        with_ids: keep the triangle (UInt64 keys: depth bits << 32 | triangle id) or only
            the depth (UInt32 float bits: shadow maps).
        aa: sub-samples per pixel side (sets the buffer order, :func:`sample_index`).
        small: triangles with at most this many candidates are tested in the binning
            kernel (each extra one costs every triangle an edge test).
        floor: optional per-sample keys (``with_ids``): only fragments whose key is
            larger enter the depth test (depth peeling; :data:`EMPTY` draws nothing).
        alpha: optional per-fragment test (a GPU's ``discard``): ``alpha(tri, active)``
            reads what it needs of triangles ``tri`` (once per thread, outside the loops
            over samples) and returns ``test(index, b1, b2, active) -> Bool`` of their
            fragments at samples ``index`` (:func:`sample_index`) with perspective-correct
            barycentrics (b1, b2); fragments that fail it write no depth.
        initial: optional keys to draw over (an existing z-buffer, left unchanged: the
            result is a copy); default: empty.  With ``with_ids``, triangles behind every
            stored fragment of their box are skipped whole (:func:`_behind`).

    Returns:
        (keys, clip): a (width * height,) UInt64 or UInt32 buffer in
        :func:`sample_index` order (:data:`EMPTY` / 0xFFFFFFFF where nothing was drawn)
        and the clip-space vertices (None without triangles).
    """
    n_faces = dr.width(geom.faces)
    samples = view.width * view.height
    if initial is None:
        keys = dr.full(mi.UInt64 if with_ids else mi.UInt32,
                       EMPTY if with_ids else 0xFFFFFFFF, samples)
    else:
        keys = dr.copy(initial)
    if n_faces == 0 or samples == 0:
        return keys, None
    clip = to_clip(view, geom)

    def depth_test(t, X, Y, inside, b1, b2, z, test=None):
        depth = _depth_bits(z)
        index = sample_index(view, X, Y, aa)
        if with_ids:
            key = _key(z, t)
            if floor is not None:
                inside &= key > dr.gather(mi.UInt64, floor, index, inside)
        # early depth test (a read; the minimum only falls, so a stale value is safe): a
        # fragment behind the stored one runs no alpha test and no atomic.  The alpha test
        # runs under a symbolic if, which a SIMD packet with no fragment left jumps over.
        value = key if with_ids else depth
        inside &= value < dr.gather(type(value), keys, index, inside)
        if test is not None:
            inside = dr.if_stmt((inside,), inside, lambda m: (m & test(index, b1, b2, m),),
                                lambda m: (m,), label="raster_alpha")[0]
        # real atomics (Direct): the lanes rarely meet on a sample, and the default for a
        # buffer this small (Expand: a copy per worker thread, reduced at the end) costs
        # more memory traffic (measured: -9 % on the donut's slices, -19 % wall on a 1M-
        # triangle mesh at 512^2, same keys)
        dr.scatter_reduce(dr.ReduceOp.Min, keys, value, index, inside, mode=dr.ReduceMode.Direct)

    tri = dr.arange(mi.UInt32, n_faces)
    face, c = _triangles(geom, clip, tri)
    x0, y0, bw, bh = _bbox(view, c)
    count = mi.UInt32(bw * bh)
    if initial is not None and with_ids:   # hierarchical z: whole triangles behind the buffer
        count = dr.select(_behind(view, aa, initial, x0, y0, bw, bh, _z_range(c)[0]), 0, count)
    # small triangles (<= `small` candidate samples): tested by the thread that bins them
    w = mi.UInt32(dr.maximum(bw, 1))  # >= 1: no division by zero, even in padding lanes
    for i in range(small):
        X, Y = mi.UInt32(x0) + i % w, mi.UInt32(y0) + i // w
        active = (count <= small) & (i < count)
        depth_test(tri, X, Y, *_edges(view, face, c, X, Y, active),
                   None if alpha is None else alpha(tri, active))
    dr.eval(keys, count)
    medium = dr.compress((count > small) & (count <= MEDIUM))
    if dr.width(medium):  # a symbolic loop over each triangle's candidates, one thread each
        face_m, c_m = _triangles(geom, clip, medium)
        x0_m, y0_m, bw_m, bh_m = _bbox(view, c_m)
        n_m, w_m = mi.UInt32(bw_m * bh_m), mi.UInt32(dr.maximum(bw_m, 1))
        test_m = None if alpha is None else alpha(medium, mi.Bool(True))
        setup_m = _edge_setup(view, face_m, c_m)

        def body(i):
            X, Y = mi.UInt32(x0_m) + i % w_m, mi.UInt32(y0_m) + i // w_m
            depth_test(medium, X, Y, *_edges_at(view, setup_m, X, Y, mi.Bool(True)), test_m)
            return (i + 1,)

        dr.while_loop((mi.UInt32(0),), lambda i: i < n_m, body, label="raster_medium")
        dr.eval(keys)
    large = count > MEDIUM
    narrow = large & (bw <= SPAN) & (bh <= TALL)
    slim = dr.compress(narrow)
    if dr.width(slim):  # slivers: one thread each, looping over its rows' spans
        face_s, c_s = _triangles(geom, clip, slim)
        x0_s, y0_s, bw_s, bh_s = _bbox(view, c_s)
        test_s = None if alpha is None else alpha(slim, mi.Bool(True))
        setup_s = _edge_setup(view, face_s, c_s)

        def row(Y):
            xs, xe = _row_span(view, c_s, Y, x0_s, x0_s + bw_s)

            def body(X):
                depth_test(slim, X, Y, *_edges_at(view, setup_s, X, Y, mi.Bool(True)), test_s)
                return (X + 1,)

            dr.while_loop((mi.UInt32(xs),), lambda X: X < mi.UInt32(xe), body, label="raster_sliver_span")
            return (Y + 1,)

        dr.while_loop((mi.UInt32(y0_s),), lambda Y: Y < mi.UInt32(y0_s + bh_s), row, label="raster_slivers")
        dr.eval(keys)
    busy = dr.compress(large & ~narrow)  # the rest: one thread per piece of a row
    if dr.width(busy) == 0:
        return keys, clip
    _, c = _triangles(geom, clip, busy)
    for k, Y, x0, x1 in _row_pieces(*_bbox(view, c)):
        t = dr.gather(mi.UInt32, busy, k)
        face, c = _triangles(geom, clip, t)
        xs, xe = _row_span(view, c, Y, x0, x1)
        test = None if alpha is None else alpha(t, mi.Bool(True))
        setup = _edge_setup(view, face, c)

        def body(X):
            depth_test(t, X, Y, *_edges_at(view, setup, X, Y, mi.Bool(True)), test)
            return (X + 1,)

        dr.while_loop((mi.UInt32(xs),), lambda X: X < mi.UInt32(xe), body, label="raster_rows")
        dr.eval(keys)
    return keys, clip


def _layer_edge_setup(view: View, face: mi.Vector3u, c: list, m: list):
    """Per prism (vertex indices ``face``, clip-space vertices ``c`` of layer 0 and their
    steps ``m`` per layer): the edge functions of layer k as quadratics in k, one
    ``(A, B, C)`` triple of vectors per edge with ``e_i(k) = (A + k B + k^2 C) . (qx, qy, 1)``
    — h(c + k m) x h'(c' + k m') expanded, in :func:`_edge_setup`'s canonical vertex order
    (the prisms sharing an edge get bit-exactly opposite values at every k)."""
    hc = [view.homogeneous(p) for p in c]
    hm = [mi.Vector3f(v.x, v.y, v.z if view.perspective else 0.0) for v in m]
    E = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        swap = face[j] > face[k]
        a, b = [dr.select(swap, x[k], x[j]) for x in (hc, hm)], [dr.select(swap, x[j], x[k]) for x in (hc, hm)]
        sign = dr.select(swap, -1.0, 1.0)
        E.append((sign * dr.cross(a[0], b[0]), sign * (dr.cross(a[0], b[1]) + dr.cross(a[1], b[0])),
                  sign * dr.cross(a[1], b[1])))
    return E


def _layer_range(coef: list, top: float) -> tuple[mi.Float, mi.Float]:
    """Copies [lo, hi] (integral Floats; empty when lo > hi) of a prism that may cover a
    sample whose edge functions are ``a + k (b + k c)`` for ``coef`` = 3 x (a, b, c): a
    superset of those whose three values share a sign (the inside test).  Per sign s and
    edge, s (a + b k) >= -tol with tol >= |c| top^2 (the quadratic term over [0, top]) plus
    a margin far above float32 rounding of the values; widened by one copy."""
    lo, hi = mi.Float(dr.inf), mi.Float(-dr.inf)
    for s in (1.0, -1.0):
        lo_s, hi_s = mi.Float(0.0), mi.Float(top)
        for a, b, c in coef:
            quad = dr.abs(c) * (top * top)
            tol = quad + 1e-5 * (dr.abs(a) + dr.abs(b) * top + quad)
            a_, b_ = s * a + tol, s * b   # need a_ + b_ k >= 0
            root = -a_ / dr.select(b_ == 0, 1.0, b_)
            lo_s = dr.select(b_ > 0, dr.maximum(lo_s, root), lo_s)
            hi_s = dr.select(b_ < 0, dr.minimum(hi_s, root), hi_s)
            lo_s = dr.select((b_ == 0) & (a_ < 0), dr.inf, lo_s)
        some = lo_s <= hi_s
        lo, hi = dr.select(some, dr.minimum(lo, lo_s), lo), dr.select(some, dr.maximum(hi, hi_s), hi)
    lo = dr.maximum(dr.ceil(lo) - 1.0, 0.0)
    hi = dr.minimum(dr.floor(hi) + 1.0, top)
    return lo, hi


def rasterise_layers(view: View, geom: Geometry, step: mi.Vector3f, layers: int, aa: int = 1,
                     alpha=None, initial=None):
    """Depth-test ``layers`` offset copies of the triangles of ``geom`` at every grid sample
    of ``view``: copy k (k = 0 ... layers - 1) of vertex v lies at ``positions[v] + k
    step[v]`` (world units).  The result is :func:`rasterise`'s of the copies drawn as one
    mesh with face k F + f for copy k of face f (F faces): keys ``depth << 32 | k F + f``.

    The copies of one triangle form a prism, drawn by one thread per piece of a row of the
    prism's screen box (the hull of its bottom and top triangles, :data:`PRISM`), looping
    over the piece's samples and, per sample, over the copies: the clip-space vertices are
    affine in k, so each edge function is a quadratic in k whose coefficients are set up
    once per sample (:func:`_layer_edge_setup`), and a copy costs a few multiply-adds.  The
    copies are visited from the end of the stack nearer the viewer; the alpha test (a
    discard) runs only for a fragment in front of the thread's best so far, and one atomic
    minimum per sample writes that best: exact whatever the order, and front to back it
    tests about one fragment per prism and sample instead of one per copy.  A sample whose
    stored fragment lies in front of the prism's nearest vertex skips the prism before
    any setup (a third of the donut's sample-prism pairs behind its depth pre-pass).

    Args:
        step: per-vertex offset between consecutive copies, (V,) Vector3f [world units].
        alpha: optional per-fragment test: ``alpha(f, active)`` reads what it needs of
            faces ``f`` (once per thread) and returns ``test(index, k, b1, b2, active) ->
            Bool`` of their copy k's fragments at samples ``index`` (:func:`sample_index`).
        initial: optional keys to draw over (unchanged: the result is a copy); prisms
            behind every stored fragment of their box are skipped whole (:func:`_behind`).

    Returns:
        (keys, clip): the (width * height,) UInt64 buffer and the clip-space vertices of
        copy 0 (None without triangles).
    """
    samples = view.width * view.height
    keys = dr.full(mi.UInt64, EMPTY, samples) if initial is None else dr.copy(initial)
    n_faces = dr.width(geom.faces)
    if n_faces == 0 or samples == 0 or layers < 1:
        return keys, None
    clip = to_clip(view, geom)
    dclip = view.to_clip @ step   # the linear part: clip-space offset per copy
    dr.eval(dclip)
    top = float(layers - 1)

    def prism(f, active=True):
        face, c = _triangles(geom, clip, f, active)
        m = [dr.gather(mi.Vector3f, dclip, face[i], active) for i in range(3)]
        return face, c, m, c + [ci + top * mk for ci, mk in zip(c, m)]

    every = dr.arange(mi.UInt32, n_faces)
    _, _, _, hull = prism(every)
    x0, y0, bw, bh = _bbox(view, hull, PRISM)
    if initial is not None:   # hierarchical z: whole prisms behind the buffer
        gone = _behind(view, aa, initial, x0, y0, bw, bh, _z_range(hull)[0])
        bw = dr.select(gone, 0, bw)
    for k, Y, xa, xb in _row_pieces(x0, y0, bw, bh):
        f = k
        face, c, m, hull = prism(f)
        xs, xe = _row_span(view, hull, Y, xa, xb, PRISM)
        E = _layer_edge_setup(view, face, c, m)
        z0, dz = [ci.z for ci in c], [mk.z for mk in m]
        # the stack from its nearer end: the top copy first where it lies in front
        down = (dz[0] + dz[1] + dz[2]) < 0
        test = None if alpha is None else alpha(f, mi.Bool(True))

        # the prism's nearest vertex depth, less a margin for the rounding of a fragment's
        # interpolated depth (a convex combination of its copy's vertex depths)
        z_near = _z_range(hull)[0]
        z_near -= 1e-6 * dr.abs(z_near)

        def sample(X):
            index = sample_index(view, X, Y, aa)
            # early depth read (the buffer as at launch), kept as (depth, id) in 32 bits
            stored = dr.gather(mi.UInt64, keys, index)
            best_z = dr.select(stored == EMPTY, dr.inf,
                               dr.reinterpret_array(mi.Float, mi.UInt32(stored >> 32)))
            best_t = mi.UInt32(stored & 0xFFFFFFFF)
            # a prism whose nearest point lies behind the stored fragment draws nothing
            # here: the sample's setup is skipped (by a SIMD packet whose lanes all skip it)
            dr.if_stmt((X, index, best_z, best_t), z_near <= best_z, draw,
                       lambda *_: (), label="raster_layer_sample")
            return (X + 1,)

        def draw(X, index, best_z, best_t):
            q = mi.Vector3f(mi.Float(X) + 0.5, mi.Float(Y) + 0.5, 1.0)
            coef = [[dr.dot(v, q) for v in edge] for edge in E]
            lo, hi = _layer_range(coef, top)

            def layer(kf):   # (inside, b1, b2, z) of copy kf; z: its plane's, even outside
                e = [a + kf * (b + kf * cc) for a, b, cc in coef]
                return _inside(view, e, [z + kf * d for z, d in zip(z0, dz)], mi.Bool(True))

            # the ray meets the copies' planes from its nearer end of the range on
            z_lo, z_hi = layer(lo)[3], layer(hi)[3]
            from_hi = dr.select(dr.isfinite(z_lo) & dr.isfinite(z_hi) & (z_lo != z_hi), z_hi < z_lo, down)
            kf = dr.select(from_hi, hi, lo)
            step_k = dr.select(from_hi, -1.0, 1.0)

            def copy(kf, best_z, best_t, won, behind):
                inside, b1, b2, z = layer(kf)
                k = mi.UInt32(kf)
                t = k * n_faces + f
                z = dr.maximum(z, 0.0)
                behind = inside & (z > best_z)
                inside &= (z < best_z) | ((z == best_z) & (t < best_t))
                if test is not None:
                    inside = dr.if_stmt((inside, k, b1, b2), inside,
                                        lambda m_, k_, u_, v_: (m_ & test(index, k_, u_, v_, m_),),
                                        lambda m_, k_, u_, v_: (m_,), label="raster_layer_alpha")[0]
                return (kf + step_k, dr.select(inside, z, best_z), dr.select(inside, t, best_t),
                        won | inside, behind)

            # front to back, the first copy to pass is the front-most, and once a copy lies
            # behind the stored fragment so do the rest: stop there
            _, best_z, best_t, won, _ = dr.while_loop(
                (kf, best_z, best_t, mi.Bool(False), mi.Bool(False)),
                lambda kf, bz, bt, won, behind: (kf >= lo) & (kf <= hi) & ~won & ~behind, copy,
                label="raster_layers")
            dr.scatter_reduce(dr.ReduceOp.Min, keys, _key(best_z, best_t), index, won,
                              mode=dr.ReduceMode.Direct)
            return ()

        dr.while_loop((mi.UInt32(xs),), lambda X: X < mi.UInt32(xe), sample, label="raster_layer_rows")
        dr.eval(keys)
    return keys, clip


def preliminary(geom: Geometry, tri: mi.UInt32, b1: mi.Float, b2: mi.Float,
                ray: mi.Ray3f, active: mi.Bool) -> mi.PreliminaryIntersection3f:
    """A Mitsuba preliminary intersection of ``ray`` with triangle ``tri`` at (b1, b2)."""
    face = dr.gather(mi.Vector3u, geom.faces, tri, active)
    p = [dr.gather(mi.Point3f, geom.positions, face[i], active) for i in range(3)]
    hit = (1.0 - b1 - b2) * p[0] + b1 * p[1] + b2 * p[2]
    shape = dr.gather(mi.UInt32, geom.shape_of, tri, active)
    pi = dr.zeros(mi.PreliminaryIntersection3f, dr.width(tri))
    pi.t = dr.select(active, dr.dot(hit - ray.o, ray.d), dr.inf)
    pi.prim_uv = mi.Point2f(b1, b2)
    pi.prim_index = tri - dr.gather(mi.UInt32, geom.first_face, shape, active)
    pi.shape = dr.gather(mi.ShapePtr, geom.shapes, shape, active)
    pi.valid = active
    return pi
