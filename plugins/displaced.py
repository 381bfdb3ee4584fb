"""``<shape type="displaced">``: a base surface displaced along its normal by a height texture.

(:data:`SPEC` declares its parameters.)

Mesh bases: ``base="mesh"`` with ``filename`` (PLY/OBJ with UVs) and ``subdivision`` (edge
splits per triangle) or ``edge_length``.  Meshes without UVs are refused (unwrap them
first, e.g. with ``mi_displace.bake.unwrap.unwrap`` (xatlas)).  Every copy of a position (UV seams, hard edges) moves by one vector:
along the angle-weighted normal of the welded surface, by the mean of the copies' heights,
so closed meshes stay closed; ``split_normals="true"`` instead moves each copy along its own
vertex normal (cracks open where they differ; warns at load).
``scale``, ``midlevel`` and the height texture's parameters are editable through
``mi.traverse`` (re-displacement keeps the topology) and differentiable (issue 14: the
vertices and shading normals are recomputed with the AD graph attached; integer texture
parameters and the dicing rates refuse a gradient, naming it).

Screen-adaptive dicing (:mod:`mi_displace.core.dicing`, Cycles' meaning): ``dicing_rate``
(pixels per micro-edge, instead of ``resolution`` / ``subdivision`` / ``edge_length``;
``tessellation`` = ``uniform`` / ``dicing`` chooses when a scene gives both) and
``offscreen_dicing_scale`` (default 4, coarser outside the view frustum and behind the
camera).  The sensors are those referenced in the shape (``<ref id="camera"/>``, any number:
the finest need wins); without one the shape dices coarsely and warns until
:func:`mi_displace.fit_to_sensors` gives it the scene's sensors (the mi-displace loaders
do).  ``dicing_rate`` and ``offscreen_dicing_scale`` are editable through ``mi.traverse``;
every edit (and ``fit_to_sensors`` after a camera edit) recomputes the edge rates and rebuilds
only what changed: the topology is kept when no edge rate moved.

``build_stats`` (a dict attribute, printed by ``mi-displace render --explain``): mode, rate,
patches, edge segments, vertices, faces, bytes, seconds per stage, what was rebuilt, and
``warnings`` (displacement deeper than the base's thickness, pending dicing).
"""
from __future__ import annotations

import math
import time
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import dicing, surfaces, tessellate, thickness
from mi_displace.core.mesh_io import load_uv_mesh
from mi_displace.core.properties import Param, PluginSpec
from mi_displace.core.texture_height import check_texture_finite, height_function, warn_if_srgb
from mi_displace.core.thickness import crossing_check, crossing_warning
from mi_displace.plugins._guard import constructor, take_sensors

