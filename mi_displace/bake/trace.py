"""Distance rays from the low-poly surface into the high-poly (§2 Fig. 5, §3.2 step 2c, §4 Fig. 8).

For every covered sample (low-poly triangle + barycentrics from :mod:`uv_raster`) the low-poly
point p, the interpolated normal n and tangent frame are built, and the high-poly is hit with
Mitsuba's acceleration structure:

* **normal mode** — two rays, along +n from p - delta n and along -n from p + delta n, each
  within ``max_distance + delta`` (the paper's *maximum displacement*, §3.2 step 2b).
  ``delta`` (1e-5 of the bounding-box diagonal by default) makes a high-poly surface that
  passes exactly through p visible to both rays.
  **Hit rule.** A hit is *front-facing* when the high-poly face is oriented like the low-poly
  there (dot(face normal, n) > 0): the surface the ray is meant to measure.  The nearest
  front-facing hit of the two rays wins (ties go outward); only if neither ray has one does
  the nearest back-facing hit count, flagged ``backface``.  When both rays hit front-facing faces at
  different crossings (outside diagnostics mode the inward ray stops at the outward front
  hit's distance, so only folds nearer than that are seen), the normal line leaves the high-poly twice within +-max_distance (a
  fold or overhang; a thin shell's far wall is back-facing and does not count): the
  projection is ambiguous (height-field assumption broken, §3.1), flagged ``ambiguous`` (the
  value of the rule above is still written).  Diagnostics mode adds a continuation ray from
  the chosen hit away from the low-poly: another crossing within range (an overhang above
  the hit) is ``ambiguous`` too.
* **cage mode** (Fig. 8: rays along directions set by a transformed copy of the low-poly) — a
  cage with the low-poly's topology; the ray leaves the interpolated cage point q towards p and
  runs until ``max_distance`` past p.  The displacement is measured along that direction
  (outward = from p towards q), and the direction itself is stored for the direction formats
  of §1.2.  A second ray from the hit onward flags ``ambiguous`` crossings.

Signed displacement d [object units]: positive outside the low-poly (along n or towards the
cage).  Misses are re-traced without distance limit to tell ``beyond`` (a hit exists farther
than ``max_distance``) from ``miss`` (nothing at all).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.meshdata import MeshData, weld_ids
from mi_displace.bake.mitsuba_frames import stock_frame
from mi_displace.core.tessellate import gather as _gather_all

# Per-sample status, ordered so that the largest code is the worst (texel status = max).
EMPTY, OK, AMBIGUOUS, BACKFACE, BEYOND, MISS = 0, 1, 2, 3, 4, 5
STATUS_NAMES = {EMPTY: "empty", OK: "ok", AMBIGUOUS: "ambiguous", BACKFACE: "backface",
                BEYOND: "beyond", MISS: "miss"}


def gather(cls, source, index, active=True):
    """Masked dr.gather of a vector type, component by component (``active`` = in bounds)."""
    if active is True:
        return _gather_all(cls, source, index)
    return cls(*(dr.gather(type(c), c, index, active) for c in source))


def _vec(a: np.ndarray, cls=None):
    """(N, k) NumPy -> a Dr.Jit vector of type ``cls`` (default mi.Vector3f)."""
    a = np.asarray(a, np.float32)
    cls = cls or mi.Vector3f
    return cls(*[mi.Float(np.ascontiguousarray(a[:, k])) for k in range(a.shape[1])])


class HighPoly:
    """The high-poly in a Mitsuba scene (its BVH) plus face and vertex normals on the device."""

    def __init__(self, high: MeshData):
        # welded by position: a textured high-poly (vertices split at its UV seams) gets one
        # normal per position, so its normal map does not crease along its own seams
        weld = weld_ids(high.positions)
        V, F = int(weld.max()) + 1, len(high.faces)
        positions = np.zeros((V, 3), np.float32)
        positions[weld] = high.positions
        faces = weld[high.faces].astype(np.uint32)
        mesh = mi.Mesh("high_poly", V, F, has_vertex_normals=True, has_vertex_texcoords=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(np.ascontiguousarray(positions.ravel()))
        params["faces"] = mi.UInt32(np.ascontiguousarray(faces.ravel()))
        params.update()
        mesh.recompute_vertex_normals()   # Mitsuba's own (area/angle-weighted), on the device
        self.scene = mi.load_dict({"type": "scene", "high": mesh})
        p = high.positions.astype(np.float64)
        fn = np.cross(p[high.faces[:, 1]] - p[high.faces[:, 0]], p[high.faces[:, 2]] - p[high.faces[:, 0]])
        self.face_normals = _vec(fn)
        vn = mi.traverse(mesh)["vertex_normals"]
        self.vertex_normals = mi.Vector3f(*(dr.gather(mi.Float, vn, dr.arange(mi.UInt32, V) * 3 + k)
                                            for k in range(3)))
        self.faces = mi.Vector3u(*[mi.UInt32(np.ascontiguousarray(faces[:, k])) for k in range(3)])
        self.positions = _vec(positions, mi.Point3f)
        self.welded = (positions, faces)   # (V, 3) float32, (F, 3) uint32: one vertex per position

    def point(self, prim: mi.UInt32, bary: mi.Point2f, active: mi.Bool) -> mi.Point3f:
        """The high-poly point of triangle ``prim`` at barycentrics (b1, b2) = ``bary``."""
        f = [dr.gather(mi.UInt32, self.faces[k], prim, active) for k in range(3)]
        return (gather(mi.Point3f, self.positions, f[0], active) * (1.0 - bary.x - bary.y)
                + gather(mi.Point3f, self.positions, f[1], active) * bary.x
                + gather(mi.Point3f, self.positions, f[2], active) * bary.y)

    def shading_normal(self, prim: mi.UInt32, b1: mi.Float, b2: mi.Float,
                       active: mi.Bool) -> mi.Vector3f:
        """Interpolated (smooth) high-poly normal at a hit (``active``: valid hits only)."""
        f = [dr.gather(mi.UInt32, self.faces[k], prim, active) for k in range(3)]
        n = (gather(mi.Vector3f, self.vertex_normals, f[0], active) * (1.0 - b1 - b2)
             + gather(mi.Vector3f, self.vertex_normals, f[1], active) * b1
             + gather(mi.Vector3f, self.vertex_normals, f[2], active) * b2)
        return dr.normalize(n)

    def facing(self, prim: mi.UInt32, n: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        """True where a valid (``active``) hit face is oriented like the low-poly normal n."""
        return active & (dr.dot(gather(mi.Vector3f, self.face_normals, prim, active), n) > 0)


class LowPolyDevice:
    """Low-poly attributes on the device: positions, normals, tangents, signs, optional cage."""

    def __init__(self, low: MeshData, normals: np.ndarray, tangents: np.ndarray,
                 signs: np.ndarray, cage: np.ndarray | None = None):
        """``tangents`` (F, 3, 3) and ``signs`` (F, 3): per face corner (MikkTSpace)."""
        self.faces = [mi.UInt32(low.faces[:, k].astype(np.uint32)) for k in range(3)]
        self.p = _vec(low.positions, mi.Point3f)
        self.uv = _vec(low.uvs, mi.Point2f)
        self.n = _vec(normals)
        self.t = _vec(np.asarray(tangents, np.float32).reshape(-1, 3))
        self.sign = mi.Float(np.asarray(signs, np.float32).ravel())
        self.cage = None if cage is None else _vec(cage, mi.Point3f)

    def interpolate(self, prim, b1, b2):
        """p, unnormalised n and t, per-pixel bitangent sign*(n x t) and the cage point q."""
        f = [dr.gather(mi.UInt32, self.faces[k], prim) for k in range(3)]
        corner = [prim * 3 + k for k in range(3)]
        w = (1.0 - b1 - b2, b1, b2)

        def lerp(cls, arr, index):
            return sum((gather(cls, arr, index[k]) * w[k] for k in (1, 2)), gather(cls, arr, index[0]) * w[0])

        p, n = lerp(mi.Point3f, self.p, f), lerp(mi.Vector3f, self.n, f)
        t = lerp(mi.Vector3f, self.t, corner)
        s = dr.sign(sum((dr.gather(mi.Float, self.sign, corner[k]) * w[k] for k in (1, 2)),
                        dr.gather(mi.Float, self.sign, corner[0]) * w[0]))
        q = None if self.cage is None else lerp(mi.Point3f, self.cage, f)
        return p, n, t, s * dr.cross(n, t), q

    def stock_frame(self, prim, n):
        """Mitsuba's ``normalmap`` frame ``(s, t)`` at the samples (``n``: unit normal)."""
        f = [dr.gather(mi.UInt32, self.faces[k], prim) for k in range(3)]
        return stock_frame(*(gather(mi.Point3f, self.p, i) for i in f),
                           *(gather(mi.Point2f, self.uv, i) for i in f), n)


