"""The slice polygons of displacement by slicing (§3) and the displacement volume.

The *displacement volume* of a base polygon is its prism extruded along the interpolated
vertex directions up to the maximum displacement ``scale``: a point of it is
``P(b, h) = sum_i b_i (P_i + h scale n_i)`` (barycentrics b, normalised height h in [0, 1];
on a mesh base n_i is the welded normal, one per position, as ``displaced`` uses).
The slices are the polygons a GPU draws through it, built once here with NumPy (one-off
precomputation; the per-pixel work is in :mod:`mi_displace.slicing.trace`):

* direction **a** (surface-aligned, §3.1): the base polygons offset to h = k / N,
  k = 0 ... N - 1, with the constant α value h_α = k / N;
* directions **b** and **c** (orthogonal, §3.2, Fig. 5): the iso-lines u = const (b) and
  v = const (c) of each base triangle extruded from h = 0 to h = 1 (quads), with the α-ramp
  h_α = 0 at the bottom and 1 at the top as a vertex attribute and the same texture
  coordinates at the lower and upper vertices ("the displacement texture extruded along
  the slicing polygon").

Every slice vertex carries: texture coordinates (u, v), ``rw`` = (h_α, wall flag, bottom
flag), the
base normal ``bn`` and the base tangents ``su`` = dS/du, ``sv`` = dS/dv (world units per
unit uv), interpolated like any GPU varying.  The volume's boundary (top at h = 1 + ε,
bottom at h = -ε, side walls along the base's open edges) is the proxy mesh that rays
enter; it carries the wall flag 1.  Units: world units; arrays NumPy float64 unless noted.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import surfaces, tessellate
from mi_displace.core.mesh_io import load_uv_mesh
from mi_displace.render import zbuffer
from mi_displace.slicing.trace import NO_FACE, SPAWN_EPS

#: Most slice triangles one object may build (memory guard, ~100 bytes each).
MAX_SLICE_TRIANGLES = 8_000_000
#: Largest slice count per family (the issue's extreme).
MAX_SLICES = 4096
#: Offset of the proxy walls outside the slices: this fraction of ``scale``, and at least
#: four slice-walk offsets (:data:`mi_displace.slicing.trace.SPAWN_EPS`).
WALL_EPS = 2e-3
ATTRIBUTES = ("rw", "bn", "su", "sv")


def _columns(v) -> np.ndarray:
    """(N, k) float64 NumPy array of a Dr.Jit vector (scalar components broadcast)."""
    n = dr.width(v)
    return np.stack([np.broadcast_to(np.asarray(c, np.float64), (n,)) for c in v], 1)


@dataclass
class BaseMesh:
    """The base polygons in world space.

    Attributes:
        positions, normals: (V, 3) world points and unit normals.
        uvs: (V, 2) texture coordinates; faces: (F, 3) int64 vertex indices.
        su, sv: (V, 3) tangents dS/du, dS/dv [world units per unit uv].
        base: the parametric base (``None`` for a mesh file); to_world: (4, 4) matrix.
        extrude: (V, 3) world displacement per unit of ``scale`` (the object-space
            direction through to_world, as ``displaced`` displaces in object space: on a
            mesh base the welded normal of :func:`tessellate.welded_normals`); None: normals.
    """

    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    faces: np.ndarray
    su: np.ndarray
    sv: np.ndarray
    base: surfaces.BaseSurface | None = None
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    extrude: np.ndarray | None = None

    def __post_init__(self):
        if self.extrude is None:
            self.extrude = self.normals

    def world_scale(self, scale: float) -> float:
        """The maximum displacement ``scale`` (object units) in world units (median)."""
        return scale * float(np.median(np.linalg.norm(self.extrude, axis=1)))

    def extent(self) -> tuple[float, float]:
        """World lengths (L_u, L_v) of the base along u and v (median tangent x uv range)."""
        span = self.uvs.max(0) - self.uvs.min(0)
        lu = float(np.median(np.linalg.norm(self.su, axis=1))) * float(span[0])
        lv = float(np.median(np.linalg.norm(self.sv, axis=1))) * float(span[1])
        return lu, lv

    def mean_edge(self) -> float:
        """Mean edge length of the base polygons [world units]."""
        p = self.positions[self.faces]
        return float(np.mean(np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2)))

    def in_object_space(self) -> "BaseMesh":
        """The same base before ``to_world`` (positions, tangents and extrusion mapped back
        by its inverse; normals are the extrusion directions made unit)."""
        m = np.asarray(self.to_world, np.float64)
        inv = np.linalg.inv(m[:3, :3])
        back = lambda v: v @ inv.T
        extrude = back(self.extrude)
        normals = extrude / np.maximum(np.linalg.norm(extrude, axis=1, keepdims=True), 1e-30)
        return BaseMesh(back(self.positions - m[:3, 3]), normals, self.uvs, self.faces,
                        back(self.su), back(self.sv), self.base, np.eye(4), extrude)

    def bbox(self, scale: float) -> tuple[np.ndarray, np.ndarray]:
        """Bounding box of the displacement volume (min, max), (3,) each."""
        pts = np.concatenate([self.positions, self.positions + scale * self.extrude])
        return pts.min(0), pts.max(0)


def make_base_mesh(base_name: str, params: dict, filename: str | None, resolution,
                   to_world: np.ndarray, owner: str = "slicing") -> BaseMesh:
    """The coarse base polygons (what the GPU draws) of a parametric base or a mesh file.

    Args:
        base_name: ``plane`` | ``sphere`` | ``cylinder`` | ``torus`` | ``mesh``.
        params: base parameters (radius, ...); filename: PLY/OBJ with UVs for ``mesh``.
        resolution: grid cells along u of a parametric base (v follows its aspect ratio).
        to_world: (4, 4) object-to-world matrix.
    """
    base = None
    if base_name == "mesh":
        if filename is None:
            raise ValueError(f"{owner}: base 'mesh' needs a 'filename' (PLY/OBJ with UVs)")
        pos, nrm, uvs, faces = (np.asarray(a, np.float64) for a in load_uv_mesh(filename, owner))
        faces = faces.astype(np.int64)
        # one direction per position (as `displaced`): the copies of a UV-seam or hard-edge
        # position extrude together, so the slices close over the seam
        direction = tessellate.welded_normals(pos, nrm, faces).astype(np.float64)
    else:
        base = surfaces.make_base(base_name, **params)
        nu, nv = tessellate.grid_resolution(base, resolution)
        t = tessellate.displace_parametric(base, None, 0.0, 0.0, nu, nv)
        pos, nrm, uvs = _columns(t.positions), _columns(t.normals), _columns(t.texcoords)
        faces = _columns(t.faces).astype(np.int64)
        direction = nrm
    m = np.asarray(to_world, np.float64)
    pos = pos @ m[:3, :3].T + m[:3, 3]
    extrude = direction @ m[:3, :3].T
    nrm = nrm @ np.linalg.inv(m[:3, :3])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm)) and np.all(np.isfinite(uvs))):
        raise ValueError(f"{owner}: the base has NaN/Inf positions, normals or UVs")
    # wind every face so that its normal agrees with the vertex normals (outward)
    inward = np.einsum("ij,ij->i", face_normals(pos, faces), nrm[faces].sum(1)) < 0
    faces[inward] = faces[inward][:, ::-1]
    su, sv = (a.astype(np.float64) for a in tessellate.vertex_frames(pos, nrm, uvs, faces)[:2])
    return BaseMesh(pos, nrm, uvs, faces, su, sv, base, m, extrude)


def face_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unnormalised geometric normals (p1 - p0) x (p2 - p0) of triangles ``faces`` (F, 3)
    of ``positions`` (V, 3): (F, 3)."""
    p = positions[faces]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def transform_pair(matrix: np.ndarray) -> tuple[mi.Transform4f, mi.Transform4f]:
    """(to_world, to_object) Dr.Jit transforms of a (4, 4) object-to-world matrix (the
    inverse taken in float64)."""
    m = np.asarray(matrix, np.float64)
    make = lambda a: mi.Transform4f(mi.ScalarTransform4f(mi.ScalarMatrix4f(a.astype(np.float32))))
    return make(m), make(np.linalg.inv(m))


