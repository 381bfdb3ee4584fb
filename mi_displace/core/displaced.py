"""The tessellation behind ``<shape type="displaced">``: uniform or diced, rebuilt on edits.

:class:`DisplacedSurface` is a plain Python object holding everything the displaced surface
P = S + scale (h - midlevel) n depends on (the base, the height texture, the sensors, the
traversed parameters) and the caches that make an edit cheap.  The plugin
(``mi_displace.plugins.displaced``) only uploads the :class:`MeshBuffers` it returns into its
``mi.Mesh`` and forwards ``traverse`` / ``parameters_changed`` / ``fit_to_sensors``.

* Uniform: a parametric base on an (nu, nv) grid (:func:`tessellate.displace_parametric`) or
  a mesh base split ``subdivision`` times per edge (:func:`tessellate.displace_mesh_vertices`;
  every copy of a position moves by one vector, so closed meshes stay closed).
* Dicing (:mod:`mi_displace.core.dicing`, Cycles' meaning): edge rates -> topology (kept
  when no edge rate moved) -> vertices, for the finest need of the sensors.
* After every build: the thickness check (:mod:`mi_displace.core.thickness`; on a mesh base
  its rays are cast once per topology) and ``build_stats``.
"""
from __future__ import annotations

import math
import time
import warnings
import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core import dicing, surfaces, tessellate, thickness
from mi_displace.core.mesh_buffers import MeshBuffers
from mi_displace.core.mesh_io import load_uv_mesh
from mi_displace.core.texture_height import check_texture_finite, height_function, warn_if_srgb
from mi_displace.core.thickness import crossing_check, crossing_warning

#: The traversed parameters whose edits re-displace (the height texture's too, as ``height.*``).
OWN_KEYS = frozenset({"scale", "midlevel", "dicing_rate", "offscreen_dicing_scale"})


