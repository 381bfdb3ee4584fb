"""Front-to-back slice loops: the first slice whose fragment passes the α-test wins.

A GPU draws every slice polygon and its depth test keeps the front-most fragment that the
α-test lets through.  Per ray that is a loop over the slices in the order the ray meets
them, stopping at the first passing one — never a march with its own step: the slices sit
at fixed places, so their artefacts (see-through at grazing angles, stair steps) are kept.

* :func:`first_passing_slice` — slice *polygons* (surface-aligned or orthogonal, any base):
  each iteration asks the slices' own BVH for the next polygon along the ray (the order a
  depth test sorts fragments in), until a fragment passes or the ray leaves the
  displacement volume through a wall.
* :func:`first_passing_plane` — parallel *planes* ``p . m = c + k delta`` (screen-space
  slices §3.3, the cube slices of depth objects §4.1): plane k is met at
  ``t_k = (c + k delta - o . m) / (d . m)`` in closed form, k stepping towards the ray.

Both are Dr.Jit symbolic loops; every argument is a Dr.Jit array of one entry per ray.
"""
from __future__ import annotations

from typing import Callable

import drjit as dr
import mitsuba as mi

#: α-test of §3.1 (``basic``: D >= h_α, zero heights drawn) and §3.2 (``ramp``: D - h_α > 0,
#: zero heights masked out).
ALPHA_TESTS = ("basic", "ramp")
#: A face index that names no face (:meth:`mi_displace.slicing.geometry.LayerStack.next_face`).
NO_FACE = 0xFFFFFFFF
#: Offset [x (L + max |p|), L the slices' bounding-box diagonal] that moves a walk off the
#: polygon it just met: relative to the object's size and position, never an absolute
#: length, so a model in millimetres walks the same slices as one in metres.  Mitsuba's
#: spawn_ray uses ~9e-5, which would skip slices closer than that.
SPAWN_EPS = 1e-5


def step_past(p: mi.Point3f, n: mi.Vector3f, d: mi.Vector3f, length: float | mi.Float) -> mi.Float:
    """Distance along unit ``d`` that leaves the polygon through ``p`` (unit normal ``n``)
    behind by :data:`SPAWN_EPS` x (``length`` + max |p|) along its normal (``length``: the
    slices' size, world units).  Walks stay on the ray's line (a normal offset per slice
    would drift the ray sideways over thousands of slices)."""
    offset = SPAWN_EPS * (length + dr.max(dr.abs(p)))
    return offset / dr.maximum(dr.abs(dr.dot(d, n)), 1e-3)


def alpha_test(kind: str, D: mi.Float, h_alpha: mi.Float) -> mi.Bool:
    """The fragment test: ``D`` displacement (α channel, [0, 1]), ``h_alpha`` the slice's."""
    if kind == "basic":
        return D >= h_alpha
    return D - h_alpha > 0