#: Bytes per vertex and per triangle of a :class:`SliceMesh` (:meth:`SliceMesh.nbytes`).
VERTEX_BYTES, TRIANGLE_BYTES = (3 + 2 + 4 * 3) * 4, 12 + 4   # indices, the walks' step bits


@dataclass
class SliceMesh:
    """Triangles with the slice attributes (module docstring); all (V, k) float64."""

    positions: np.ndarray
    uvs: np.ndarray
    rw: np.ndarray
    bn: np.ndarray
    su: np.ndarray
    sv: np.ndarray
    faces: np.ndarray
    #: per triangle, the walks' step bits (:class:`LayerStack`; :func:`orthogonal_slices`),
    #: or None (a concatenation keeps none)
    steps: np.ndarray | None = None

    @property
    def triangles(self) -> int:
        return len(self.faces)

    def nbytes(self) -> int:
        """Bytes of the float32 vertex buffers, the uint32 indices and the walks' step bits
        (:class:`LayerStack`, 4 bytes a triangle)."""
        return len(self.positions) * VERTEX_BYTES + len(self.faces) * TRIANGLE_BYTES


def _vertex_data(bm: BaseMesh, h: float, ramp: float, wall: float, bottom: float = 0.0):
    """Base vertices lifted by ``h`` x scale (object units) with constant α value / flags."""
    v = len(bm.positions)
    rw = np.zeros((v, 3))
    rw[:, 0], rw[:, 1], rw[:, 2] = ramp, wall, bottom
    return bm.positions + h * bm.extrude, bm.uvs, rw, bm.normals, bm.su, bm.sv


def concat(parts: list[SliceMesh]) -> SliceMesh:
    """One mesh from several (indices shifted)."""
    offsets = np.cumsum([0] + [len(p.positions) for p in parts[:-1]])
    return SliceMesh(*(np.concatenate([getattr(p, k) for p in parts]) for k in
                       ("positions", "uvs", "rw", "bn", "su", "sv")),
                     np.concatenate([p.faces + o for p, o in zip(parts, offsets)]))