@dataclass
class TraceResult:
    """Per-sample outputs (Dr.Jit arrays of the samples' width)."""

    status: mi.UInt32
    displacement: mi.Float          # signed, object units
    normal_object: mi.Vector3f      # high-poly shading normal (object space), unit
    normal_tangent: mi.Vector3f     # the same in the low-poly's tangent frame, unit
    normal_mitsuba: mi.Vector3f     # the same in Mitsuba's normalmap frame (s, t, n), unit
    direction_tangent: mi.Vector3f  # displacement direction in the tangent frame, unit
    back_depth: mi.Float | None     # dual-depth: signed displacement of the surface behind
    prim_high: mi.UInt32            # the high-poly triangle hit (valid where ``found``)
    bary_high: mi.Point2f           # its barycentrics (b1, b2) at the hit
    found: mi.Bool                  # a high-poly surface was hit within range


def _tangent_space(t, b, n, v):
    """Solve [t b n] x = v (the exact inverse of the shader's t*x + b*y + n*z), normalised."""
    m = mi.Matrix3f(t.x, b.x, n.x, t.y, b.y, n.y, t.z, b.z, n.z)
    x = dr.rcp(m) @ v  # matrix inverse
    ok = dr.all(dr.isfinite(x)) & (dr.squared_norm(x) > 0)
    return dr.select(ok, dr.normalize(x), mi.Vector3f(0, 0, 1))


