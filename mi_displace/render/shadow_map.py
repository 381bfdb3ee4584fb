"""Shadow maps (Williams 1978): depth images rasterised from each delta light by
:func:`mi_displace.render.zbuffer.rasterise`, the GPU's hard shadows.

* spot light: one perspective map over its cone (half-angle = ``cutoff_angle``);
* point light: a cube map, six 90-degree perspective faces;
* directional light: one orthographic map over the scene's bounding sphere;
* a point of an area light (:func:`point_views`): a cube map like a point light's.

A point P is looked up at P + n texel normal_offset sin(theta) (normal-offset shadows:
n the geometric normal on the light's side, theta its angle to the light, ``texel`` the
world size of a texel at P's depth) and is in shadow when that point's depth in the light's
view exceeds the stored depth of its texel (nearest texel, no filtering) by more than
``constant`` x texel.  ``constant`` and ``normal_offset`` (in texels) and the resolution
are the quality knobs (measured trade in ``docs/raster.md``: a slope-scaled depth bias
leaked 4-5 % of the grazing key light's shadow decisions where the normal offset leaks 1 %).  Like shadow rays (and Mitsuba's
``path``) every surface casts shadows, null BSDFs included.  Depths are linear float32 view
z (see :mod:`.zbuffer`).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.render import zbuffer

#: Near plane of perspective light views, relative to the scene's bounding-sphere radius.
NEAR = 1e-5

_CUBE_AXES = ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))


@dataclass
class ShadowMap:
    """The depth maps of one delta light.

    Attributes:
        views: 1 view (spot, directional) or 6 (point: +x, -x, +y, -y, +z, -z faces).
        depth: per view, (resolution^2,) Float of stored depths (inf where empty).
        resolution: texels per side.
        constant, normal_offset: bias knobs in texels.
    """
    views: list
    depth: list
    resolution: int
    constant: float
    normal_offset: float


def _frame(origin, forward) -> np.ndarray:
    """World -> local matrix of a frame at ``origin`` looking along ``forward`` (+z)."""
    forward = np.asarray(forward, float) / np.linalg.norm(forward)
    up = [0.0, 0.0, 1.0] if abs(forward[2]) < 0.9 else [1.0, 0.0, 0.0]
    to_world = np.array(mi.ScalarTransform4f().look_at(
        origin=list(map(float, origin)), target=list(map(float, np.asarray(origin) + forward)),
        up=up).matrix, dtype=np.float64)
    return np.linalg.inv(to_world)


def _perspective(to_local: np.ndarray, tan_half: float, res: int, near: float,
                 far: float) -> zbuffer.View:
    return zbuffer.View(to_local=to_local, perspective=True,
                        q0=(-tan_half, -tan_half), dq=(2 * tan_half / res, 2 * tan_half / res),
                        near=near, far=far, width=res, height=res)


def light_views(emitter: mi.Emitter, bbox: mi.ScalarBoundingBox3f, res: int) -> list:
    """The views of a delta light's shadow map over a scene bounded by ``bbox``.

    Raises:
        ValueError: for delta emitters other than point, spot and directional.
    """
    kind = emitter.class_name()
    centre = np.array(bbox.center(), float)
    radius = max(float(np.linalg.norm(np.array(bbox.extents(), float))) / 2, 1e-30)
    params = mi.traverse(emitter)
    if kind == "DirectionalEmitter":
        to_world = np.array(params["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        d = to_world[:3, 2] / np.linalg.norm(to_world[:3, 2])   # direction of travel
        to_local = _frame(centre - 1.01 * radius * d, d)
        r = 1.01 * radius
        return [zbuffer.View(to_local=to_local, perspective=False, q0=(-r, -r), dq=(2 * r / res, 2 * r / res),
                             near=0.0, far=2.02 * radius, width=res, height=res)]
    if kind == "SpotLight":
        to_world = np.array(params["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        origin = to_world[:3, 3]
        far = np.linalg.norm(origin - centre) + radius
        tan_half = float(np.tan(np.radians(min(float(params["cutoff_angle"][0]), 89.0))))
        return [_perspective(_frame(origin, to_world[:3, 2]), tan_half, res, NEAR * radius,
                             1.01 * far)]
    if kind == "PointLight":
        return point_views(np.array(params["position"], float).reshape(3), bbox, res)
    raise ValueError(f"raster: shadows='map' supports point, spot and directional lights, "
                     f"not {kind!r} (use shadows='ray')")


def point_views(origin, bbox: mi.ScalarBoundingBox3f, res: int) -> list:
    """The six 90-degree faces of a cube map at ``origin`` (3,) over a scene in ``bbox``.

    The far plane reaches the far side of the scene's bounding sphere; it is the same for
    every origin inside that sphere (the points of an area light), so their maps share
    compiled kernels."""
    origin = np.asarray(origin, float)
    centre = np.array(bbox.center(), float)
    radius = max(float(np.linalg.norm(np.array(bbox.extents(), float))) / 2, 1e-30)
    far = 1.01 * (max(float(np.linalg.norm(origin - centre)), radius) + radius)
    return [_perspective(_frame(origin, axis), 1.0, res, NEAR * radius, far)
            for axis in _CUBE_AXES]


def build(emitter: mi.Emitter, geom: zbuffer.Geometry, res: int, constant: float,
          normal_offset: float) -> ShadowMap:
    """Rasterise the shadow map of ``emitter`` over ``geom``."""
    return build_views(light_views(emitter, geom.bbox, res), geom, res, constant,
                       normal_offset, f"the {emitter.class_name()} shadow map")


def build_views(views: list, geom: zbuffer.Geometry, res: int, constant: float,
                normal_offset: float, what: str) -> ShadowMap:
    """Rasterise the depth maps of ``views`` over ``geom`` (``what`` names them in the
    memory error)."""
    # depth bits + float depth per texel and face
    zbuffer.check_memory(len(views) * res * res, f"{what} ({len(views)} x {res}^2)", 8)
    depth = []
    for view in views:  # 1 or 6 faces
        bits, _ = zbuffer.rasterise(view, geom, with_ids=False)
        d = dr.select(bits == 0xFFFFFFFF, dr.inf, dr.reinterpret_array(mi.Float, bits))
        dr.eval(d)
        depth.append(d)
    return ShadowMap(views=views, depth=depth, resolution=res, constant=constant,
                     normal_offset=normal_offset)


def unshadowed(sm: ShadowMap, si: mi.SurfaceInteraction3f, to_light: mi.Vector3f,
               active: mi.Bool) -> mi.Bool:
    """Whether the points ``si.p`` see the light (``to_light``: unit world direction)."""
    active = mi.Bool(active)
    cos = dr.abs(dr.dot(si.n, to_light))
    sin = dr.safe_sqrt(1.0 - cos * cos)
    n_light = dr.mulsign(mi.Vector3f(si.n), dr.dot(si.n, to_light))
    visible = mi.Bool(active)
    pending = mi.Bool(active)
    res = sm.resolution
    for view, depth in zip(sm.views, sm.depth):  # cube faces: the first face holding P
        texel = view.texel((view.to_clip @ si.p).z)   # world size of a texel at P
        # normal offset: the lookup moves off the surface by offset x texel x sin(theta)
        p = view.to_clip @ mi.Point3f(si.p + n_light * (texel * sm.normal_offset * sin))
        gx, gy = view.grid(p)
        inside = pending & (gx >= 0) & (gx < res) & (gy >= 0) & (gy < res)
        if view.perspective:
            inside &= p.z > 0
        X = mi.UInt32(dr.clip(gx, 0, res - 1))
        Y = mi.UInt32(dr.clip(gy, 0, res - 1))
        stored = dr.gather(mi.Float, depth, zbuffer.sample_index(view, X, Y, 1), inside)
        blocked = p.z - texel * sm.constant > stored
        visible = dr.select(inside, ~blocked, visible)
        pending &= ~inside
    return visible & active
