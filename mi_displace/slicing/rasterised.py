"""The slice polygons drawn as a GPU draws them (§3): rasterised by our z-buffer.

Under the ``raster`` integrator the slices of a :class:`~mi_displace.slicing.sliced.SlicedVolume`
are not walked by ray queries but rasterised once per frame by
:func:`mi_displace.render.zbuffer.rasterise` at the sensor's samples: the α-test is a
per-fragment ``discard`` (a fragment whose test fails writes no depth), the depth test
keeps the front-most passing fragment, and the BSDF then shades that fragment
(:meth:`FrameBuffer.lookup`).  The slices are the same polygons, at the same places, as
those the ray-traced walk meets (:mod:`mi_displace.slicing.trace`), so both draw the same
image:

* the slicing family of a sample (``best``: §3.2, the direction most perpendicular to the
  viewer) is chosen, as by the walk, from the frame of the first wall of the displacement
  volume the sample's ray meets (the walls rasterised first); a fragment of another family
  is discarded;
* the walls themselves are never drawn, except the bottom wall where the ray leaves
  through it when the base polygons are drawn too (``opaque_base``).

The walk stops at the wall the ray leaves through and Mitsuba continues the ray; the
rasteriser sees every stretch of the volume at once, with the family chosen at the first
one.  Where they differ: rays that pass through a first stretch and meet a second one
whose entry face would pick another family, and slices seen edge-on (a view along the
slices of a forced direction b or c), where the walk's step past each polygon and the
rasteriser's sliver triangles decide a few pixels differently (measured in
docs/slicing.md).  Screen-space slicing (closed-form planes) is not rasterised.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mi_displace.render import zbuffer
from mi_displace.render.raster import pixel_rays
from mi_displace.slicing import geometry as geo
from mi_displace.slicing.sliced import FAMILIES, Hit, SlicedVolume
from mi_displace.slicing.trace import alpha_test

#: Floats per sample of :attr:`FrameBuffer.packed` (a power of two: one packet gather).
PACKED = 16
#: A lane's ray is one of the frame's sample rays when it passes this close to the sample's
#: ray (relative to the volume's size + the distance) and points along it within this many grid cells.
ON_RAY_EPS, ON_SAMPLE_CELLS = 1e-4, 1e-2


@dataclass(init=False, eq=False)   # its fields a PyTree: a frozen raster frame finds the arrays
class FrameBuffer:
    """The front-most passing slice fragment of every sample of one view.

    Attributes:
        view: the sensor's :class:`~mi_displace.render.zbuffer.View`; aa: sub-samples per
            pixel side (the sample order of :func:`mi_displace.render.raster.pixel_rays`).
        covered: per sample, whether the frame answers for it: its ray meets the volume's
            walls (Bool; every sample when one family is drawn: the walls then decide
            nothing, as every slice and base polygon lies inside them).
        found: per sample, whether a fragment passed (Bool).
        packed: per sample, the fragment: :data:`PACKED` floats (1, p, uv, n, su, sv, 0;
            undefined where ``found`` is not set), read by one packet gather, (n * 16,)
            Float; :attr:`hit` unpacks it.
        eye: camera position (opaque Point3f, world units; perspective) or None (orthographic).
        length: the volume's size [world units] that :data:`ON_RAY_EPS` is relative to (opaque Float).
        to_local, q0, dq: the view's :class:`~mi_displace.render.zbuffer.ViewUniforms` the
            lookup reads, as fields (a frozen frame traverses dataclass fields; with the
            ``NamedTuple`` as one field, Dr.Jit refused the recording).
    """

    covered: mi.Bool
    found: mi.Bool
    packed: mi.Float
    eye: mi.Point3f | None
    length: mi.Float
    to_local: mi.Transform4f
    q0: mi.Point2f
    dq: mi.Vector2f

    def __init__(self, view: zbuffer.View, aa: int, covered: mi.Bool, found: mi.Bool,
                 packed: mi.Float, eye: mi.Point3f | None, length: mi.Float):
        self.view, self.aa = view, aa   # not fields: Python values the frame's kernels are traced with
        self.covered, self.found, self.packed, self.eye, self.length = covered, found, packed, eye, length
        self.to_local, self.q0, self.dq = view.uniforms.to_local, view.uniforms.q0, view.uniforms.dq

    @property
    def hit(self) -> Hit:
        """Every sample's fragment (:class:`~mi_displace.slicing.sliced.Hit`)."""
        n = dr.width(self.covered)
        return _unpack(dr.gather(mi.ArrayXf, self.packed, dr.arange(mi.UInt32, n), self.found,
                                 shape=(PACKED, n)))

    def lookup(self, origin: mi.Point3f, d: mi.Vector3f, active: mi.Bool):
        """The fragment of the frame's sample whose ray ``origin + t d`` (t >= 0) is.

        Returns:
            ``(use, hit)``: ``use`` where the lane's ray is a sample ray of this frame that
            meets the volume (and its fragment is not behind ``origin``); elsewhere the
            caller walks the slices itself.
        """
        view = self.view
        local, q0, dq = self.to_local, self.q0, self.dq
        dl = local @ d
        if view.perspective:
            r = origin - self.eye
            off = r - dr.dot(r, d) * d
            tol = ON_RAY_EPS * (self.length + dr.norm(r))
            on_ray = (dr.norm(off) <= tol) & (dr.dot(r, d) >= -tol) & (dl.z > 0)
            q = mi.Point2f(dl.x / dl.z, dl.y / dl.z)
        else:
            ol = local @ origin
            on_ray = (dr.abs(dl.x) + dr.abs(dl.y) <= ON_RAY_EPS) & (dl.z > 0)
            q = mi.Point2f(ol.x, ol.y)
        gx, gy = (q.x - q0.x) / dq.x, (q.y - q0.y) / dq.y
        X, Y = dr.floor(gx), dr.floor(gy)
        on_ray &= (dr.abs(gx - X - 0.5) <= ON_SAMPLE_CELLS) & (dr.abs(gy - Y - 0.5) <= ON_SAMPLE_CELLS)
        on_ray &= (X >= 0) & (X < view.width) & (Y >= 0) & (Y < view.height)
        use = mi.Bool(active) & on_ray
        index = zbuffer.sample_index(view, mi.UInt32(dr.maximum(X, 0)), mi.UInt32(dr.maximum(Y, 0)),
                                     self.aa)
        use &= dr.gather(mi.Bool, self.covered, index, use)
        found = dr.gather(mi.Bool, self.found, index, use)
        hit = _unpack(dr.gather(mi.ArrayXf, self.packed, index, found, shape=(PACKED, dr.width(index))))
        use &= ~hit.found | (dr.dot(hit.p - origin, d) >= -ON_RAY_EPS * (self.length + dr.norm(hit.p - origin)))
        return use, hit