#: Floats per vertex of :func:`vertex_table` (a power of two: one packet gather).
TABLE_WIDTH = 16


def vertex_table(bm: BaseMesh) -> mi.Float:
    """The base vertices' slice attributes interleaved for packet gathers: per vertex
    ``TABLE_WIDTH`` floats (u, v, bn, su, sv, zero padding), (V * 16,) Float.  Every
    surface-aligned slice's vertices carry these (:func:`aligned_slices`)."""
    table = np.zeros((len(bm.positions), TABLE_WIDTH), np.float32)
    table[:, :11] = np.concatenate([bm.uvs, bm.normals, bm.su, bm.sv], 1)
    return mi.Float(table.ravel())


def prism_geometry(slices: "SliceScene", bm: BaseMesh, scale: float, n: int):
    """Direction a's ``n`` slices as layered copies for
    :func:`mi_displace.render.zbuffer.rasterise_layers`: slice 0's triangles (the base
    polygons; slice k's vertex k V + v and face k F + f, :func:`aligned_slices`) and the
    per-vertex offset between consecutive slices, (V,) Vector3f [world units]."""
    full = slices.geometry()
    V, F = len(bm.positions), len(bm.faces)
    base = dataclasses.replace(full, positions=dr.gather(mi.Point3f, full.positions, dr.arange(mi.UInt32, V)),
                               faces=dr.gather(mi.Vector3u, full.faces, dr.arange(mi.UInt32, F)))
    step = mi.Vector3f(*(mi.Float(c) for c in (bm.extrude * (scale / n)).astype(np.float32).T))
    dr.eval(base.positions, base.faces, step)
    return base, step


def _check_size(triangles: int, what: str) -> None:
    if triangles > MAX_SLICE_TRIANGLES:
        raise ValueError(f"slicing: {what} would need {triangles:,} slice triangles, more than "
                         f"the limit of {MAX_SLICE_TRIANGLES:,}; lower 'slices' or the base "
                         "'resolution', or set ratio_scaling=false")


def aligned_slices(bm: BaseMesh, scale: float, n: int) -> SliceMesh:
    """Direction a (§3.1): the base lifted to h = k / n, k = 0 ... n - 1 (h_α = k / n)."""
    _check_size(n * len(bm.faces), f"{n} surface-aligned slices")
    parts = []
    for k in range(n):  # n offset copies of the base (NumPy, one-off)
        pos, uvs, rw, bn, su, sv = _vertex_data(bm, scale * k / n, k / n, 0.0)
        parts.append(SliceMesh(pos, uvs, rw, bn, su, sv, bm.faces))
    return concat(parts)


#: Bits of a slice triangle's entry in a family's step table (:class:`LayerStack`): the
#: polygon of its stack one level up / down exists, and "up" lies on the side its geometric
#: normal points to.
STEP_UP, STEP_DOWN, STEP_UP_ALONG_NORMAL = 1, 2, 4


def step_bits(up: np.ndarray, down: np.ndarray, along: np.ndarray) -> np.ndarray:
    """A step table (:data:`STEP_UP` ...) from per-triangle booleans, (T,) uint32."""
    return (up * STEP_UP + down * STEP_DOWN + along * STEP_UP_ALONG_NORMAL).astype(np.uint32)


def aligned_steps(bm: BaseMesh, n: int) -> np.ndarray:
    """Direction a's step table: slice k's face k F + f (:func:`aligned_slices`) steps to
    k F + f +- F, up along the extrusion; the stack's last polygon is the top wall's face
    n F + f (:func:`volume_walls`, the walls following the slices in the family's mesh):
    a ray leaves the volume, or enters it, through it in closed form as well."""
    F = len(bm.faces)
    along = np.einsum("ij,ij->i", face_normals(bm.positions, bm.faces), bm.extrude[bm.faces].sum(1)) > 0
    k = np.repeat(np.arange(n + 1), F)
    return step_bits(k < n, k > 0, np.tile(along, n + 1))