def _hit(scene, o, d, maxt):
    """Preliminary intersections, evaluated at once (else every field re-traces the rays)."""
    pi = scene.ray_intersect_preliminary(mi.Ray3f(o, d, maxt, 0.0, []), coherent=False)
    dr.eval(pi.t, pi.prim_index, pi.prim_uv, pi.valid)
    return pi


def trace(high: HighPoly, low: LowPolyDevice, prim, b1, b2, max_distance: float,
          delta: float, dual_depth: bool = False, continuation: bool = False) -> TraceResult:
    """Trace the samples (see the module docstring); all arguments per sample.

    ``continuation`` (diagnostics mode) traces one more ray from the chosen hit onward, away
    from the low-poly, to the end of the ``max_distance`` range: a second crossing there
    (an overhang above the hit) also marks the texel ``ambiguous``.
    """
    p, n_raw, t, b, q = low.interpolate(prim, b1, b2)
    n = dr.normalize(n_raw)
    dr.eval(p, n, n_raw, t, b, q)  # shared by every ray kernel below
    if q is None:
        pa = _hit(high.scene, p - delta * n, n, max_distance + delta)
        va = pa.is_valid()
        fa = high.facing(pa.prim_index, n, va)
        da = pa.t - delta
        # the inward ray only needs to beat a front hit outward (shorter rays traverse less);
        # diagnostics mode searches the whole range, to count every fold
        reach = max_distance + delta
        if not continuation:
            reach = dr.select(fa, dr.minimum(pa.t + delta, reach), reach)
        pb = _hit(high.scene, p + delta * n, -n, reach)
        vb = pb.is_valid()
        db = -(pb.t - delta)
        fb = high.facing(pb.prim_index, n, vb)
        pick_a = dr.select(fa | fb, fa & (~fb | (dr.abs(da) <= dr.abs(db))),
                           va & (~vb | (dr.abs(da) <= dr.abs(db))))
        found = va | vb
        front = dr.select(pick_a, fa, fb)
        ambiguous = fa & fb & (dr.abs(da - db) > 2 * delta)
        d = dr.select(found, dr.select(pick_a, da, db), 0.0)
        prim_h = dr.select(pick_a, pa.prim_index, pb.prim_index)
        uv_h = dr.select(pick_a, pa.prim_uv, pb.prim_uv)
        direction = n
    else:  # cage: from q through p (Fig. 8)
        to_p = p - q
        span = dr.norm(to_p)
        dirn = mi.Vector3f(to_p / dr.maximum(span, 1e-30))  # Point3f - Point3f stays a Point3f
        pc = _hit(high.scene, q, dirn, span + max_distance)
        found = pc.is_valid()
        front = high.facing(pc.prim_index, n, found)
        d = dr.select(found, span - pc.t, 0.0)
        prim_h, uv_h = pc.prim_index, pc.prim_uv
        nxt = _hit(high.scene, q + dirn * (pc.t + delta), dirn, span + max_distance - pc.t - delta)
        ambiguous = found & nxt.is_valid()
        direction = -dirn
    if continuation and q is None:  # diagnostics: does the line cross the high-poly again?
        beyond_hit = p + direction * (d + dr.select(d >= 0, delta, -delta))
        sgn = dr.select(d >= 0, 1.0, -1.0)
        again = _hit(high.scene, beyond_hit, direction * sgn, dr.maximum(max_distance - dr.abs(d) - delta, 0.0))
        ambiguous |= found & front & again.is_valid() & (max_distance - dr.abs(d) > 2 * delta)
    u32 = mi.UInt32
    status = dr.select(found, dr.select(front, dr.select(ambiguous, u32(AMBIGUOUS), u32(OK)),
                                        u32(BACKFACE)), u32(MISS))
    # misses: is there a hit farther than max_distance?
    miss = dr.compress(~found)
    if dr.width(miss):
        pm = dr.gather(mi.Point3f, p, miss)
        dm = dr.gather(mi.Vector3f, direction, miss)
        far = _hit(high.scene, pm, dm, dr.inf).is_valid() | _hit(high.scene, pm, -dm, dr.inf).is_valid()
        dr.scatter(status, dr.select(far, u32(BEYOND), u32(MISS)), miss)
    n_high = dr.select(found, high.shading_normal(prim_h, uv_h.x, uv_h.y, found), n)
    back = None
    if dual_depth:  # the next surface behind the chosen one, down to the lower plane
        start = p + direction * d
        pd = _hit(high.scene, start - direction * delta, -direction, d + max_distance)
        back = dr.select(found & pd.is_valid(), d - delta - pd.t, -max_distance)
    # along the normal the direction is the tangent frame's z axis by construction
    dir_ts = (_tangent_space(t, b, n_raw, direction) if q is not None
              else mi.Vector3f(dr.zeros(mi.Float, dr.width(d)), 0.0, 1.0))
    s_m, t_m = low.stock_frame(prim, n)
    n_mitsuba = mi.Vector3f(dr.dot(n_high, s_m), dr.dot(n_high, t_m), dr.dot(n_high, n))
    return TraceResult(status, d, n_high, _tangent_space(t, b, n_raw, n_high), n_mitsuba,
                       dir_ts, back, prim_h, mi.Point2f(uv_h), found)
