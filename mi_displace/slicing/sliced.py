"""A displaced surface drawn as slices through its displacement volume (§3).

:class:`SlicedVolume` owns the slice polygons of each slicing direction as private scenes
(:class:`mi_displace.slicing.geometry.SliceScene`) and answers, per ray, where the front-
most slice fragment that passes the α-test lies (:meth:`SlicedVolume.find`) and whether the
slices occlude a light from a point (:meth:`SlicedVolume.occluded`).

Directions: ``a`` (surface-aligned, §3.1), ``b`` / ``c`` (orthogonal along u / v, §3.2),
``best`` (per ray the one of a, b, c whose slices face the ray most, §3.2: "the slicing
direction that is most perpendicular to the viewer"), ``screen`` (§3.3: planes
perpendicular to the ray, ``p . d = k delta`` in object space, clipped to the displacement
volume: a parametric base's exact coordinates, a mesh base's by ray queries,
:class:`mi_displace.slicing.geometry.MeshCoordinates`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.texture_height import height_function
from mi_displace.slicing import geometry as geo
from mi_displace.slicing.trace import ALPHA_TESTS, alpha_test, first_passing_plane, first_passing_slice

DIRECTIONS = ("a", "b", "c", "best", "screen")
#: Offset of the self-shadow rays [slice spacings].
SHADOW_BIAS = 2.0
#: Distance the self-shadow rays start along the light direction [slice spacings].
SHADOW_LEAVE = 0.05
#: The self-shadow walk's query bound per family: each query after the first looks this
#: many times the previous step ahead (:func:`~mi_displace.slicing.trace.first_passing_slice`'s
#: ``reach``; the same walk, bit for bit).  Measured on the donut's walk alone at 512^2
#: (best): 0.92-0.93x with b and c bounded, the frame 0.95-0.97x (scripts/constant_ab.py);
#: a's few large slices gain nothing (1.006x).
SHADOW_REACH = {"a": None, "b": 1.5, "c": 1.5}
FAMILIES = {"a": ("a",), "b": ("b",), "c": ("c",), "best": ("a", "b", "c"), "screen": ()}


@dataclass
class Hit:
    """The passing fragment of each ray (Dr.Jit, one entry per ray).

    Attributes: found; p (world point); uv; n, su, sv (base normal and tangents there);
    offset_n (the geometric normal of the slice polygon, for spawning rays off it).
    """

    found: mi.Bool
    p: mi.Point3f
    uv: mi.Point2f
    n: mi.Vector3f
    su: mi.Vector3f
    sv: mi.Vector3f

    def fields(self) -> tuple:
        """(found, p, uv, n, su, sv)."""
        return self.found, self.p, self.uv, self.n, self.su, self.sv

    def select(self, mask: mi.Bool, other: "Hit") -> "Hit":
        """Per lane ``self`` where ``mask``, else ``other``."""
        return Hit(*(dr.select(mask, a, b) for a, b in zip(self.fields(), other.fields())))


@dataclass(init=False, eq=False)   # its fields a PyTree: a frozen raster frame finds the arrays
class SlicedVolume:
    """The slices of one displaced surface.

    Args:
        bm: base polygons (world space). height: texture whose ``eval_1`` in [0, 1] is the
            α channel D (values outside are clipped). scale: maximum displacement [world].
        slices: N, surface-aligned slices (the orthogonal counts follow, see
            :func:`mi_displace.slicing.geometry.orthogonal_counts`).
        direction: one of :data:`DIRECTIONS`; alpha: one of ``basic`` / ``ramp``.
        ratio_scaling: §3.4 orthogonal slice counts; opaque_base: the base polygons are
            drawn too (opaque where every slice fails, e.g. under zero heights).
        sensor: bounds the b / c counts by what it resolves
            (:func:`mi_displace.slicing.geometry.sensor_counts`); None: unbounded.
        max_memory_mb: the slice buffers' bound [MB]; the families' size is predicted
            (:func:`mi_displace.slicing.geometry.family_bytes`) and a larger one refused
            before anything is built.  None: unbounded.
    """

    # the fields: what a frame's kernels read (Dr.Jit arrays, scenes, textures), found by a
    # frozen raster frame; a rebuild (a new ``scale`` or ``slices``) makes new scenes, so a
    # frozen frame records again, and the sizes the kernels read are opaque arrays
    height: mi.Texture
    families: dict
    walls_scene: geo.SliceScene
    frame: object            # the rasterised FrameBuffer of the current raster frame, or None
    coherent: bool
    to_world: mi.Transform4f
    to_object: mi.Transform4f
    delta: mi.Float | None
    mesh_coords: geo.MeshCoordinates | None
    kernel_scale: mi.Float
    shadow_offsets: tuple

    def __init__(self, bm: geo.BaseMesh, height: mi.Texture, scale: float, slices: int,
                 direction: str, alpha: str, ratio_scaling: bool = True, opaque_base: bool = False,
                 sensor: mi.Sensor | None = None, max_memory_mb: float | None = None):
        if direction not in DIRECTIONS:
            raise ValueError(f"slicing: 'direction' must be one of {', '.join(DIRECTIONS)}, got {direction!r}")
        if alpha not in ALPHA_TESTS:
            raise ValueError(f"slicing: 'alpha' must be one of {', '.join(ALPHA_TESTS)}, got {alpha!r}")
        if not (isinstance(slices, int) and 1 <= slices <= geo.MAX_SLICES):
            raise ValueError(f"slicing: 'slices' must be an integer in [1, {geo.MAX_SLICES}] or "
                             f"'auto', got {slices!r}")
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"slicing: 'scale' must be a positive number, got {scale!r}")
        self.bm, self.height, self.scale, self.n = bm, height, float(scale), slices
        self.world_scale = bm.world_scale(scale)   # the maximum displacement in world units
        self.direction, self.alpha, self.opaque_base = direction, alpha, bool(opaque_base)
        self._grad = height_function(height, 1e-3)
        cb, cc = geo.orthogonal_counts(bm, scale, slices, ratio_scaling)
        if sensor is not None and direction != "screen":
            cb, cc = geo.sensor_counts(sensor, bm, scale, (cb, cc))
        self.counts = {"a": slices, "b": cb, "c": cc}
        axes = {"a": None, "b": 0, "c": 1}
        need = {f: geo.family_bytes(bm, axes[f], self.counts[f]) for f in FAMILIES[direction]}
        if max_memory_mb is not None and sum(need.values()) > max_memory_mb * 1e6:
            raise ValueError(
                f"slicing: the slices would need {sum(need.values()) / 1e6:,.2f} MB ("
                + ", ".join(f"{f}: {self.counts[f]} slices, {b / 1e6:,.2f} MB" for f, b in need.items())
                + f"), more than max_memory_mb={max_memory_mb:g}; lower 'slices' or 'resolution', "
                "reference the 'sensor' (bounds b / c by its pixels), or raise 'max_memory_mb'")
        walls = geo.volume_walls(bm, scale)
        self.walls = walls
        self.families, tris, nbytes = {}, 0, walls.nbytes()
        family_stats = {}
        for fam in FAMILIES[direction]:
            start = time.perf_counter()
            if axes[fam] is None:
                sm = geo.aligned_slices(bm, scale, slices)
            else:
                sm = geo.orthogonal_slices(bm, scale, axes[fam], geo.orthogonal_levels(bm, axes[fam], self.counts[fam]))
            tris += sm.triangles
            nbytes += sm.nbytes()
            # the walk's polygon bound, opaque: the b / c counts follow the scale; the walks
            # step over the same base triangle in closed form (geo.LayerStack)
            scene = geo.SliceScene(geo.concat([sm, walls]), f"slices_{fam}")
            if axes[fam] is None:
                stack = geo.LayerStack(geo.aligned_steps(bm, slices), scene, len(bm.faces), False)
            else:
                stack = geo.LayerStack(sm.steps, scene, sm.triangles // 2, True)
            self.families[fam] = (scene, dr.opaque(mi.UInt32, 4 * self.counts[fam] + 64), stack)
            family_stats[fam] = {"slices": self.counts[fam], "triangles": int(sm.triangles),
                                 "bytes": int(sm.nbytes()), "build_s": time.perf_counter() - start}
        self.walls_scene = geo.SliceScene(walls, "walls")   # also the proxy's face frames
        #: direction a for the rasteriser (mi_displace.slicing.rasterised): the base vertices'
        #: attributes, slice 0's triangles and the step between slices
        self.vertex_table = self.prisms = None
        if "a" in FAMILIES[direction]:
            self.vertex_table = geo.vertex_table(bm)
            self.prisms = geo.prism_geometry(self.families["a"][0], bm, scale, slices)
        #: the slices rasterised for the current raster frame (mi_displace.slicing.rasterised)
        self.frame = None
        #: whether the lanes now rendered are a raster frame's samples (pixel order, one
        #: per pixel or aa x aa): its view rays and its self-shadow rays (from neighbouring
        #: points towards the same light) query the slices as coherent rays
        #: (:func:`~mi_displace.slicing.trace.first_passing_slice`: the same polygons; the
        #: donut's raster frame at 512^2, scripts/coherent_ab.py with WHICH=slicing:
        #: 0.75-0.78x (a), 0.86-0.89x (best), 0.68-0.69x (screen); a path tracer's
        #: scattered shadow rays are slower so: 1.36x)
        self.coherent = False
        #: object <-> world (Dr.Jit transforms): the family choice and the screen-space
        #: planes are made in object space, so any ``to_world`` moves them with the surface
        self.to_world, self.to_object = geo.transform_pair(bm.to_world)
        self.delta = self.mesh_coords = None
        if direction == "screen":
            self.delta = dr.opaque(mi.Float, self.scale / slices)   # object units
            #: a mesh base's (u, v, h) of a point (a parametric one's are closed-form)
            self.mesh_coords = geo.MeshCoordinates(bm, self.scale) if bm.base is None else None
            nbytes += self.mesh_coords.nbytes if self.mesh_coords is not None else 0
        #: the sizes the kernels read, opaque (kernel parameters, not traced constants): a
        #: rebuild at a new ``scale`` reuses the compiled kernels.  ``scale`` [object units];
        #: the self-shadow rays' offsets along the normal and the light [world units]
        self.kernel_scale = dr.opaque(mi.Float, self.scale)
        self.shadow_offsets = (dr.opaque(mi.Float, SHADOW_BIAS * self.spacing()),
                               dr.opaque(mi.Float, SHADOW_LEAVE * self.spacing()))
        self.stats = {"slices": slices, "direction": direction, "alpha": alpha,
                      "slices_b": cb, "slices_c": cc, "ratio_scaling": bool(ratio_scaling),
                      "opaque_base": self.opaque_base,
                      "slice_triangles": int(tris), "wall_triangles": int(walls.triangles),
                      "bytes": int(nbytes), "base_faces": int(len(bm.faces))}
        if direction != "screen":
            self.stats["slices_used"] = {f: self.counts[f] for f in FAMILIES[direction]}
            self.stats["families"] = family_stats

    # -- the α channel -------------------------------------------------------------------
    def D(self, uv: mi.Point2f) -> mi.Float:
        """Displacement in [0, 1] at ``uv`` (the α channel of the displacement texture)."""
        si = dr.zeros(mi.SurfaceInteraction3f, dr.width(uv))
        si.uv = uv
        return dr.clip(self.height.eval_1(si), 0.0, 1.0)

    def _test(self, uv, h_alpha):
        return alpha_test(self.alpha, self.D(uv), h_alpha)

    # -- families ------------------------------------------------------------------------
    def choose(self, d: mi.Vector3f, n: mi.Vector3f, su: mi.Vector3f, sv: mi.Vector3f) -> mi.UInt32:
        """Per ray, index into ``FAMILIES[direction]`` of the family to use: for ``best`` the
        one whose slice normal (n, grad u, grad v) is most parallel to ``d`` (§3.2), measured
        in object space."""
        fams = FAMILIES[self.direction]
        if len(fams) == 1:
            return dr.zeros(mi.UInt32, dr.width(d))
        # in object space: under a non-uniform to_world the world angles would pick
        # another family than the untransformed surface does
        inv = self.to_object
        d, n, su, sv = inv @ mi.Vector3f(d), inv @ mi.Normal3f(n), inv @ su, inv @ sv
        e, f, g = dr.dot(su, su), dr.dot(su, sv), dr.dot(sv, sv)
        grad_u, grad_v = g * su - f * sv, e * sv - f * su   # parallel to grad u, grad v
        cos = [dr.abs(dr.dot(d, dr.normalize(x))) for x in (n, grad_u, grad_v)]
        best = dr.select(cos[1] > cos[0], 1, 0)
        best_cos = dr.maximum(cos[0], cos[1])
        return mi.UInt32(dr.select(cos[2] > best_cos, 2, best))

    def find(self, origin: mi.Point3f, d: mi.Vector3f, choice: mi.UInt32, active: mi.Bool,
             t_floor: mi.Float | None = None, coherent: bool = False, reach: dict | None = None):
        """Front-most passing fragment along ``origin + t d`` (t >= 0) inside the first
        stretch of displacement volume the ray meets (up to the wall it leaves through);
        with ``t_floor`` (the distance of the proxy wall walked for), the first stretch
        not left before it (:func:`~mi_displace.slicing.trace.first_passing_slice`).

        ``coherent``: query the slices as coherent rays; ``reach`` (per family, e.g.
        :data:`SHADOW_REACH`): bound each query by the previous step (both
        :func:`~mi_displace.slicing.trace.first_passing_slice`).

        Returns:
            :class:`Hit` (``found`` False where every slice failed the test).
        """
        n = dr.width(origin)
        active = mi.Bool(active)
        if self.direction == "screen":
            return self._find_screen(origin, d, active, t_floor, coherent)
        found = dr.zeros(mi.Bool, n)
        hit = Hit(found, mi.Point3f(origin), dr.zeros(mi.Point2f, n), dr.zeros(mi.Vector3f, n),
                  dr.zeros(mi.Vector3f, n), dr.zeros(mi.Vector3f, n))
        for index, fam in enumerate(FAMILIES[self.direction]):
            slices, max_iter, stack = self.families[fam]
            mine = active & (choice == index)
            ok, t, prim, bary, *_ = first_passing_slice(slices, origin, d, self._test, mine,
                                                        max_iter, self.opaque_base, t_floor, coherent,
                                                        (reach or {}).get(fam), stack)
            idx = slices.corners(prim, ok)
            uv = mi.Point2f(*slices.lerp(slices.uv, 2, idx, bary, ok))
            bn, su, sv = slices.frame(prim, bary, ok)
            hit.found |= ok
            hit.p = dr.select(ok, origin + t * d, hit.p)
            hit.uv = dr.select(ok, uv, hit.uv)
            hit.n, hit.su, hit.sv = (dr.select(ok, new, old) for new, old in
                                     ((bn, hit.n), (su, hit.su), (sv, hit.sv)))
        hit.n = dr.normalize(hit.n)
        return hit

    def find_view(self, origin: mi.Point3f, d: mi.Vector3f, choice: mi.UInt32,
                  active: mi.Bool, t_floor: mi.Float) -> Hit:
        """:meth:`find` (from the proxy wall at ``t_floor``) for rays that may be the
        current frame's sample rays: those take their fragment from the rasterised slices
        (:attr:`frame`, set by the raster integrator), the others walk (as coherent rays
        during a raster frame, :attr:`coherent`)."""
        if self.frame is None:
            return self.find(origin, d, choice, active, t_floor, self.coherent)
        use, drawn = self.frame.lookup(origin, d, active)
        walk = mi.Bool(active) & ~use
        # under a symbolic if: a SIMD packet of frame samples only jumps over the walk
        walked = dr.if_stmt((origin, d, choice, walk, t_floor), walk,
                            lambda o, w, c, m, f: self.find(o, w, c, m, f, self.coherent).fields(),
                            lambda o, w, c, m, f: drawn.fields(), label="slicing_walk")
        return drawn.select(use, Hit(*walked))

    def _find_screen(self, origin, d, active, t_floor=None, coherent=False):
        """§3.3: planes perpendicular to the ray, p . d = k delta, clipped to the volume (a
        parametric base's exact coordinates; a mesh base's by :attr:`mesh_coords`, from the
        extrusion where the ray enters the volume).  Made in object space (p, d, delta = scale / N there), so
        that ``to_world`` moves them with the surface; the ray parameter t is shared."""
        never = lambda uv, h: dr.zeros(mi.Bool, dr.width(h))
        *_, t_in, t_out, bottom = first_passing_slice(self.walls_scene, origin, d, never, active, 64,
                                                      t_floor=t_floor, coherent=coherent)
        t_out = dr.select(dr.isinf(t_out), t_in, t_out)
        base, mesh = self.bm.base, self.mesh_coords
        o_obj, d_obj = self.to_object @ mi.Point3f(origin), self.to_object @ mi.Vector3f(d)
        if mesh is not None:   # the fixed point's first guess: the extrusion where the ray enters
            pi = self.walls_scene.scene.ray_intersect_preliminary(mi.Ray3f(origin, d), coherent, active=active)
            guess = self.walls_scene.frame(pi.prim_index, (pi.prim_uv.x, pi.prim_uv.y), active)[0]

        def coords(p):   # p: object space; the frame (n, su, sv) [world] on a mesh
            if mesh is not None:
                return mesh(self.to_world @ mi.Point3f(p), guess, active, coherent)
            u, v, dist, inside = geo.base_coordinates(base, p)
            return mi.Point2f(u, v), dist / self.kernel_scale, inside, None

        def test(p):
            uv, h, inside, _ = coords(p)
            return inside & (h >= 0) & (h <= 1) & alpha_test(self.alpha, self.D(uv), h)

        steps = int(2 * self.n * 200) + 64   # grazing rays: path length / delta
        found, t = first_passing_plane(o_obj, d_obj, dr.normalize(d_obj), 0.0, self.delta,
                                       t_in, t_out, test, active, steps)
        if self.opaque_base:
            t = dr.select(found, t, t_out)
            found |= active & bottom
        uv, _, _, frame = coords(o_obj + t * d_obj)
        if frame is not None:
            n, su, sv = frame
            return Hit(found, mi.Point3f(origin + t * d), uv, dr.normalize(n), su, sv)
        s = base.sample(uv.x, uv.y)
        n = dr.normalize(self.to_world @ mi.Normal3f(s.n))
        return Hit(found, mi.Point3f(origin + t * d), uv, mi.Vector3f(n),
                   self.to_world @ s.dp_du, self.to_world @ s.dp_dv)

    # -- shading -------------------------------------------------------------------------
    def normal(self, hit: Hit) -> mi.Vector3f:
        """Unit normal of the displaced surface S + scale D e at the fragment's uv:
        (S_u + scale D_u e) x (S_v + scale D_v e) (the e_u terms dropped), towards n; e is
        the unit object-space normal through to_world (world units per object unit, not
        along n under a non-uniform scale), as :class:`mi_displace.slicing.geometry.BaseMesh`
        extrudes."""
        _, grad = self._grad(hit.uv)
        e = self.to_world @ dr.normalize(mi.Vector3f(self.to_object @ mi.Normal3f(hit.n)))
        m = dr.cross(hit.su + self.kernel_scale * grad.x * e, hit.sv + self.kernel_scale * grad.y * e)
        m = dr.select(dr.dot(m, hit.n) < 0, -m, m)
        return dr.select(dr.squared_norm(m) > 0, dr.normalize(m), hit.n)

    def spacing(self) -> float:
        """World distance between adjacent surface-aligned slices."""
        return self.world_scale / self.n

    def occluded(self, hit: Hit, normal: mi.Vector3f, wl: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        """Whether the slices block unit direction ``wl`` from the fragment (self-shadows
        drawn by the slices themselves).  The ray starts :data:`SHADOW_BIAS` slice spacings
        off the surface along ``normal``: a fragment lies up to one spacing inside the
        solid, and the slices' own staircase would otherwise shadow it (acne).  It starts
        :data:`SHADOW_LEAVE` spacings along ``wl`` as well: an orthogonal slice contains
        the normal at a bevel, and a ray starting inside its plane meets it or not by
        float rounding (to_world's translation alone flipped 1.7 % of such pixels).
        Queried as coherent rays during a raster frame (:attr:`coherent`)."""
        bias, leave = self.shadow_offsets
        origin = hit.p + normal * bias + wl * leave
        choice = self.choose(wl, hit.n, hit.su, hit.sv)
        return self.find(origin, wl, choice, active, coherent=self.coherent, reach=SHADOW_REACH).found


def crossing(bm: geo.BaseMesh, height: mi.Texture, scale: float, rays=None):
    """The thickness check of ``displaced`` (:func:`mi_displace.core.thickness.crossing_check`)
    for the slices of a mesh base: from each base vertex, the fragments reach
    ``scale D(uv)`` along the extrusion; a part of the base met closer than that along the
    same ray (a two-walled model whose walls both face outwards, a fold) lies inside the
    other part's displacement volume, whose slices then hide it.

    Args:
        bm: a mesh base (world space); height: the α texture; scale: object units.
        rays: the :class:`mi_displace.core.thickness.CrossingRays` of an earlier call on the
            same ``bm`` (cast here when ``None``; they depend on the base only).

    Returns:
        ``(check, rays)``: the check's dict (crossing_vertices, vertices, max_depth_ratio)
        and the rays, for the next call after a ``scale`` edit.
    """
    from mi_displace.core import thickness
    from mi_displace.core.tessellate import Tessellation

    length = np.linalg.norm(bm.extrude, axis=1)
    unit = bm.extrude / np.maximum(length, 1e-30)[:, None]
    to_pt = lambda a: mi.Point3f(*(mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)))
    uv = mi.Point2f(*(mi.Float(np.ascontiguousarray(bm.uvs[:, k], np.float32)) for k in range(2)))
    si = dr.zeros(mi.SurfaceInteraction3f, len(length))
    si.uv = uv
    D = dr.clip(height.eval_1(si), 0.0, 1.0)
    t = Tessellation(to_pt(bm.positions), mi.Vector3f(to_pt(unit)), uv,
                     mi.Vector3u(*(mi.UInt32(np.ascontiguousarray(bm.faces[:, k], np.uint32))
                                   for k in range(3))),
                     to_pt(bm.positions), mi.Vector3f(to_pt(unit)),
                     scale * mi.Float(length.astype(np.float32)) * D)
    base_mesh = (bm.positions, bm.faces, bm.uvs)
    rays = thickness.cast_crossing_rays(t, base_mesh) if rays is None else rays
    return thickness.crossing_check(t, base_mesh=base_mesh, rays=rays), rays


def crossing_message(owner: str, check: dict) -> str | None:
    """The user's warning for :func:`crossing`'s check, or ``None`` when clean."""
    if not check["crossing_vertices"]:
        return None
    return (f"{owner}: the displacement volume reaches through another part of the base at "
            f"{check['crossing_vertices']:,} of {check['vertices']:,} base vertices (up to "
            f"{check['max_depth_ratio']:.2f}x the distance to it): that part's slices hide "
            "this one's relief; lower 'scale' (or orient the base's faces outwards)")