SPEC = PluginSpec(
    "displaced", "shape",
    "True displacement: a base surface (parametric, or a mesh with UVs) tessellated and "
    "displaced along its normal, P = S + scale (h - midlevel) n, by a height texture.  Every "
    "copy of a mesh position (UV seams, hard edges) moves by one vector, so closed meshes stay "
    "closed.  Tessellation is uniform (`resolution` / `edge_length` / `subdivision`) or "
    "screen-adaptive (`dicing_rate`, Cycles' meaning) for the sensors referenced in the shape "
    "(`<ref id=\"camera\"/>`), else the scene's once `mi_displace.fit_to_sensors` runs.  Edits "
    "through `mi.traverse` re-displace the mesh (keeping its topology when no edge rate moved); "
    "the height texture's own parameters are editable and differentiable too.",
    (
        surfaces.base_param("sphere"), *surfaces.BASE_DIMENSIONS,
        surfaces.resolution_param(None, "uniform: grid cells along u (default 64; v keeps the "
                                  "base's aspect ratio)"),
        surfaces.EDGE_LENGTH, surfaces.BASE_FILENAME,
        Param("subdivision", "int", 1, "uniform, mesh base: edge splits per triangle", low=1),
        Param("split_normals", "bool", False, "mesh base: move each copy of a position along "
              "its own normal (cracks open where they differ; warns)"),
        Param("height", "texture", None, "the height h (none: the undisplaced base)",
              unit="texture", editable=True, differentiable=True),
        Param("scale", "float", 0.1, "displacement per unit height", unit="object",
              editable=True, differentiable=True),
        Param("midlevel", "float", 0.0, "height with zero displacement", unit="texture",
              editable=True, differentiable=True),
        Param("tessellation", "string", None, "uniform or dicing (default: dicing when "
              "`dicing_rate` is given)", choices=("uniform", "dicing")),
        Param("dicing_rate", "float", None, "dicing: pixels per micro-edge", unit="px",
              low=0, open_low=True, editable=True),
        Param("offscreen_dicing_scale", "float", 4.0, "dicing: rate multiplier outside the view "
              "frustum and behind the camera", low=1, editable=True),
    ),
    example="""<shape type="displaced">
    <string name="base" value="sphere"/>
    <texture type="ripples" name="height"/>
    <float name="scale" value="0.1"/>
    <integer name="resolution" value="32"/>
    <bsdf type="diffuse"/>
</shape>""",
    nested="the `height` texture, one `bsdf`; sensors (`<ref id=\"camera\"/>`) for dicing",
    stats="mode, tessellate_s, vertices, faces, bytes, crossing_vertices, warnings; dicing: "
          "dicing_rate, offscreen_dicing_scale, sensors, bound, patches, patch_grid, "
          "edge_segments_min/max, rebuilt, rates_s, topology_s, displace_s",
    limits="Displacement deeper than the base's thickness crosses the other side (warns); "
           "meshes need UVs; integer texture parameters and the dicing rates take no gradient "
           "(refused by name).",
)


def _mesh_level(mesh_data, values: dict) -> int:
    """Edge splits per base triangle: ``subdivision`` or from ``edge_length``."""
    edge_length = values["edge_length"]
    if edge_length is not None:
        pos, faces = mesh_data[0], mesh_data[3]
        mean_edge = float(np.mean(np.linalg.norm(pos[faces] - pos[np.roll(faces, 1, 1)], axis=2)))
        level = max(1, math.ceil(mean_edge / edge_length))
    else:
        level = values["subdivision"]
    faces = len(mesh_data[3]) * int(level) ** 2
    if faces > 2 * tessellate.MAX_VERTICES:
        raise ValueError(f"displaced: subdivision level {level} gives {faces:,} triangles, more "
                         f"than the limit of {2 * tessellate.MAX_VERTICES:,}; lower "
                         "'subdivision' or raise 'edge_length'")
    return int(level)