def first_passing_slice(slices, origin: mi.Point3f, d: mi.Vector3f,
                        test: Callable[[mi.Point2f, mi.Float], mi.Bool],
                        active: mi.Bool, max_iter: int | mi.UInt32, opaque_base: bool = False,
                        t_floor: mi.Float | None = None, coherent: bool = False,
                        reach: float | None = None, stack=None):
    """Walk the slice polygons of ``slices`` (a :class:`mi_displace.slicing.geometry.SliceScene`)
    from ``origin`` along unit ``d``.

    Walls (the volume boundary) are passed when entered; the walk stops at the first
    passing slice fragment, at the first wall the ray leaves through, at a miss, or after
    ``max_iter`` polygons.  With ``opaque_base`` the bottom wall (the base surface) is a
    passing fragment when the ray leaves through it (the base polygons drawn as well).

    ``t_floor`` (optional, per ray): the distance of the surface the walk is made for (a
    proxy wall the ray reached after passing others); stretches of volume the ray leaves
    before it are passed over, as a chain of pass-throughs left them behind.  A ray
    spawned at the last wall meets no such stretch; a ray from the camera (the z-buffer's
    depth peeling) does.

    Args:
        test: ``test(uv, h_alpha) -> Bool``, the α-test of a slice fragment.
        coherent: the rays are coherent (neighbouring lanes: neighbouring origins, nearly
            parallel directions, e.g. a raster frame's shadow rays towards one light): the
            slices' BVH is queried with Embree's coherent flag (its packet traversal), which
            finds the same polygons, faster for such rays and slower for scattered ones.
        reach: bound each query after the first to ``reach`` x the distance the previous
            step advanced (the ray's ``maxt``): the BVH culls every node beyond it, so a
            query from inside a stack of slices visits the nodes near its origin only.  A
            query that finds nothing so near is asked again without the bound in the next
            iteration (not counted against ``max_iter``).  The polygon found is the nearest
            either way, and Embree computes its distance and barycentrics the same (they do
            not depend on ``maxt``): the same walk, bit for bit (``None``: unbounded), but
            for two polygons met within float rounding of the bound itself, where Embree's
            own bound test could keep the farther one (none seen: tested on random rays,
            and the donut's frames at 10 views are identical).
        stack: the slices' :class:`~mi_displace.slicing.geometry.LayerStack` or ``None``:
            after a slice polygon (or a's top wall), the ray is first tested against the
            adjacent polygon over the same base triangle (a's next slice or its top wall,
            b's / c's next iso-level) with Mitsuba's ray-triangle arithmetic
            (:meth:`~mi_displace.slicing.geometry.LayerStack.intersect`); where it meets
            it, that is the next polygon and the BVH is not queried.  Within a prism of the
            stack the next polygon is that one, except for a ray that leaves the prism
            through a side and comes back to it, which then skips what it met outside:
            where the volumes over neighbouring base triangles overlap (a thick
            displacement over sharp features; tests/slicing/test_walk_stack.py bounds how
            often).

    Returns:
        ``(found, t, prim, bary, t_enter, t_exit, bottom)``: distance, face and barycentrics
        of the fragment found; ``t_enter`` the distance to the first wall entered (0 if the
        walk starts inside), ``t_exit`` to the wall left (inf on a miss), both from
        ``origin``; ``bottom``: that wall is the bottom.
    """
    scene = slices.scene
    n = dr.width(origin)
    inf, zero = dr.full(mi.Float, dr.inf, n), dr.zeros(mi.Float, n)

    def body(i, t_acc, found, going, t_hit, prim, b0, b1, t_enter, t_exit, bottom, near, after):
        ray = mi.Ray3f(origin + t_acc * d, d)
        if reach is not None:
            ray.maxt = near
        stepped = dr.zeros(mi.Bool, n)
        if stack is not None:   # the adjacent polygon over the same base triangle
            # under a symbolic if too: a packet with no lane past a slice polygon (walks that
            # begin, or enter through a wall) skips the test
            can = going & (after != NO_FACE)
            stepped, tc, u, v, after = dr.if_stmt(
                (ray, can, after), can, lambda r, m, f: stack.step(f, r, m),
                lambda r, m, f: (dr.zeros(mi.Bool, n), zero, zero, zero, f), label="slicing_step")

        def query(ray, active):   # the BVH: the nearest polygon
            pi = scene.ray_intersect_preliminary(ray, coherent=coherent, active=active)
            return pi.t, pi.prim_uv.x, pi.prim_uv.y, pi.prim_index

        if stack is None:
            tq, bu, bv, face = query(ray, going)
        else:   # under a symbolic if: a SIMD packet whose lanes all stepped skips the BVH
            # (the donut's raster frame, a: 0.97-0.98x against a masked query)
            tq, bu, bv, face = dr.if_stmt(
                (ray, going & ~stepped, tc, u, v, after), going & ~stepped,
                lambda r, m, *_: query(r, m), lambda r, m, t_, u_, v_, f_: (t_, u_, v_, f_),
                label="slicing_query")
        valid = going & (stepped | (tq < dr.inf))
        retry = dr.zeros(mi.Bool, n)
        if reach is not None:   # nothing within the bound: ask again, unbounded
            retry = going & ~valid & (near < dr.inf)
        flags = dr.gather(mi.UInt32, slices.flags, face, valid)
        fn = slices.face_normal(face, valid)
        wall = (flags & 1) != 0
        leaving = valid & wall & (dr.dot(ray.d, fn) > 0)
        entering = valid & wall & ~leaving
        t = t_acc + tq
        p = origin + t * d
        early = dr.zeros(mi.Bool, dr.width(t))
        if t_floor is not None:   # before the surface walked for: left behind
            early = valid & (t < t_floor - step_past(p, fn, d, slices.length))
            leaving &= ~early
        t_enter = dr.select(entering & (t_enter == dr.inf) & (t_exit == dr.inf), t, t_enter)
        t_enter = dr.select(early & wall & ~entering, dr.inf, t_enter)
        t_exit = dr.select(leaving, t, t_exit)
        bottom = leaving & ((flags & 2) != 0)
        idx = slices.corners(face, valid)
        bary = (bu, bv)
        uv = mi.Point2f(*slices.lerp(slices.uv, 2, idx, bary, valid))
        ramp = slices.lerp(slices.ramp, 1, idx, bary, valid)[0]
        passes = valid & ~wall & ~early & test(uv, ramp)
        if opaque_base:
            passes |= bottom
        t_hit = dr.select(passes, t, t_hit)
        prim = dr.select(passes, face, prim)
        b0, b1 = dr.select(passes, bary[0], b0), dr.select(passes, bary[1], b1)
        found |= passes
        going = valid & ~passes & ~leaving & (i + 1 < max_iter)
        step = step_past(p, fn, d, slices.length)
        t_acc = dr.select(going, t + step, t_acc)
        if reach is not None:
            near = dr.select(retry, dr.inf, dr.select(going, reach * (tq + step), near))
            i = dr.select(retry, i, i + 1)
            going |= retry
        else:
            i = i + 1
        if stack is not None:
            # a retried query (reach) asks again from the same place: the same step first
            after = dr.select(retry, after, stack.next_face(face, fn, d, going & valid))
        return i, t_acc, found, going, t_hit, prim, b0, b1, t_enter, t_exit, bottom, near, after

    state = (dr.zeros(mi.UInt32, n), mi.Float(zero), dr.zeros(mi.Bool, n), mi.Bool(active),
             mi.Float(zero), dr.zeros(mi.UInt32, n), mi.Float(zero), mi.Float(zero),
             mi.Float(inf), mi.Float(inf), dr.zeros(mi.Bool, n), mi.Float(inf),
             dr.full(mi.UInt32, NO_FACE, n))
    _, _, found, _, t_hit, prim, b0, b1, t_enter, t_exit, bottom, _, _ = dr.while_loop(
        state=state, cond=lambda i, ray, found, going, *_: going, body=body,
        labels=("i", "t_acc", "found", "going", "t_hit", "prim", "b0", "b1", "t_enter",
                "t_exit", "bottom", "near", "after"),
        label="slicing_polygons")
    t_enter = dr.select(t_enter == dr.inf, 0.0, dr.minimum(t_enter, t_exit))
    return found, t_hit, prim, (b0, b1), t_enter, t_exit, bottom