class DisplacedSurface:
    """Builds and rebuilds the displaced mesh of one ``displaced`` shape (object units inside,
    world units in :class:`MeshBuffers`).

    Args:
        values: the plugin's declared values (``SPEC.read``).
        given: the names of the parameters the scene gave explicitly (mode conflicts).
        sensors: the sensors referenced in the shape (dicing; may be empty).
        to_world: the shape's ``to_world`` (any Mitsuba transform; rounded to float32 like the
            mesh).
        name: the shape's id ('' without one), for messages.
    """

    def __init__(self, values: dict, given: set, sensors: list, to_world, name: str):
        self.name, self.sensors = name, list(sensors)
        self._scene_sensors = False   # True once fit_to_sensors gave the scene's sensors
        base_name = surfaces.base_name("displaced", values, "sphere")
        height, scale, midlevel = values["height"], values["scale"], values["midlevel"]
        resolution, edge_length = values["resolution"], values["edge_length"]
        uniform_keys = [k for k in ("resolution", "edge_length", "subdivision") if k in given]
        mode = values["tessellation"]   # explicit: the other mode's settings may stay
        if mode is None:
            mode = "uniform" if values["dicing_rate"] is None else "dicing"
            if mode == "dicing" and uniform_keys:
                raise ValueError(f"displaced: 'dicing_rate' replaces {', '.join(map(repr, uniform_keys))}; "
                                 "give one or the other (or choose with 'tessellation')")
            if mode == "uniform" and "offscreen_dicing_scale" in given:
                raise ValueError("displaced: 'offscreen_dicing_scale' needs 'dicing_rate'")
        self.dicing = mode == "dicing"
        if self.dicing:
            if values["dicing_rate"] is None:
                raise ValueError("displaced: tessellation 'dicing' needs 'dicing_rate'")
            resolution = edge_length = None
        # load_dict/XML hand over a double-precision transform; the mesh is float32
        self.to_world = mi.ScalarTransform4f(mi.ScalarMatrix4f(np.array(to_world.matrix,
                                                                        dtype=np.float32)))
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
                                                name or "(no id)")
            if not self.dicing:
                self._topology = tessellate.subdivision_topology(mesh_data[3], self._weld, grid)
        else:
            base = surfaces.make_base(base_name, **surfaces.base_params("displaced", base_name, values))
            if "split_normals" in given:
                raise ValueError(f"displaced: 'split_normals' applies to base 'mesh' only "
                                 f"(base is {base_name!r})")
            mesh_data = None
            grid = None if self.dicing else tessellate.grid_resolution(base, resolution, edge_length)
        self.base, self.mesh_data, self.grid = base, mesh_data, grid
        self.height_texture = height
        self._rays = None   # (topology, CrossingRays) of the last crossing check on a mesh
        self.to_world_np = np.array(self.to_world.matrix, dtype=np.float64)
        # traversed in place (the plugin puts these very objects): edits land here
        self.scale, self.midlevel = mi.Float(scale), mi.Float(midlevel)
        if self.dicing:
            self.dicing_rate = mi.Float(values["dicing_rate"])
            self.offscreen_dicing_scale = mi.Float(values["offscreen_dicing_scale"])
            self._cache = {}
            self._height_range = _height_range(height)

    # -- the plugin's interface ----------------------------------------------------------
    def build_mesh(self) -> MeshBuffers:
        """The first build (at load)."""
        start = time.perf_counter()
        t, stats = self.build(self.name or "displaced")
        built = self._finish(t, start, stats)
        if self.dicing:
            self._cache["key"] = self._dice_key()
        return built

    def parameters(self) -> list[tuple[str, object, bool]]:
        """(name, value, differentiable) of the parameters to traverse; the values are the
        objects the builds read, so an edit through ``mi.traverse`` reaches them."""
        # differentiable: the vertices are recomputed from them with the AD graph attached
        out = [("scale", self.scale, True), ("midlevel", self.midlevel, True)]
        if self.height_texture is not None:  # its edits re-displace (never stale)
            out.append(("height", self.height_texture, True))
        if self.dicing:
            out += [("dicing_rate", self.dicing_rate, False),
                    ("offscreen_dicing_scale", self.offscreen_dicing_scale, False)]
        return out

    def owns(self, keys) -> bool:
        """Whether an edit of ``keys`` (``parameters_changed``) concerns the displacement."""
        return bool(OWN_KEYS & set(keys)) or self._texture_edited(keys)

    def edit(self, keys) -> MeshBuffers | None:
        """Re-displace after an edit of ``keys`` (:meth:`owns` is true); ``None`` when the
        diced mesh is unchanged.  ValueError for a non-finite value or a gradient that cannot
        flow, naming the parameter."""
        texture = self._texture_edited(keys)
        self._refuse_gradients_that_cannot_flow()
        for key in ("scale", "midlevel"):
            if not math.isfinite(float(dr.detach(getattr(self, key))[0])):
                raise ValueError(f"displaced: '{key}' must be finite")
        if texture:
            check_texture_finite(self.height_texture)
        if not self.dicing:
            start = time.perf_counter()
            t, stats = self.build()
            return self._finish(t, start, stats)
        if texture:  # the height range (hence the bound) may have moved
            self._height_range = _height_range(self.height_texture)
            self._cache.pop("key", None)
        return self._rebuild_if_needed()

    def fit_to_sensors(self, sensors) -> MeshBuffers | None:
        """Dice for ``sensors`` (the scene's) unless the shape references its own; ``None``
        when nothing was rebuilt (or the tessellation is uniform)."""
        if not self.dicing:
            return None
        if sensors is not None and not self._own_sensors():
            self.sensors = list(sensors)
            self._scene_sensors = True
        return self._rebuild_if_needed()

    # -- building ------------------------------------------------------------------------
    def build(self, name: str | None = None):
        """(Tessellation in object units, stats) for the current parameters (uniform or diced).

        ``scale`` and ``midlevel`` enter the kernels as the traversed ``mi.Float`` values, so a
        gradient enabled on them (or on the height texture's data) reaches the vertices."""
        if self.dicing:
            return self._dice(self.name if name is None else name)
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

    def _finish(self, t: tessellate.Tessellation, start: float, stats: dict) -> MeshBuffers:
        """``t`` in world space, checked for NaN/Inf and for crossing the base's other side
        (warns), with its ``build_stats``."""
        to_world = mi.Transform4f(self.to_world)
        positions = dr.ravel(to_world @ t.positions)
        normals = dr.ravel(dr.normalize(to_world @ mi.Normal3f(t.normals)))
        finite = dr.all(dr.isfinite(positions)) & dr.all(dr.isfinite(normals))
        if not finite[0]:
            raise ValueError(f"displaced: tessellation of {self.name!r} produced NaN/Inf "
                             "(check the height texture and 'scale')")
        v, f = t.vertex_count, t.face_count
        tessellate_s = time.perf_counter() - start
        check = self._crossing_check(t)
        messages = list(stats.pop("warnings", []))
        message = crossing_warning(f"displaced {self.name or '(no id)'!r}", check)
        if message:
            messages.append(message)
        for m in messages:
            warnings.warn(m, stacklevel=3)
        stats = {**stats, "tessellate_s": tessellate_s, "vertices": v, "faces": f,
                 "bytes": v * 8 * 4 + f * 3 * 4,
                 "crossing_vertices": check["crossing_vertices"], "warnings": messages}
        return MeshBuffers(positions, normals, dr.ravel(t.texcoords), dr.ravel(t.faces), v, f, stats)

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

    # -- rebuild cache -------------------------------------------------------------------
    def _own_sensors(self) -> bool:
        return bool(self.sensors) and not self._scene_sensors

    def _dice_key(self) -> tuple:
        """Everything the diced mesh depends on (sensor states and the four parameters);
        a parameter with a gradient enabled always rebuilds (its graph must be fresh)."""
        grad = (dr.grad_enabled(self.scale) or dr.grad_enabled(self.midlevel)
                or self._texture_grad_enabled())
        return ([dicing.sensor_view(s).key() for s in self.sensors],
                float(dr.detach(self.scale)[0]), float(dr.detach(self.midlevel)[0]),
                float(self.dicing_rate[0]), float(self.offscreen_dicing_scale[0]),
                object() if grad else None)

    def _rebuild_if_needed(self) -> MeshBuffers | None:
        key = self._dice_key()
        if key == self._cache.get("key"):
            return None
        start = time.perf_counter()
        t, stats = self.build()
        built = self._finish(t, start, stats)
        self._cache["key"] = key
        return built

    # -- gradients -----------------------------------------------------------------------
    @staticmethod
    def _texture_edited(keys) -> bool:
        return any(k == "height" or k.startswith("height.") for k in keys)

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
            raise ValueError(f"displaced {self.name!r}: a gradient was enabled on "
                             f"{', '.join(map(repr, names))}, which the tessellation cannot "
                             "differentiate (it would stay exactly zero); differentiable: "
                             "'scale', 'midlevel' and the height texture's continuous "
                             "parameters (a bitmap's data; ripples' frequencies and phase, "
                             "bricks' mortar and bevel, cells' radius and jitter)")


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