@dataclass(init=False, eq=False)   # its fields a PyTree: a frozen raster frame finds the arrays
class LayerStack:
    """A slice family as stacks over the base triangles, for walks that step from a slice
    polygon to the adjacent one over the same base triangle in closed form
    (:func:`mi_displace.slicing.trace.first_passing_slice`): direction a's slices k and
    k +- 1 (faces k F + f, :func:`aligned_slices`), b's / c's iso-line quads at adjacent
    levels (quad q's triangles q and q + Q, the quads of one base triangle consecutive,
    :func:`orthogonal_slices`).

    Attributes:
        mesh: the family's ``mi.Mesh`` (slices, then walls), the triangles Embree holds.
        steps: per face its step bits (:data:`STEP_UP` ...; 0 on walls but a's top wall),
            (F',) UInt32: 4 bytes a triangle, the polygons' indices follow from the layout.
        stride: a's faces per slice F, or b's / c's quad count Q (opaque UInt32).
        quads: whether the polygons are quads (b, c), not triangles (a).
    """

    mesh: mi.Mesh
    steps: mi.UInt32
    stride: mi.UInt32
    quads: bool

    def __init__(self, steps: np.ndarray, slices: "SliceScene", stride: int, quads: bool):
        table = np.zeros(slices.triangles, np.uint32)
        table[: len(steps)] = steps   # the slices come first, the walls after
        self.mesh, self.steps = slices.mesh, mi.UInt32(table)
        self.stride, self.quads = dr.opaque(mi.UInt32, stride), quads

    def intersect(self, face: mi.UInt32, ray: mi.Ray3f, active: mi.Bool):
        """``ray`` against triangle ``face``: ``(hit, t, b1, b2)``, by Mitsuba's own test
        (``Mesh.ray_intersect_triangle``, Möller-Trumbore over the triangles Embree holds:
        the donut's raster frames are the BVH-only walk's bit for bit; a hand-written copy
        with direct gathers measured 0.94-0.99x the frame, not kept)."""
        pi = self.mesh.ray_intersect_triangle(face, ray, active)
        return active & pi.is_valid(), pi.t, pi.prim_uv.x, pi.prim_uv.y

    def next_face(self, face: mi.UInt32, fn: mi.Vector3f, d: mi.Vector3f, active: mi.Bool) -> mi.UInt32:
        """The first triangle of the polygon over the same base triangle that a ray along
        ``d`` meets next after triangle ``face`` (unit normal ``fn``): the next or the
        previous one of its stack; :data:`NO_FACE` at the stack's ends, on walls outside
        it and where not ``active``."""
        bits = dr.gather(mi.UInt32, self.steps, face, active)
        up = (dr.dot(d, fn) > 0) == ((bits & STEP_UP_ALONG_NORMAL) != 0)
        exists = (bits & dr.select(up, STEP_UP, STEP_DOWN)) != 0
        if self.quads:   # the quad's index: its first triangle's
            face = dr.select(face < self.stride, face, face - self.stride)
            nxt = dr.select(up, face + 1, face - 1)
        else:
            nxt = dr.select(up, face + self.stride, face - self.stride)
        return dr.select(active & exists, nxt, NO_FACE)

    def step(self, face: mi.UInt32, ray: mi.Ray3f, active: mi.Bool):
        """``ray`` against the polygon whose first triangle is ``face`` (:meth:`next_face`):
        ``(hit, t, b1, b2, triangle)``, the nearer of a quad's two triangles."""
        active = active & (face != NO_FACE)
        hit, t, u, v = self.intersect(face, ray, active)
        if not self.quads:
            return hit, t, u, v, face
        other = face + self.stride   # a quad's second triangle
        hit2, t2, u2, v2 = self.intersect(other, ray, active)
        second = hit2 & (~hit | (t2 < t))
        return (hit | hit2, dr.select(second, t2, t), dr.select(second, u2, u), dr.select(second, v2, v),
                dr.select(second, other, face))


def orthogonal_levels(bm: BaseMesh, axis: int, count: int) -> np.ndarray:
    """``count`` slice positions in texture space along ``axis`` (0: u, 1: v): the centres
    of ``count`` equal bins over the base's uv range (fixed in texture space)."""
    lo, hi = float(bm.uvs[:, axis].min()), float(bm.uvs[:, axis].max())
    return lo + (np.arange(count) + 0.5) * (hi - lo) / count