def first_passing_plane(o: mi.Point3f, d: mi.Vector3f, m: mi.Vector3f, c, delta: float | mi.Float,
                        t_in: mi.Float, t_out: mi.Float, test: Callable[[mi.Point3f], mi.Bool],
                        active: mi.Bool, max_iter: int, skip=None):
    """First of the planes ``p . m = c + k delta`` (k integer) met by ``o + t d`` in
    [t_in, t_out] where ``test(p)`` holds, front to back.

    ``skip(t) -> Float`` (optional, empty-space skipping): a ray parameter up to which
    ``test`` fails for every point of the ray (``t`` where nothing is known); the planes
    before it are passed over without testing them.  The result is the same.

    Returns:
        ``(found, t)``: t of the passing plane point (unspecified where not found).
    """
    dm, om = dr.dot(d, m), dr.dot(o, m)
    ok = mi.Bool(active) & (dr.abs(dm) > 1e-12) & (t_out >= t_in)
    dm_safe = dr.select(dr.abs(dm) > 1e-12, dm, 1.0)
    f = (om + t_in * dm - c) / delta
    k0 = dr.select(dm > 0, dr.ceil(f), dr.floor(f))
    step = dr.select(dm > 0, 1.0, -1.0)
    n = dr.width(ok)

    def body(j, found, t_hit, going):
        t = (c + (k0 + step * mi.Float(j)) * delta - om) / dm_safe
        going &= t <= t_out
        passes = going & test(o + t * d)
        t_hit = dr.select(passes, t, t_hit)
        found |= passes
        nxt = j + 1
        if skip is not None:   # the first plane at or after skip(t)
            f = (om + skip(t) * dm - c) / delta
            k = dr.select(dm > 0, dr.ceil(f), dr.floor(f))
            nxt = mi.UInt32(dr.clip(step * (k - k0), mi.Float(nxt), float(max_iter)))
        return nxt, found, t_hit, going & ~passes & (nxt < max_iter)

    _, found, t_hit, _ = dr.while_loop(
        state=(mi.UInt32(0), dr.zeros(mi.Bool, n), dr.zeros(mi.Float, n), ok),
        cond=lambda j, found, t_hit, going: going, body=body,
        labels=("j", "found", "t_hit", "going"), label="slicing_planes")
    return found, t_hit