class Displaced(mi.Mesh):
    """True displacement: a tessellated mesh P = S + scale (h - midlevel) n."""

    def __init__(self, props: mi.Properties, values: dict):
        self.sensors = take_sensors(props)   # the sensors referenced for dicing
        base_name = surfaces.base_name("displaced", values, "sphere")
        height, scale, midlevel = values["height"], values["scale"], values["midlevel"]
        resolution, edge_length = values["resolution"], values["edge_length"]
        uniform_keys = [k for k in ("resolution", "edge_length", "subdivision") if k in props]
        mode = values["tessellation"]   # explicit: the other mode's settings may stay
        if mode is None:
            mode = "uniform" if values["dicing_rate"] is None else "dicing"
            if mode == "dicing" and uniform_keys:
                raise ValueError(f"displaced: 'dicing_rate' replaces {', '.join(map(repr, uniform_keys))}; "
                                 "give one or the other (or choose with 'tessellation')")
            if mode == "uniform" and "offscreen_dicing_scale" in props:
                raise ValueError("displaced: 'offscreen_dicing_scale' needs 'dicing_rate'")
        self.dicing = mode == "dicing"
        if self.dicing:
            if values["dicing_rate"] is None:
                raise ValueError("displaced: tessellation 'dicing' needs 'dicing_rate'")
            rate, off = values["dicing_rate"], values["offscreen_dicing_scale"]
            resolution = edge_length = None
        # load_dict/XML hand over a double-precision transform; the mesh is float32
        to_world = mi.ScalarTransform4f(mi.ScalarMatrix4f(np.array(
            props.get("to_world", mi.ScalarTransform4f()).matrix, dtype=np.float32)))
        if height is not None:
            check_texture_finite(height)
            warn_if_srgb(height, "displaced")

        if base_name == "mesh":
            mesh_data = load_uv_mesh(values["filename"])
            base = None
            grid = None if self.dicing else _mesh_level(mesh_data, values)
            # constant per load (every re-displacement reuses them): position classes, the
            # interpolated frame, the uniform refinement's topology
            self._weld = tessellate.weld_classes(mesh_data[0])
            self._frames = tessellate.vertex_frames(*mesh_data)
            self._directions = _mesh_directions(mesh_data, self._weld, values["split_normals"],
                                                props.id() or "(no id)")
            if not self.dicing:
                self._topology = tessellate.subdivision_topology(mesh_data[3], self._weld, grid)
        else:
            base = surfaces.make_base(base_name, **surfaces.base_params("displaced", base_name, values))
            if "split_normals" in props:
                raise ValueError(f"displaced: 'split_normals' applies to base 'mesh' only "
                                 f"(base is {base_name!r})")
            mesh_data = None
            grid = None if self.dicing else tessellate.grid_resolution(base, resolution, edge_length)
        self.base, self.mesh_data, self.grid = base, mesh_data, grid
        self.height_texture, self.to_world = height, to_world
        self._rays = None   # (topology, CrossingRays) of the last crossing check on a mesh
        self.to_world_np = np.array(to_world.matrix, dtype=np.float64)
        self.scale, self.midlevel = mi.Float(scale), mi.Float(midlevel)
        if self.dicing:
            self.dicing_rate, self.offscreen_dicing_scale = mi.Float(rate), mi.Float(off)
            self._cache = {}
            self._height_range = _height_range(height)
        start = time.perf_counter()
        t, stats = self._build(props.id() or "displaced")
        super().__init__(props.id() or "displaced", t.vertex_count, t.face_count, props,
                         True, True)
        self._upload(t, start, stats)
        if self.dicing:
            self._cache["key"] = self._dice_key()

    # -- building ------------------------------------------------------------------------
    def _build(self, name: str | None = None):
        """(Tessellation, stats) for the current parameters (uniform or diced).

        ``scale`` and ``midlevel`` enter the kernels as the traversed ``mi.Float``s, so a
        gradient enabled on them (or on the height texture's data) reaches the vertices."""
        if self.dicing:
            return self._dice(name or self.id())
        if self.base is not None:
            nu, nv = self.grid
            height = None if self.height_texture is None else height_function(
                self.height_texture, 0.5 / max(nu, nv))
            t = tessellate.displace_parametric(self.base, height, self.scale, self.midlevel,
                                               nu, nv)
        else:
            height = None if self.height_texture is None else height_function(
                self.height_texture, 1e-3 / self.grid)
            t = tessellate.displace_mesh_vertices(*self.mesh_data, *self._topology, height,
                                                  self.scale, self.midlevel,
                                                  frames=self._frames,
                                                  directions=self._directions)
        return t, {"mode": "uniform"}

    def _dice(self, name: str):
        """Staged dicing: edge rates -> topology (kept if no rate moved) -> vertices."""
        owner = f"displaced {name!r}"
        scale, midlevel = self.scale, self.midlevel
        rate, off = float(self.dicing_rate[0]), float(self.offscreen_dicing_scale[0])
        dicing.check_rates(rate, off)
        times, rebuilt, warn = {}, [], []
        clock = time.perf_counter()
        views = [dicing.sensor_view(s) for s in self.sensors]
        lo, hi = self._height_range
        scale_f, midlevel_f = float(dr.detach(scale)[0]), float(dr.detach(midlevel)[0])
        bound = abs(scale_f) * max(abs(hi - midlevel_f), abs(lo - midlevel_f)) * dicing.linear_scale(
            self.to_world_np)
        if not views:
            warn.append(f"{owner}: dicing_rate needs a sensor and none is referenced "
                        "(<ref id=\"...\"/> in the shape); diced coarsely until "
                        "mi_displace.fit_to_sensors(scene) gives it the scene's sensors")
            views = None
        c = self._cache
        if self.base is not None:
            if views is None:
                grid = c.get("grid", (16, 8))
            else:
                grid = dicing.parametric_grid(self.base, self.to_world_np, views, bound, rate, off)
                old = c.get("grid")
                # keep the patch grid unless the finest need moved by more than 2x
                if old is not None and all(0.5 <= g / o <= 2 for g, o in zip(grid, old)):
                    grid = old
            edges = (dicing.parametric_edge_segments(self.base, self.to_world_np, grid, views,
                                                     bound, rate, off) if views else
                     _unit_edges(grid))
            same = c.get("grid") == grid and "edges" in c and all(
                np.array_equal(edges[k], c["edges"][k]) for k in edges)
        else:
            pos, _, _, faces = self.mesh_data
            if views:
                seg, side = dicing.mesh_edge_segments(pos, faces, self._weld, self.to_world_np,
                                                      views, bound, rate, off)
            else:
                _, side = dicing.mesh_edges(faces, self._weld)
                seg = np.ones(int(side.max()) + 1, np.int64)
            edges, grid = {"seg": seg, "side": side}, None
            same = "edges" in c and np.array_equal(seg, c["edges"]["seg"])
        times["rates_s"] = time.perf_counter() - clock
        clock = time.perf_counter()
        if not same:
            if self.base is not None:
                c["topology"] = dicing.dice_parametric(self.base, grid, edges, rate, owner)
            else:
                c["topology"] = dicing.dice_mesh(self.mesh_data[3], self._weld, edges["seg"],
                                                 edges["side"], rate, owner)
            c["grid"], c["edges"] = grid, edges
            rebuilt.append("topology")
        times["topology_s"] = time.perf_counter() - clock
        clock = time.perf_counter()
        height = None if self.height_texture is None else height_function(self.height_texture, 1e-4)
        topo = c["topology"]
        if self.base is not None:
            t = dicing.displace_diced_parametric(self.base, topo, height, scale, midlevel)
            segs = np.concatenate([edges[k].ravel() for k in ("h", "v")])
            patches = grid[0] * grid[1]
        else:
            pos, nrm, uvs, faces = self.mesh_data
            t = tessellate.displace_mesh_vertices(pos, nrm, uvs, faces, topo.src, topo.bary,
                                                  topo.groups, topo.faces, height, scale, midlevel,
                                                  frames=self._frames, directions=self._directions)
            segs, patches = edges["seg"], len(faces)
        rebuilt.append("vertices")
        times["displace_s"] = time.perf_counter() - clock
        stats = {"mode": "dicing", "dicing_rate": rate, "offscreen_dicing_scale": off,
                 "sensors": len(self.sensors), "bound": bound, "patches": patches,
                 "patch_grid": list(grid) if grid else None,
                 "edge_segments_min": int(segs.min()), "edge_segments_max": int(segs.max()),
                 "rebuilt": rebuilt, **times, "warnings": warn}
        return t, stats

    def _upload(self, t: tessellate.Tessellation, start: float, stats: dict) -> None:
        """Write the tessellation into the mesh buffers (object -> world) and check it."""
        to_world = mi.Transform4f(self.to_world)
        positions = to_world @ t.positions
        normals = dr.normalize(to_world @ mi.Normal3f(t.normals))
        params = mi.traverse(self)
        params["vertex_positions"] = dr.ravel(positions)
        params["vertex_normals"] = dr.ravel(normals)
        params["vertex_texcoords"] = dr.ravel(t.texcoords)
        params["faces"] = dr.ravel(t.faces)
        params.update()
        finite = dr.all(dr.isfinite(params["vertex_positions"])) & dr.all(
            dr.isfinite(params["vertex_normals"]))
        if not finite[0]:
            raise ValueError(f"displaced: tessellation of {self.id()!r} produced NaN/Inf "
                             "(check the height texture and 'scale')")
        v, f = t.vertex_count, t.face_count
        tessellate_s = time.perf_counter() - start
        check = self._crossing_check(t)
        messages = list(stats.pop("warnings", []))
        message = crossing_warning(f"displaced {self.id() or '(no id)'!r}", check)
        if message:
            messages.append(message)
        for m in messages:
            warnings.warn(m, stacklevel=2)
        self.build_stats = {**stats, "tessellate_s": tessellate_s, "vertices": v, "faces": f,
                            "bytes": v * 8 * 4 + f * 3 * 4,
                            "crossing_vertices": check["crossing_vertices"],
                            "warnings": messages}

    def _crossing_check(self, t: tessellate.Tessellation) -> dict:
        """:func:`crossing_check` of ``t``; on a mesh base the rays (the costly part: a BVH of
        the base and two rays per vertex) are cast once per topology, so an edit of the
        displacement re-evaluates the check exactly (the result a fresh load gives) without
        casting a ray."""
        if self.base is not None:
            return crossing_check(t, thickness=self.base.thickness())
        base_mesh = (self.mesh_data[0], self.mesh_data[3], self.mesh_data[2])
        topology = self._cache["topology"] if self.dicing else self._topology
        if self._rays is None or self._rays[0] is not topology:
            self._rays = (topology, thickness.cast_crossing_rays(t, base_mesh))
        return crossing_check(t, base_mesh=base_mesh, other_side=self._signed_displacement(),
                              rays=self._rays[1])

    def _signed_displacement(self):
        """callable(uv) -> scale (h(uv) - midlevel), or None without a height."""
        if self.height_texture is None:
            return None
        height = height_function(self.height_texture, 1e-3)
        return lambda uv: self.scale * (height(uv)[0] - self.midlevel)

    def fit_to_sensors(self, sensors) -> bool:
        """Dice for ``sensors`` (the scene's) unless the shape references its own; True if
        anything was rebuilt.  Called by :func:`mi_displace.core.dicing.fit_to_sensors`."""
        if not self.dicing:
            return False
        if sensors is not None and not self._own_sensors():
            self.sensors = list(sensors)
            self._scene_sensors = True
        return self._rebuild_if_needed()

    def _own_sensors(self) -> bool:
        return bool(self.sensors) and not getattr(self, "_scene_sensors", False)

    def _dice_key(self) -> tuple:
        """Everything the diced mesh depends on (sensor states and the four parameters);
        a parameter with a gradient enabled always rebuilds (its graph must be fresh)."""
        grad = (dr.grad_enabled(self.scale) or dr.grad_enabled(self.midlevel)
                or self._texture_grad_enabled())
        return ([dicing.sensor_view(s).key() for s in self.sensors],
                float(dr.detach(self.scale)[0]), float(dr.detach(self.midlevel)[0]),
                float(self.dicing_rate[0]), float(self.offscreen_dicing_scale[0]),
                object() if grad else None)

    def _rebuild_if_needed(self) -> bool:
        key = self._dice_key()
        if key == self._cache.get("key"):
            return False
        start = time.perf_counter()
        t, stats = self._build()
        self._upload(t, start, stats)
        self._cache["key"] = key
        return True

    def traverse(self, cb):
        super().traverse(cb)
        # differentiable: the vertices are recomputed from them with the AD graph attached
        cb.put("scale", self.scale, mi.ParamFlags.Differentiable)
        cb.put("midlevel", self.midlevel, mi.ParamFlags.Differentiable)
        if self.height_texture is not None:  # its edits re-displace (never stale)
            cb.put("height", self.height_texture, mi.ParamFlags.Differentiable)
        if self.dicing:
            cb.put("dicing_rate", self.dicing_rate, mi.ParamFlags.NonDifferentiable)
            cb.put("offscreen_dicing_scale", self.offscreen_dicing_scale,
                   mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=[]):
        own = {"scale", "midlevel", "dicing_rate", "offscreen_dicing_scale"}
        texture = any(k == "height" or k.startswith("height.") for k in keys)
        if own & set(keys) or texture:
            self._refuse_gradients_that_cannot_flow()
            for key in ("scale", "midlevel"):
                if not math.isfinite(float(dr.detach(getattr(self, key))[0])):
                    raise ValueError(f"displaced: '{key}' must be finite")
            if texture:
                check_texture_finite(self.height_texture)
            if self.dicing:
                if texture:  # the height range (hence the bound) may have moved
                    self._height_range = _height_range(self.height_texture)
                    self._cache.pop("key", None)
                self._rebuild_if_needed()
            else:
                start = time.perf_counter()
                t, stats = self._build()
                self._upload(t, start, stats)
        else:
            super().parameters_changed(keys)

    def _texture_grad_enabled(self) -> bool:
        """Whether a parameter of the height texture (texels, a procedural number) has a
        gradient enabled."""
        if self.height_texture is None:
            return False
        params = mi.traverse(self.height_texture)
        return any(dr.is_array_v(params[k]) and dr.grad_enabled(params[k]) for k in params.keys())

    def _refuse_gradients_that_cannot_flow(self) -> None:
        """ValueError naming a parameter whose gradient would silently stay zero."""
        names = [k for k in ("dicing_rate", "offscreen_dicing_scale")
                 if self.dicing and dr.grad_enabled(getattr(self, k))]
        if self.height_texture is not None:
            params = mi.traverse(self.height_texture)
            names += [f"height.{k}" for k in params.keys()
                      if params.flags(k) & mi.ParamFlags.NonDifferentiable
                      and dr.is_array_v(params[k]) and dr.grad_enabled(params[k])]
        if names:
            raise ValueError(f"displaced {self.id()!r}: a gradient was enabled on "
                             f"{', '.join(map(repr, names))}, which the tessellation cannot "
                             "differentiate (it would stay exactly zero); differentiable: "
                             "'scale', 'midlevel' and the height texture's continuous "
                             "parameters (a bitmap's data; ripples' frequencies and phase, "
                             "bricks' mortar and bevel, cells' radius and jitter)")

    def to_string(self):
        s = self.build_stats
        return (f"Displaced[base={self.base.name if self.base else 'mesh'}, "
                f"vertices={s.get('vertices')}, faces={s.get('faces')}]")


