"""Displacement deeper than the base is thick (issue 12.3): detect it, name the shape.

Inward displacement larger than the local thickness of a thin shell (a teapot's wall, a
leaf) carries the displaced surface through the other side of the base, and the path-traced
reference silently turns dark.  :func:`crossing_check` casts, from every displaced vertex's
base point S, one ray along sign(d) n (d = scale (h - m), the signed displacement) against
the base mesh itself, through Mitsuba, vectorised; a hit closer than |d| is a crossing.
With the base's UVs and the height, the displacement of the part that is hit counts too
(both walls of a shell move towards each other).  Parametric bases have a known thickness
(:meth:`BaseSurface.thickness`), so they need no rays (the other side's motion is not
counted there).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.tessellate import Tessellation

GRAZING_COS = 0.2   # hits meeting the ray more obliquely than ~78 degrees are ignored


def crossing_check(t: Tessellation, base_mesh: tuple | None = None,
                   thickness: float = float("inf"), other_side=None) -> dict:
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

    Returns:
        ``{"crossing_vertices": int, "vertices": int, "max_depth_ratio": float}`` where
        ``max_depth_ratio`` is the largest (|d| + the other side's approach) / (distance to
        the base along sign(d) n) over crossing vertices (> 1 there; 0 without crossings).
    """
    n_vertices = t.vertex_count
    if t.displacement is None:
        return {"crossing_vertices": 0, "vertices": n_vertices, "max_depth_ratio": 0.0}
    d = dr.detach(t.displacement)
    if base_mesh is None:
        depth = dr.maximum(-d, 0.0)
        ratio = depth / thickness if np.isfinite(thickness) else dr.zeros(mi.Float, n_vertices)
        crossing = ratio > 1.0
    else:
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
        reach = dr.abs(d)
        direction = dr.detach(t.base_normals) * dr.sign(d)
        # start a hair off the base so the ray does not find the triangles at its own origin
        eps = 1e-5 * extent
        ray = mi.Ray3f(dr.detach(t.base_positions) + eps * direction, direction)
        ray.maxt = reach if other_side is None else dr.full(mi.Float, extent, dr.width(reach))
        active = reach > 2 * eps
        pi = scene.ray_intersect_preliminary(ray, active=active)
        hit = active & pi.is_valid()
        # a ray running along a face at a crease (a shell's rim) is not a crossing: count
        # only the other side met at a real angle (|cos| > GRAZING_COS)
        si = pi.compute_surface_interaction(ray, active=hit)
        facing = dr.dot(si.n, direction)
        gap, approach = pi.t + eps, reach
        if other_side is not None and uvs is not None:
            # the other side moves too: towards the ray where its own displacement runs
            # against the ray (its normal n' ~ -direction at a shell's opposite wall)
            d_other = dr.detach(other_side(si.uv))
            approach = reach + dr.maximum(-d_other, 0.0) * dr.abs(facing)
        hit &= (dr.abs(facing) > GRAZING_COS) & (approach > gap)
        ratio = dr.select(hit, approach / gap, 0.0)
        crossing = hit
    count = int(dr.count(crossing)[0]) if n_vertices else 0
    return {"crossing_vertices": count, "vertices": n_vertices,
            "max_depth_ratio": float(dr.max(ratio)[0]) if n_vertices else 0.0}


def crossing_warning(owner: str, check: dict) -> str | None:
    """A user-facing warning for :func:`crossing_check`'s result, or ``None`` if clean."""
    if not check["crossing_vertices"]:
        return None
    return (f"{owner}: displacement deeper than the local thickness of the base at "
            f"{check['crossing_vertices']:,} of {check['vertices']:,} vertices (up to "
            f"{check['max_depth_ratio']:.2f}x the distance to the base's other side): the "
            "displaced surface passes through the base and the reference is wrong there; "
            "lower 'scale' or raise 'midlevel'")