def _unpack(a: mi.ArrayXf) -> Hit:
    """The :class:`Hit` of :data:`PACKED` floats per sample (:attr:`FrameBuffer.packed`)."""
    return Hit(a[0] > 0, mi.Point3f(a[1], a[2], a[3]), mi.Point2f(a[4], a[5]),
               *(mi.Vector3f(a[j], a[j + 1], a[j + 2]) for j in (6, 9, 12)))


def _box_counts(view: zbuffer.View, aa: int, mask: mi.Bool, boxes) -> mi.UInt32:
    """Per rectangle ``(x0, y0, width, height)`` of the sample grid, how many samples in it
    have ``mask`` set (a summed-area table: two prefix sums, four lookups per box)."""
    w, h = view.width, view.height
    X, Y = zbuffer.sample_xy(view, dr.arange(mi.UInt32, w * h), aa)
    grid = dr.zeros(mi.UInt32, (w + 1) * (h + 1))   # zero first row and column
    dr.scatter(grid, mi.UInt32(mask), (Y + 1) * (w + 1) + X + 1)
    for stride, length in ((w + 1, h + 1), (h + 1, w + 1)):   # rows, then columns
        inclusive = dr.cumsum(grid)
        start = dr.arange(mi.UInt32, dr.width(grid)) // stride * stride
        grid = inclusive - dr.gather(mi.UInt32, inclusive - grid, start)
        # transpose (stride x length -> length x stride) for the next pass / the result
        i = dr.arange(mi.UInt32, dr.width(grid))
        grid = dr.gather(mi.UInt32, grid, (i % length) * stride + i // length)
        dr.eval(grid)
    x0, y0, bw, bh = boxes
    x0, y0 = mi.UInt32(x0), mi.UInt32(y0)
    x1, y1 = x0 + mi.UInt32(bw), y0 + mi.UInt32(bh)
    some = (bw > 0) & (bh > 0)
    at = lambda x, y: dr.gather(mi.UInt32, grid, y * (w + 1) + x, some)
    return dr.select(some, at(x1, y1) - at(x0, y1) - at(x1, y0) + at(x0, y0), 0)


def _store(frame: FrameBuffer, ray, found, keys, clip, geom, attributes) -> None:
    """Write into ``frame`` (:attr:`FrameBuffer.packed`, :attr:`FrameBuffer.found`) the
    fragments of ``keys`` where ``found`` (only those samples are resolved): the point at
    the key's depth on the sample's ray, and ``attributes(tri, b1, b2) -> (uv, n, su, sv)``
    at the barycentrics of the key's triangle of ``geom`` (clip-space vertices ``clip``) at
    the sample (n normalised); one packet scatter per sample."""
    index = dr.compress(found)
    if dr.width(index) == 0:
        return
    view, aa = frame.view, frame.aa
    key = dr.gather(mi.UInt64, keys, index)
    tri = mi.UInt32(key & 0xFFFFFFFF)
    X, Y = zbuffer.sample_xy(view, index, aa)
    _, b1, b2, _ = zbuffer.fragment(view, clip, geom, tri, X, Y, True)
    o, d = dr.gather(mi.Point3f, ray.o, index), dr.gather(mi.Vector3f, ray.d, index)
    local = view.uniforms.to_local
    depth = dr.reinterpret_array(mi.Float, mi.UInt32(key >> 32))   # view-local z
    p = o + (depth - (local @ o).z) / (local @ d).z * d
    uv, n, su, sv = attributes(tri, b1, b2)
    columns = [dr.full(mi.Float, 1.0, dr.width(index)), *p, *uv, *dr.normalize(n), *su, *sv]
    columns += [dr.zeros(mi.Float, dr.width(index))] * (PACKED - len(columns))
    dr.scatter(frame.packed, mi.ArrayXf(columns), index)
    dr.scatter(frame.found, True, index)
    dr.eval(frame.packed, frame.found)


def _slice_attributes(slices, prim_of=None):
    """``attributes`` of :func:`_store` from the vertices of ``slices`` faces
    ``prim_of[tri]`` (or ``tri``)."""
    def attributes(tri, b1, b2):
        prim = tri if prim_of is None else dr.gather(mi.UInt32, prim_of, tri)
        idx = slices.corners(prim, True)
        uv = mi.Point2f(*slices.lerp(slices.uv, 2, idx, (b1, b2), True))
        return (uv, *(mi.Vector3f(*slices.lerp(b, 3, idx, (b1, b2), True))
                      for b in (slices.bn, slices.su, slices.sv)))
    return attributes


def _corner_uvs(slices, idx: list, active) -> list:
    """The uv of slice vertices ``idx`` (3 UInt32: a triangle's corners), 3 Point2f."""
    return [mi.Point2f(*(dr.gather(mi.Float, slices.uv, 2 * v + k, active) for k in range(2)))
            for v in idx]


def _passes(volume: SlicedVolume, uvs: list, b1, b2, h_alpha, active) -> mi.Bool:
    """The α-test (§3.1 / §3.2, a discard) of fragments at barycentrics (b1, b2) of
    triangles with corner uvs ``uvs``, against the slice's value ``h_alpha``."""
    uv = (1.0 - b1 - b2) * uvs[0] + b1 * uvs[1] + b2 * uvs[2]
    return active & alpha_test(volume.alpha, volume.D(uv), h_alpha)


def _draw_polygons(volume: SlicedVolume, view, aa, slices, mine, start):
    """The slice triangles (not the walls) whose screen box holds a sample of ``mine``,
    rasterised one by one.  Returns ``(keys, clip, geom, attributes)`` (:func:`_store`)."""
    full = slices.geometry()
    every = dr.arange(mi.UInt32, dr.width(full.faces))
    boxes = zbuffer.screen_boxes(view, full, zbuffer.to_clip(view, full), every)
    keep = dr.compress((_box_counts(view, aa, mine, boxes) > 0)
                       & ((dr.gather(mi.UInt32, slices.flags, every) & 1) == 0))
    geom = dataclasses.replace(full, faces=dr.gather(mi.Vector3u, full.faces, keep))

    def alpha(tri, active):   # corners read once per thread; h_α interpolated (§3.2 ramps)
        idx = slices.corners(dr.gather(mi.UInt32, keep, tri, active), active)
        uvs = _corner_uvs(slices, idx, active)
        ramps = [dr.gather(mi.Float, slices.ramp, v, active) for v in idx]

        def test(sample, b1, b2, active):
            ramp = (1.0 - b1 - b2) * ramps[0] + b1 * ramps[1] + b2 * ramps[2]
            return _passes(volume, uvs, b1, b2, ramp, active)

        return test

    keys, clip = zbuffer.rasterise(view, geom, True, aa=aa, alpha=alpha, initial=start)
    return keys, clip, geom, _slice_attributes(slices, keep)


def _draw_aligned(volume: SlicedVolume, view, aa, slices, start):
    """Direction a's slices — the base lifted to h = k / N, slice k's faces k F + f of the
    family's mesh (:func:`mi_displace.slicing.geometry.aligned_slices`) — rasterised as
    layered copies of slice 0 (:func:`mi_displace.render.zbuffer.rasterise_layers`: one
    prism per base polygon, front to back).  Returns ``(keys, clip, geom, attributes)``
    (:func:`_store`; the attributes read from the base vertices, one packet per corner)."""
    n, V = volume.counts["a"], len(volume.bm.positions)
    full = slices.geometry()
    base, step = volume.prisms   # built with the volume: slice 0 and the step between slices

    def alpha(f, active):   # every copy has slice 0's uvs; copy k's h_α is k / N
        uvs = _corner_uvs(slices, slices.corners(f, active), active)
        return lambda sample, k, b1, b2, active: _passes(volume, uvs, b1, b2, mi.Float(k) / n, active)

    if volume.alpha == "basic" and not volume.opaque_base:
        # slice 0 passes the basic test everywhere (D >= 0), so its fragments are in the
        # result wherever nothing nearer passes: drawn first without α-test (a depth
        # pre-pass, same keys), they cull the prisms and fragments behind the surface.  The
        # base polygons, when drawn (before, in `draw`), cull the same: their bottom wall
        # lies just below slice 0 (the donut's raster frame at 512^2: 0.95-0.98x, the same)
        start, _ = zbuffer.rasterise(view, base, True, aa=aa, initial=start)
    keys, _ = zbuffer.rasterise_layers(view, base, step, n, aa=aa, alpha=alpha, initial=start)
    table = volume.vertex_table   # every slice's vertex v' has base vertex v' mod V's attributes

    def attributes(tri, b1, b2):
        face = dr.gather(mi.Vector3u, full.faces, tri)
        w = (1.0 - b1 - b2, b1, b2)
        a = sum(w[i] * dr.gather(mi.ArrayXf, table, face[i] % V, shape=(geo.TABLE_WIDTH, dr.width(tri)))
                for i in range(3))
        return mi.Point2f(a[0], a[1]), *(mi.Vector3f(a[j], a[j + 1], a[j + 2]) for j in (2, 5, 8))

    return keys, zbuffer.to_clip(view, full), full, attributes


def draw(volume: SlicedVolume, sensor: mi.Sensor, aa: int = 1) -> FrameBuffer:
    """Rasterise the slices of ``volume`` at the samples of ``sensor`` (module doc).

    Raises:
        ValueError: for screen-space slicing (planes, not polygons) and sensors the
            z-buffer does not support (:func:`mi_displace.render.zbuffer.view_from_sensor`).
    """
    if volume.direction == "screen":
        raise ValueError("slicing: screen-space slices are planes met in closed form, not "
                         "polygons: they are not rasterised")
    view = zbuffer.view_from_sensor(sensor, aa)
    ray, _, _, _ = pixel_rays(sensor, aa)
    dr.eval(ray.o, ray.d)   # one kernel (gathered from, each component would be its own)
    n = view.width * view.height   # samples (a constant ray component has width 1)
    low = mi.UInt64(0xFFFFFFFF)
    walls = volume.walls_scene
    wgeom = walls.geometry()
    if len(FAMILIES[volume.direction]) > 1:
        # the first wall each sample's ray meets: the proxy face the walk starts from
        wkeys, _ = zbuffer.rasterise(view, wgeom, True, aa=aa)
        covered = wkeys != zbuffer.EMPTY
        third = dr.full(mi.Float, 1 / 3, n)
        bn, su, sv = walls.frame(mi.UInt32(wkeys & low), (third, third), covered)
        choice = volume.choose(ray.d, dr.normalize(bn), su, sv)
    else:   # one family: the walls decide nothing (every slice and base polygon lies inside
        # them, and a ray that misses them never asks the frame: it misses the proxy)
        covered, choice = dr.full(mi.Bool, True, n), dr.zeros(mi.UInt32, n)
    dr.eval(covered, choice)
    eye = None
    if view.perspective:
        eye = mi.Point3f(sensor.world_transform() @ mi.ScalarPoint3f(0, 0, 0))
        dr.make_opaque(eye)   # a kernel parameter: a camera move compiles nothing new
    frame = FrameBuffer(view, aa, covered, dr.zeros(mi.Bool, n), dr.empty(mi.Float, PACKED * n), eye,
                        walls.length)
    # the base polygons, when drawn: the bottom wall where the ray leaves through it; drawn
    # first, it hides every slice fragment behind it (early depth test) and stays below
    # every slice fragment in front of it (its key keeps the depth, an id of all ones)
    initial = dr.full(mi.UInt64, zbuffer.EMPTY, n)
    if volume.opaque_base:
        every = dr.arange(mi.UInt32, dr.width(wgeom.faces))
        bottoms = dr.compress((dr.gather(mi.UInt32, walls.flags, every) & 2) != 0)
        bgeom = dataclasses.replace(wgeom, faces=dr.gather(mi.Vector3u, wgeom.faces, bottoms))

        def leaving(tri, active):   # seen from inside: the ray runs along the outward normal
            fn = walls.face_normal(dr.gather(mi.UInt32, bottoms, tri, active), active)
            return lambda sample, b1, b2, active: active & (
                dr.dot(dr.gather(mi.Vector3f, ray.d, sample, active), fn) > 0)

        # samples whose ray misses the volume start at the nearest key: nothing drawn there
        base, bclip = zbuffer.rasterise(view, bgeom, True, aa=aa, alpha=leaving,
                                        initial=dr.select(covered, initial, 0))
        # stored last, where no slice fragment lies in front of it: a few samples (the
        # slices' own base, slice 0 or the lowest iso-levels, is in front almost everywhere)
        bottom = covered & (base != zbuffer.EMPTY)
        initial = base | low
        dr.eval(initial, bottom)
    for index, fam in enumerate(FAMILIES[volume.direction]):   # a, b, c: three at most
        mine = covered & (choice == index)
        if not dr.any(mine):
            continue
        # a fragment of another family's sample is discarded: there the buffer starts at
        # the nearest key, so the early depth test rejects every fragment before its alpha
        # test (and the hierarchical z skips triangles with no sample of this family)
        start = dr.select(mine, initial, 0)
        if len(FAMILIES[volume.direction]) == 1 and not volume.opaque_base:
            start = None   # an empty buffer: no hierarchical z to build
        slices = volume.families[fam][0]
        if fam == "a":   # offset copies of the base: drawn as prisms, front to back
            keys, clip, geom, attributes = _draw_aligned(volume, view, aa, slices, start)
        else:
            keys, clip, geom, attributes = _draw_polygons(volume, view, aa, slices, mine, start)
        drawn = mine & ((keys & low) != low)
        _store(frame, ray, drawn, keys, clip, geom, attributes)
        if volume.opaque_base:
            bottom &= ~drawn
    if volume.opaque_base:
        _store(frame, ray, bottom, base, bclip, bgeom, _slice_attributes(walls, bottoms))
    return frame