def _mesh_directions(mesh_data, weld: np.ndarray, split_normals: bool, name: str) -> np.ndarray:
    """(V, 3) displacement direction of each base vertex: the welded normal (one per
    position, watertight), or with ``split_normals`` the vertex's own normal, warning once
    (here, at load) when copies of a position disagree and the surface will crack."""
    pos, nrm, _, faces = mesh_data
    if not split_normals:
        return tessellate.welded_normals(pos, nrm, faces, weld)
    split = tessellate.split_positions(nrm, weld)
    if split:
        warnings.warn(f"displaced {name!r}: split_normals=true moves each copy of a position "
                      f"along its own vertex normal; the copies disagree at {split:,} positions "
                      "(UV seams, hard edges), where the displaced surface cracks open",
                      stacklevel=3)
    return nrm


def _height_range(texture) -> tuple[float, float]:
    """(min, max) of a height texture: probed on a 256^2 uv grid, max widened by ``max()``."""
    if texture is None:
        return 0.0, 0.0
    g = (np.arange(256) + 0.5) / 256
    u, v = np.meshgrid(g, g)
    h, _ = height_function(texture, 1e-3)(mi.Point2f(mi.Float(u.ravel()), mi.Float(v.ravel())))
    h = np.asarray(h)
    hi = float(h.max())
    try:
        hi = max(hi, float(np.asarray(texture.max()).max()))
    except Exception:  # textures without a max() keep the probed value
        pass
    return float(h.min()), hi


def _unit_edges(grid) -> dict:
    """Every patch edge and mid-line of a (nu, nv) patch grid with one segment."""
    nu, nv = grid
    return {"h": np.ones((nv + 1, nu), np.int64), "v": np.ones((nv, nu + 1), np.int64),
            "mid_u": np.ones((nv, nu), np.int64), "mid_v": np.ones((nv, nu), np.int64)}


def register():
    mi.register_shape("displaced", constructor(SPEC, Displaced))
