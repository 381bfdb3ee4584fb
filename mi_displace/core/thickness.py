"""Displacement deeper than the base is thick (issue 12.3): detect it, name the shape.

Inward displacement larger than the local thickness of a thin shell (a teapot's wall, a
leaf) carries the displaced surface through the other side of the base, and the path-traced
reference silently turns dark.  :func:`crossing_check` casts, from every displaced vertex's
base point S, one ray along sign(d) n (d = scale (h - m), the signed displacement) against
the base mesh itself, through Mitsuba, vectorised; a hit closer than |d| is a crossing.
With the base's UVs and the height, the displacement of the part that is hit counts too
(both walls of a shell move towards each other).  Parametric bases have a known thickness
(:meth:`BaseSurface.thickness`), so they need no rays (the other side's motion is not
counted there).  The rays depend on the base points only (:func:`cast_crossing_rays`, both
ways along n): a re-displacement of the same topology reuses them and re-evaluates the
check exactly, without a ray.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.tessellate import Tessellation

GRAZING_COS = 0.2   # hits meeting the ray more obliquely than ~78 degrees are ignored


@dataclass
class CrossingRays:
    """The geometric half of :func:`crossing_check` for one tessellation's base points: the
    first hit of the base mesh along +n (index 0) and -n (index 1) from every vertex's base
    point S, whatever the displacement (it depends on the vertices' base points only, so a
    re-displacement of the same topology reuses it).

    ``gap[k]``: distance to that hit + ``eps`` (inf without a hit) [object units];
    ``facing[k]``: cos between the hit's normal and the ray (0 without a hit);
    ``uv[k]``: the hit's texture coordinates (``None`` without base UVs); ``eps``: the rays'
    start offset; ``vertices``: how many vertices (rays per direction)."""
    gap: tuple
    facing: tuple
    uv: tuple | None
    eps: float
    vertices: int


def cast_crossing_rays(t: Tessellation, base_mesh: tuple) -> CrossingRays:
    """Cast the rays of :func:`crossing_check` both ways along n, through Mitsuba, vectorised.

    ``base_mesh``: ``(positions (V, 3), faces (F, 3))`` or ``(positions, faces, uvs (V, 2))``
    of the polygonal base (object space); ``t`` supplies ``base_positions`` and
    ``base_normals``."""
    pos, faces = base_mesh[:2]
    uvs = base_mesh[2] if len(base_mesh) > 2 else None
    mesh = mi.Mesh("base", len(pos), len(faces), has_vertex_normals=False,
                   has_vertex_texcoords=uvs is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.asarray(pos, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
    if uvs is not None:
        params["vertex_texcoords"] = mi.Float(np.asarray(uvs, np.float32).ravel())
    params.update()
    scene = mi.load_dict({"type": "scene", "base": mesh})
    extent = float(np.linalg.norm(np.ptp(np.asarray(pos, np.float64), axis=0)))
    # start a hair off the base so the ray does not find the triangles at its own origin
    eps = 1e-5 * extent
    gaps, facings, hit_uvs = [], [], []
    for sign in (1.0, -1.0):
        direction = dr.detach(t.base_normals) * sign
        # no ray from the base reaches farther than the base's extent
        ray = mi.Ray3f(dr.detach(t.base_positions) + eps * direction, direction)
        ray.maxt = dr.full(mi.Float, extent, t.vertex_count)
        pi = scene.ray_intersect_preliminary(ray)
        hit = pi.is_valid()
        si = pi.compute_surface_interaction(ray, active=hit)
        gap = dr.select(hit, pi.t + eps, dr.inf)
        facing = dr.select(hit, dr.dot(si.n, direction), 0.0)
        dr.eval(gap, facing)
        gaps.append(gap)
        facings.append(facing)
        if uvs is not None:
            uv = mi.Point2f(si.uv)
            dr.eval(uv)
            hit_uvs.append(uv)
    return CrossingRays(tuple(gaps), tuple(facings), tuple(hit_uvs) if uvs is not None else None,
                        eps, t.vertex_count)


def crossing_check(t: Tessellation, base_mesh: tuple | None = None,
                   thickness: float = float("inf"), other_side=None,
                   rays: CrossingRays | None = None) -> dict:
    """Count vertices whose displacement passes through another part of the base.

    Args:
        t: a tessellation with ``base_positions``, ``base_normals`` and ``displacement``.
        base_mesh: ``(positions (V, 3), faces (F, 3))`` or ``(positions, faces, uvs (V, 2))``
            of a polygonal base (object space), or ``None`` for a parametric base of
            analytic ``thickness`` [object units].
        thickness: distance along -n to the other side of a parametric base.
        other_side: with UVs in ``base_mesh``, callable(uv: mi.Point2f) -> signed
            displacement (mi.Float) of the surface that is hit: the part of it moving
            towards the ray (the other wall displaced too) shortens the distance.
        rays: :func:`cast_crossing_rays` of ``t``'s base points against ``base_mesh`` (cast
            here when ``None``): a re-displacement of the same topology passes the rays of
            an earlier check and gets the same result as a fresh check, without a ray.

    Returns:
        ``{"crossing_vertices": int, "vertices": int, "max_depth_ratio": float}`` where
        ``max_depth_ratio`` is, on a mesh base, the largest (|d| + the other side's approach)
        / (distance to the base along sign(d) n) over crossing vertices (> 1 there; 0 without
        crossings); on a parametric base, the largest inward depth / thickness over all
        vertices (> 1 exactly where there are crossings).
    """
    n_vertices = t.vertex_count
    if t.displacement is None or not n_vertices:   # (Dr.Jit cannot mix width 0 and 1)
        return {"crossing_vertices": 0, "vertices": n_vertices, "max_depth_ratio": 0.0}
    d = dr.detach(t.displacement)
    if base_mesh is None:
        depth = dr.maximum(-d, 0.0)
        ratio = depth / thickness if np.isfinite(thickness) else dr.zeros(mi.Float, n_vertices)
        crossing = ratio > 1.0
    else:
        rays = cast_crossing_rays(t, base_mesh) if rays is None else rays
        if rays.vertices != n_vertices:
            raise ValueError(f"crossing_check: 'rays' were cast for {rays.vertices} vertices, "
                             f"the tessellation has {n_vertices}")
        inward = d < 0   # the ray runs along sign(d) n: the -n set
        gap = dr.select(inward, rays.gap[1], rays.gap[0])
        facing = dr.select(inward, rays.facing[1], rays.facing[0])
        reach = dr.abs(d)
        approach = reach
        if other_side is not None and rays.uv is not None:
            # the other side moves too: towards the ray where its own displacement runs
            # against the ray (its normal n' ~ -direction at a shell's opposite wall)
            d_other = dr.detach(other_side(mi.Point2f(dr.select(inward, rays.uv[1],
                                                                rays.uv[0]))))
            approach = reach + dr.maximum(-d_other, 0.0) * dr.abs(facing)
        # a ray running along a face at a crease (a shell's rim) is not a crossing: count
        # only the other side met at a real angle (|cos| > GRAZING_COS)
        hit = (reach > 2 * rays.eps) & (dr.abs(facing) > GRAZING_COS) & (approach > gap)
        ratio = dr.select(hit, approach / gap, 0.0)
        crossing = hit
    return {"crossing_vertices": int(dr.count(crossing)[0]), "vertices": n_vertices,
            "max_depth_ratio": float(dr.max(ratio)[0])}


def crossing_warning(owner: str, check: dict) -> str | None:
    """A user-facing warning for :func:`crossing_check`'s result, or ``None`` if clean."""
    if not check["crossing_vertices"]:
        return None
    return (f"{owner}: displacement deeper than the local thickness of the base at "
            f"{check['crossing_vertices']:,} of {check['vertices']:,} vertices (up to "
            f"{check['max_depth_ratio']:.2f}x the distance to the base's other side): the "
            "displaced surface passes through the base and the reference is wrong there; "
            "lower 'scale' or raise 'midlevel'")