def _crossings(bm: BaseMesh, axis: int, levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per base triangle, the first of ``levels`` its ``axis`` range reaches and how many
    it spans, (F,) int each (an upper bound on its iso-line segments)."""
    val = bm.uvs[bm.faces][:, :, axis]                    # (F, 3)
    lo = np.searchsorted(levels, val.min(1), "left")
    hi = np.searchsorted(levels, val.max(1), "right")
    return lo, np.maximum(hi - lo, 0)


def family_bytes(bm: BaseMesh, axis: int | None, count: int) -> int:
    """Bytes of one slice family before it is built (an upper bound on the built
    :meth:`SliceMesh.nbytes`): ``axis`` None is direction a with ``count`` slices (each a
    copy of the base's V vertices and F faces); 0 / 1 are b / c at ``count`` levels (per
    iso-line segment a quad: 4 vertices, 2 triangles)."""
    if axis is None:
        return count * (len(bm.positions) * VERTEX_BYTES + len(bm.faces) * TRIANGLE_BYTES)
    segments = int(_crossings(bm, axis, orthogonal_levels(bm, axis, count))[1].sum())
    return segments * (4 * VERTEX_BYTES + 2 * TRIANGLE_BYTES)


def orthogonal_slices(bm: BaseMesh, scale: float, axis: int, levels: np.ndarray) -> SliceMesh:
    """Directions b (axis 0, iso-u) / c (axis 1, iso-v), §3.2: per base triangle, the
    segment of each iso-line through it extruded along the normals to h = 1 (a quad with
    h_α = 0 at the bottom, 1 at the top)."""
    lo, count = _crossings(bm, axis, levels)
    _check_size(2 * int(count.sum()), f"{len(levels)} orthogonal slices")
    face = np.repeat(np.arange(len(bm.faces)), count)
    rank = np.repeat(lo, count) + np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    level = levels[rank]
    f = bm.faces[face]
    ends, weights, found = np.zeros((len(face), 2, 2), np.int64), np.zeros((len(face), 2)), \
        np.zeros(len(face), np.int64)
    for e in range(3):  # edge (e, e+1): crossing parameter of the iso-line
        a, b = f[:, e], f[:, (e + 1) % 3]
        va, vb = bm.uvs[a, axis], bm.uvs[b, axis]
        denom = np.where(va != vb, vb - va, 1.0)
        w = (level - va) / denom
        hit = (va != vb) & (w >= 0) & (w < 1) & (found < 2)
        idx = np.nonzero(hit)[0]
        ends[idx, found[idx]] = np.stack([a[idx], b[idx]], 1)
        weights[idx, found[idx]] = w[idx]
        found[idx] += 1
    keep = found == 2
    ends, weights = ends[keep], weights[keep]
    face, rank = face[keep], rank[keep]

    def lerp(attr):  # (S, 2, k): attribute at the two segment ends
        return attr[ends[:, :, 0]] * (1 - weights[..., None]) + attr[ends[:, :, 1]] * weights[..., None]

    p, n, uv, su, sv, e = (lerp(x) for x in (bm.positions, bm.normals, bm.uvs, bm.su, bm.sv, bm.extrude))
    s = len(p)
    # quad vertices: A_bottom, B_bottom, B_top, A_top
    pos = np.stack([p[:, 0], p[:, 1], p[:, 1] + scale * e[:, 1], p[:, 0] + scale * e[:, 0]], 1)
    ramp = np.tile([0.0, 0.0, 1.0, 1.0], (s, 1))
    rw = np.zeros((s, 4, 3))
    rw[..., 0] = ramp
    pick = [0, 1, 1, 0]
    base = 4 * np.arange(s)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    # the step table (LayerStack): quad q's triangles q and s + q; its neighbours over the
    # same base triangle are the quads of the adjacent levels, "up" along the gradient of
    # the slicing coordinate on that triangle
    q = np.arange(s)
    b = bm.faces[face]
    P, c = bm.positions[b], bm.uvs[b][:, :, axis]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    N = np.cross(e1, e2)
    grad = (c[:, 1:2] - c[:, :1]) * np.cross(e2, N) + (c[:, 2:3] - c[:, :1]) * np.cross(N, e1)   # x |N|^2
    normal = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
    along = np.einsum("ij,ij->i", normal, grad) > 0
    same = lambda k: (k >= 0) & (k < s) & (face[np.clip(k, 0, s - 1)] == face) & (
        rank[np.clip(k, 0, s - 1)] == rank + np.sign(k - q))
    steps = np.tile(step_bits(same(q + 1), same(q - 1), along), 2)
    return SliceMesh(pos.reshape(-1, 3), uv[:, pick].reshape(-1, 2), rw.reshape(-1, 3),
                     n[:, pick].reshape(-1, 3), su[:, pick].reshape(-1, 3),
                     sv[:, pick].reshape(-1, 3), faces, steps)


def prism_shape(bm: BaseMesh, scale: float) -> dict:
    """How far the base's prisms (each base triangle extruded to ``scale``) are from
    straight ones, which :class:`MeshCoordinates` inverts by iteration: per triangle the
    largest angle between its corners' extrusion directions [degrees] and the largest
    distance of a side quad's fourth corner from the plane of the other three [x the
    maximum displacement] (0 and 0 where a point's (u, v, h) is linear in the prism).

    Returns:
        ``{"spread_deg": (median, 95 %, max), "twist": (median, 95 %, max),
        "spread_over_1deg": fraction of triangles}``.
    """
    e = bm.extrude / np.maximum(np.linalg.norm(bm.extrude, axis=1, keepdims=True), 1e-30)
    f, g = bm.faces, np.roll(bm.faces, -1, 1)                 # corner i and i + 1, (F, 3)
    spread = np.degrees(np.arccos(np.clip((e[f] * e[g]).sum(2), -1, 1))).max(1)
    world = bm.world_scale(scale)
    a, b = bm.positions[f], bm.positions[g]
    n = np.cross(b - a, b + world * e[g] - a)
    n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-30)
    twist = np.abs((world * e[f] * n).sum(2)).max(1) / world
    pct = lambda x: tuple(float(v) for v in np.percentile(x, [50, 95, 100]))
    return {"spread_deg": pct(spread), "twist": pct(twist), "spread_over_1deg": float((spread > 1).mean())}


def boundary_edges(bm: BaseMesh) -> np.ndarray:
    """(E, 3) open edges (a, b, opposite vertex) of the base; vertices welded by position
    (seam twins of closed parametric bases are not boundaries)."""
    key = np.round(bm.positions / max(1e-9, bm.mean_edge() * 1e-4)).astype(np.int64)
    _, weld = np.unique(key, axis=0, return_inverse=True)
    weld = weld.ravel()
    f = bm.faces
    edges = np.concatenate([f[:, [0, 1, 2]], f[:, [1, 2, 0]], f[:, [2, 0, 1]]])
    w = np.sort(weld[edges[:, :2]], axis=1)
    area = np.linalg.norm(np.cross(bm.positions[f[:, 1]] - bm.positions[f[:, 0]],
                                   bm.positions[f[:, 2]] - bm.positions[f[:, 0]]), axis=1)
    valid = np.tile(area > 0, 3) & (w[:, 0] != w[:, 1])
    _, inv, counts = np.unique(w, axis=0, return_inverse=True, return_counts=True)
    return edges[valid & (counts[inv.ravel()] == 1)]


def volume_walls(bm: BaseMesh, scale: float) -> SliceMesh:
    """The boundary of the displacement volume, slightly outside the slices: top at
    h = 1 + ε, bottom at h = -ε (wound inwards), quads on the open edges; wall flag 1 and
    outward normals, so a ray enters where it meets a wall's front face."""
    lo_box, hi_box = bm.bbox(scale)   # the reach of step_past's offset (relative: any size)
    reach = float(np.linalg.norm(hi_box - lo_box) + np.max(np.abs(np.concatenate([lo_box, hi_box]))))
    eps = max(WALL_EPS, 4 * SPAWN_EPS * reach / bm.world_scale(scale))
    top = SliceMesh(*_vertex_data(bm, scale * (1 + eps), 1.0, 1.0), bm.faces)
    bottom = SliceMesh(*_vertex_data(bm, -scale * eps, 0.0, 1.0, 1.0), bm.faces[:, ::-1])
    parts = [top, bottom]
    edges = boundary_edges(bm)
    if len(edges):
        a, b, c = edges[:, 0], edges[:, 1], edges[:, 2]
        lo, hi = -eps * scale, (1 + eps) * scale
        corners = [(a, lo), (b, lo), (b, hi), (a, hi)]
        pos = np.stack([bm.positions[i] + h * bm.extrude[i] for i, h in corners], 1)
        normal = np.cross(pos[:, 1] - pos[:, 0], pos[:, 3] - pos[:, 0])
        inward = np.einsum("ij,ij->i", normal, bm.positions[c] - bm.positions[a]) > 0
        pick = np.stack([a, b, b, a], 1)
        s = len(edges)
        rw = np.zeros((s, 4, 3))
        rw[..., 1] = 1.0
        base = 4 * np.arange(s)[:, None]
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
        faces[np.tile(inward, 2)] = faces[np.tile(inward, 2)][:, ::-1]
        parts.append(SliceMesh(pos.reshape(-1, 3), bm.uvs[pick].reshape(-1, 2),
                               rw.reshape(-1, 3), bm.normals[pick].reshape(-1, 3),
                               bm.su[pick].reshape(-1, 3), bm.sv[pick].reshape(-1, 3), faces))
    return concat(parts)


def fill_mesh(mesh: mi.Mesh, sm: SliceMesh) -> None:
    """Write the triangles of ``sm`` into a ``mi.Mesh`` created with its vertex / face
    counts (texcoords on, no vertex normals: the shading frame is the face's)."""
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(sm.positions.astype(np.float32).ravel())
    params["vertex_texcoords"] = mi.Float(sm.uvs.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(sm.faces.astype(np.uint32).ravel())
    params.update()


@dataclass(init=False, eq=False)   # its fields a PyTree: a frozen raster frame finds the arrays
class SliceScene:
    """Slice polygons in a scene of their own (not seen by Mitsuba's integrators, so their
    shadow rays meet only the volume's walls) with the slice attributes as Dr.Jit buffers,
    interpolated from preliminary intersections (cheaper than Mitsuba's full interaction).

    Attributes: scene, mesh; faces (3 x UInt32 per face); uv, ramp, bn, su, sv (per vertex);
    flags (per face: 1 wall, 2 bottom wall); fn (per-face unit geometric normal); length
    (the bounding-box diagonal [world units], the size the walks' offsets are relative to;
    an opaque Float of width 1).
    """

    scene: mi.Scene
    faces: mi.UInt32
    uv: mi.Float
    ramp: mi.Float
    bn: mi.Float
    su: mi.Float
    sv: mi.Float
    flags: mi.UInt32
    fn: mi.Float
    length: mi.Float

    def __init__(self, sm: SliceMesh, name: str):
        mesh = mi.Mesh(name, len(sm.positions), len(sm.faces), has_vertex_normals=False,
                       has_vertex_texcoords=True)
        fill_mesh(mesh, sm)
        self.scene = mi.load_dict({"type": "scene", "slices": mesh})
        self.mesh, self._geometry = mesh, None
        f32 = lambda a: mi.Float(np.ascontiguousarray(a, np.float32).ravel())
        self.faces = mi.UInt32(sm.faces.astype(np.uint32).ravel())
        self.uv, self.ramp = f32(sm.uvs), f32(sm.rw[:, 0])
        self.bn, self.su, self.sv = f32(sm.bn), f32(sm.su), f32(sm.sv)
        first = sm.rw[sm.faces[:, 0]]
        self.flags = mi.UInt32((first[:, 1] > 0.5).astype(np.uint32) + 2 * (first[:, 2] > 0.5).astype(np.uint32))
        fn = face_normals(sm.positions, sm.faces)
        self.fn = f32(fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30))
        self.triangles = len(sm.faces)
        # opaque: a kernel parameter, so a rebuild at a new scale reuses the compiled kernels
        self.length = dr.opaque(mi.Float, float(np.linalg.norm(sm.positions.max(0) - sm.positions.min(0))))

    def geometry(self) -> zbuffer.Geometry:
        """The triangles for the z-buffer (:mod:`mi_displace.slicing.rasterised`), built once."""
        if self._geometry is None:
            self._geometry = zbuffer.gather_geometry([self.mesh])
        return self._geometry

    def corners(self, prim: mi.UInt32, active):
        """The three vertex indices of faces ``prim``."""
        return [dr.gather(mi.UInt32, self.faces, 3 * prim + k, active) for k in range(3)]

    def lerp(self, buf: mi.Float, dim: int, idx, bary, active):
        """Barycentric interpolation of a per-vertex buffer with ``dim`` components."""
        b0, b1 = bary
        w = (1 - b0 - b1, b0, b1)
        out = [dr.zeros(mi.Float, dr.width(b0)) for _ in range(dim)]
        for v, wk in zip(idx, w):
            for c in range(dim):
                out[c] += wk * dr.gather(mi.Float, buf, dim * v + c, active)
        return out

    def face_normal(self, prim, active) -> mi.Vector3f:
        return mi.Vector3f(*[dr.gather(mi.Float, self.fn, 3 * prim + c, active) for c in range(3)])

    def frame(self, prim, bary, active):
        """(bn, su, sv) interpolated at a hit (base normal unnormalised, tangents)."""
        idx = self.corners(prim, active)
        return tuple(mi.Vector3f(*self.lerp(b, 3, idx, bary, active)) for b in (self.bn, self.su, self.sv))


@dataclass(init=False, eq=False)   # its fields a PyTree: a frozen raster frame finds the arrays
class MeshCoordinates:
    """(u, v, h) of world points inside a mesh base's displacement volume, for the screen-
    space slices (§3.3) where a parametric base has :func:`base_coordinates`.

    A point p of the volume is q + h scale e(q): q on a base triangle, e the extrusion
    interpolated there (:attr:`BaseMesh.extrude`).  Inverted by a fixed-point iteration:
    from p along -e to the base (a ray query against the base triangles), e re-read at the
    foot q, :data:`ITERATIONS` times; h is the distance to the foot over scale |e|.  Exact
    in one step where e is the same over the prism (a flat base); elsewhere each step
    takes the foot closer to the prism's (the spread of e over a triangle is
    :func:`prism_shape`'s)."""

    ITERATIONS = 4
    base: "SliceScene"
    scale: mi.Float

    def __init__(self, bm: BaseMesh, scale: float):
        v = len(bm.positions)
        sm = SliceMesh(bm.positions, bm.uvs, np.zeros((v, 3)), bm.extrude, bm.su, bm.sv, bm.faces)
        self.base = SliceScene(sm, "screen_base")
        self.nbytes = sm.nbytes()   # of the base triangles' buffers
        self.scale = dr.opaque(mi.Float, scale)   # object units (e is world per unit scale)

    def __call__(self, p: mi.Point3f, e: mi.Vector3f, active: mi.Bool, coherent: bool = False):
        """(uv, h, inside, (e, su, sv) at the foot) of world points ``p``, iterating from
        the extrusion guess ``e`` (world, any length); ``inside``: a foot was found.
        ``coherent``: neighbouring lanes hold neighbouring points (a raster frame's samples),
        the queries use Embree's coherent flag (the same feet)."""
        base = self.base
        for _ in range(self.ITERATIONS):
            ray = mi.Ray3f(p, -dr.normalize(e))
            pi = base.scene.ray_intersect_preliminary(ray, coherent, active=active)
            ok = active & pi.is_valid()
            bary = (pi.prim_uv.x, pi.prim_uv.y)
            foot, su, sv = base.frame(pi.prim_index, bary, ok)
            length = dr.norm(e)
            e = dr.select(ok, foot, e)
        uv = mi.Point2f(*base.lerp(base.uv, 2, base.corners(pi.prim_index, ok), bary, ok))
        h = pi.t / (self.scale * dr.maximum(length, 1e-30))
        return uv, h, ok, (e, su, sv)


# ---------------------------------------------------------------------------------------
# slice counts (§3.4)

def orthogonal_counts(bm: BaseMesh, scale: float, n: int, ratio_scaling: bool) -> tuple[int, int]:
    """Slices of directions b and c for ``n`` surface-aligned slices.

    With ``ratio_scaling`` (§3.4) the orthogonal slices get the spacing of the aligned ones
    (scale / n): n x edge length / max displacement per base polygon edge, so edge 2 and
    displacement 0.5 give 4x the slices.  Without it, n slices per base polygon edge.
    Lengths are measured in object space: ``to_world`` (a non-uniform scale too) moves the
    slices with the surface but never changes how many there are.
    """
    obj = bm.in_object_space()
    counts = []
    for length in obj.extent():
        if ratio_scaling:   # relative tolerance: float32 matrices give 80.000001 for 80
            c = math.ceil(n * length / obj.world_scale(scale) * (1 - 1e-6))
        else:
            c = n * max(1, round(length / obj.mean_edge()))
        counts.append(int(min(max(c, 1), 1 << 20)))
    return counts[0], counts[1]


def projected_size(sensor: mi.Sensor, bbox: tuple[np.ndarray, np.ndarray], length: float) -> float:
    """Pixels that ``length`` world units span on ``sensor``'s film at the point of ``bbox``
    nearest to the camera (perpendicular to the view, the worst case)."""
    to_world = sensor.world_transform()
    origin = np.array(to_world @ mi.ScalarPoint3f(0, 0, 0), np.float64).ravel()
    lo, hi = bbox
    nearest = np.clip(origin, lo, hi)
    centre = 0.5 * (lo + hi)
    point = nearest if np.linalg.norm(nearest - origin) > 1e-6 * np.linalg.norm(hi - lo) else centre
    view = point - origin
    view /= max(np.linalg.norm(view), 1e-30)
    up = np.array(to_world @ mi.ScalarVector3f(0, 1, 0), np.float64).ravel()
    up -= np.dot(up, view) * view
    up /= max(np.linalg.norm(up), 1e-30)

    def pixel(p):
        it = dr.zeros(mi.Interaction3f)
        it.p = mi.Point3f(*[float(x) for x in p])
        ds, _ = sensor.sample_direction(it, mi.Point2f(0.5))
        return np.array([ds.uv.x[0], ds.uv.y[0]])  # film pixel coordinates

    return float(np.linalg.norm(pixel(point + length * up) - pixel(point)))


#: ``slices="auto"``: surface-aligned slices per pixel of the maximum displacement's
#: projected size (adjacent slices at most half a pixel apart on screen).
SLICES_PER_PIXEL = 2


def sensor_counts(sensor: mi.Sensor, bm: BaseMesh, scale: float, counts: tuple[int, int]) -> tuple[int, int]:
    """The orthogonal slice counts ``counts`` (b, c) bounded by what ``sensor`` resolves:
    at most :data:`SLICES_PER_PIXEL` slices per pixel of the base's world length along u /
    v (:meth:`BaseMesh.extent`) projected at the volume's point nearest to the camera
    (:func:`projected_size`), the spacing rule of :func:`auto_slices` applied to b and c."""
    bbox = bm.bbox(scale)
    return tuple(min(c, max(1, math.ceil(SLICES_PER_PIXEL * projected_size(sensor, bbox, length) - 1e-6)))
                 for c, length in zip(counts, bm.extent()))


def auto_slices(sensor: mi.Sensor, bbox, scale: float) -> int:
    """§3.4 'auto': :data:`SLICES_PER_PIXEL` surface-aligned slices per pixel of the
    maximum displacement's projected size on the scene's sensor, in [1, MAX_SLICES].

    Half a pixel between adjacent slices: the front-most passing fragment lies below the
    true surface by up to one spacing, so its position (and the texel it shades) is then
    off by at most half a pixel, the reach of the pixel's own sample.  Measured
    (docs/slicing.md): this lands at the elbow of the error-vs-slices curve on the donut
    and on the brick plane at 30, 60 and 85 degrees; one slice per pixel stopped well
    before it (FLIP 0.131 vs 0.114 on the donut at 128^2)."""
    pixels = projected_size(sensor, bbox, scale)   # scale: world units here
    return int(min(max(math.ceil(SLICES_PER_PIXEL * pixels - 1e-6), 1), MAX_SLICES))


# ---------------------------------------------------------------------------------------
# exact (u, v, height) of a point over a parametric base (screen-space slices, §3.3; a
# mesh base's: MeshCoordinates)

def base_coordinates(base: surfaces.BaseSurface, p: mi.Point3f):
    """(u, v, signed distance along the normal, in_domain) of object-space points ``p``
    over ``base`` (the closest base point; Dr.Jit arrays)."""
    name = base.name
    if name == "plane":
        u, v, dist = 0.5 * (p.x + 1), 0.5 * (p.y + 1), p.z
        inside = (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
        return u, v, dist, inside
    phi = dr.atan2(p.y, p.x)
    u = dr.select(phi < 0, phi + dr.two_pi, phi) / dr.two_pi
    rho = dr.sqrt(p.x * p.x + p.y * p.y)
    if name == "sphere":
        r = dr.norm(p)
        v = dr.acos(dr.clip(p.z / dr.maximum(r, 1e-30), -1.0, 1.0)) / dr.pi
        return u, v, r - base.radius, dr.full(mi.Bool, True, dr.width(r))
    if name == "cylinder":
        v = p.z / base.length
        return u, v, rho - base.radius, (v >= 0) & (v <= 1)
    if name == "torus":
        q = rho - base.major_radius
        psi = dr.atan2(p.z, q)
        v = dr.select(psi < 0, psi + dr.two_pi, psi) / dr.two_pi
        return u, v, dr.sqrt(q * q + p.z * p.z) - base.minor_radius, dr.full(mi.Bool, True, dr.width(q))
    raise ValueError(f"slicing: no closed-form base coordinates for base {name!r}")
