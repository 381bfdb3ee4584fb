"""A complete DDM / HDDM set-up: base, tiles, layout, geometry images, mapping, memory.

:class:`DDMModel` is what the ``ddm`` plugin holds and what the benchmark and the tests
drive directly.  Construction validates everything and does the one-off work (tiles, layout,
geometry images, pruning, faces) — the *preprocessing phase* of §3.1; :meth:`map` is the
*interactive phase* of §3.2 (one Dr.Jit kernel over all tile vertices) for a time t and a
w scale.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from mi_displace.core import surfaces
from mi_displace.core.mesh_io import load_uv_mesh, resolve_path
from mi_displace.ddm import animation as anim
from mi_displace.ddm import base_maps, charts, footprint, mapping
from mi_displace.ddm.layout import make_layout
from mi_displace.ddm.tiles import Tile, get_tile

#: ddm's bases: the parametric ones and the Utah teapot body (no parameters)
BASE_PARAMS = {**surfaces.BASE_PARAMS, "teapot": ()}


def _sign(x: float) -> float:
    return -1.0 if x < 0 else 1.0


def _value(x) -> float:
    """The value of a Python number or of a one-element Dr.Jit Float (detached)."""
    return float(dr.detach(x)[0]) if dr.is_array_v(x) else float(x)


def _scalar(x):
    """A Dr.Jit Float that carries a gradient stays one (the mapping is differentiable in
    it); anything else becomes a Python float."""
    return x if dr.is_array_v(x) and dr.grad_enabled(x) else _value(x)




def _footprint_rule(dicing_rate: float, sensors: int) -> str:
    """``build_stats["map_resolution_rule"]`` of a footprint-sized ``auto``."""
    return f"auto: screen footprint, {dicing_rate:g} px per texel over {sensors} sensor(s)"


class FoldingWarning(UserWarning):
    """T(u, v, w) folds for some w the tiles reach: the mapped volume turns inside out."""


def make_base(name: str, filename: str | None = None, **params):
    """A DDM base: ``plane``/``sphere``/``cylinder``/``torus`` (analytic), ``teapot`` (the
    Utah teapot body, Bezier patches) or ``mesh`` (``filename``: OBJ/PLY with UVs)."""
    if name == "teapot":
        from mi_displace.core.bezier import teapot_body

        return teapot_body(resolve_path(filename) if filename else None)
    if name == "mesh":
        from mi_displace.ddm.mesh_base import MeshBase

        if not filename:
            raise ValueError("ddm: base 'mesh' needs a 'filename' (PLY/OBJ with UVs)")
        pos, nrm, uvs, faces = load_uv_mesh(filename, "ddm")
        return MeshBase(pos, nrm, uvs, faces)
    return surfaces.make_base(name, **params)


def _resolve_tile(spec: str) -> str:
    spec = spec.strip()
    return resolve_path(spec) if spec.lower().endswith((".obj", ".ply")) else spec


@dataclass
class DDMConfig:
    """Every setting of a DDM shape (units in brackets; see docs/ddm.md)."""

    base: str = "sphere"
    base_params: dict = field(default_factory=dict)
    filename: str | None = None
    tile: str = "thorn"                 # name, 'stone:SEED', file, or comma list
    tile_target: str | None = None      # metamorphosis partner (eq. 3)
    layout: str = "rect"
    tiles_u: int = 16
    tiles_v: int = 8
    gap_u: float = 0.0
    gap_v: float = 0.0
    w_offset: float = 0.0               # [object units]
    u0: float = 0.0
    v0: float = 0.0
    seed: int = 0
    height: float = 0.1                 # [object units per unit tile z]
    mode: str = "maps"
    map_resolution: int | str = 256     # or "auto": smallest R meeting 'tolerance'
    tolerance: float = 1e-4             # auto, no sensor: max mapped-point error / diagonal
    dicing_rate: float = 1.0            # auto with sensors: pixels per texel [px]
    chart_border: str = "clamp"         # mesh bases: tiles across UV charts clamp | drop
    normals: str = "tangent"
    epsilon: float = 1e-3               # [tile units]
    time: float = 0.0
    animation: anim.Animation = field(default_factory=anim.Animation)

    def check(self) -> "DDMConfig":
        self.mode = mapping.MODE_ALIASES.get(self.mode, self.mode)
        if self.mode not in mapping.MODES:
            raise ValueError(f"ddm: unknown 'mode' {self.mode!r}; expected exact, maps, "
                             "reference (= exact) or approximation (= maps)")
        for key in ("height", "w_offset", "time", "epsilon", "dicing_rate"):
            if not math.isfinite(getattr(self, key)):
                raise ValueError(f"ddm: '{key}' must be finite, got {getattr(self, key)!r}")
        if not 0 < self.epsilon < 0.5:
            raise ValueError(f"ddm: 'epsilon' must lie in (0, 0.5) tile units, got {self.epsilon!r}")
        if self.map_resolution != "auto":
            base_maps.check_resolution(self.map_resolution)
        if not self.dicing_rate > 0:
            raise ValueError(f"ddm: 'dicing_rate' must be positive (pixels), got {self.dicing_rate!r}")
        if not (math.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"ddm: 'tolerance' must be a positive number, got {self.tolerance!r}")
        if self.base not in BASE_PARAMS and self.base != "mesh":
            raise ValueError(f"ddm: unknown 'base' {self.base!r}; expected one of "
                             f"{', '.join(sorted(BASE_PARAMS))} or 'mesh'")
        return self


class DDMModel:
    """The preprocessed DDM scene element; :meth:`map` maps all tiles at a time t."""

    def __init__(self, cfg: DDMConfig, base=None, sensors=(), to_world=None):
        """``sensors`` (with the shape's ``to_world``): size ``map_resolution="auto"`` for
        them at once (:meth:`fit_to_sensors`); without, by the sensor-free tolerance rule."""
        start = time.perf_counter()
        self.cfg = cfg.check()
        self.tiles: list[Tile] = [get_tile(_resolve_tile(s)) for s in str(cfg.tile).split(",")
                                  if s.strip()]
        if not self.tiles:
            raise ValueError("ddm: 'tile' is empty")
        self.target = None
        if cfg.tile_target:
            if len(self.tiles) != 1:
                raise ValueError("ddm: 'tile_target' (metamorphosis) needs a single 'tile'")
            self.target = get_tile(_resolve_tile(cfg.tile_target))
            anim.check_compatible(self.tiles[0], self.target)
        # size checks before any kernel or allocation: first a lower bound from the cell
        # count (so that even the layout arrays are never allocated for absurd counts)
        what = f"{cfg.tiles_u} x {cfg.tiles_v} tiles ('tiles_u' x 'tiles_v')"
        cells = int(cfg.tiles_u) * int(cfg.tiles_v) if cfg.tiles_u >= 1 and cfg.tiles_v >= 1 else 0
        mapping.check_size(cells * min(t.vertex_count for t in self.tiles),
                           cells * min(t.face_count for t in self.tiles), what)
        layout = make_layout(cfg.layout, cfg.tiles_u, cfg.tiles_v, len(self.tiles), cfg.gap_u,
                             cfg.gap_v, cfg.u0, cfg.v0, cfg.seed)
        verts = sum(int(np.sum(layout.tile_index == k)) * t.vertex_count
                    for k, t in enumerate(self.tiles))
        faces = sum(int(np.sum(layout.tile_index == k)) * t.face_count
                    for k, t in enumerate(self.tiles))
        mapping.check_size(verts, faces, what)
        self.base = base if base is not None else make_base(
            cfg.base, cfg.filename, **cfg.base_params)
        self._warn_folding()
        self.maps = None
        self.auto_trials = None
        self.auto = cfg.map_resolution == "auto"
        self.resolution_rule = "given"
        self.pruned = 0
        self.chart_stats = {}
        if not self._all_valid_base():
            # decided on the exact mesh, the same in both modes: the reference does not move
            # with map_resolution; every tile keeps to one UV chart
            layout, self.chart_stats = charts.assign_charts(layout, self.tiles, self.base,
                                                            cfg.chart_border)
            self.pruned = self.chart_stats["tiles_pruned"]
            if layout.count == 0:
                raise ValueError("ddm: no tile touches the base mesh's UV layout")
            self.reach = charts.tile_reach(self.tiles, layout.size)
        if cfg.mode == "maps":
            if self.auto and sensors:
                cfg.map_resolution, self.footprint = footprint.resolution(
                    self.base, sensors, to_world, cfg.dicing_rate)
                self.resolution_rule = _footprint_rule(cfg.dicing_rate, len(sensors))
            elif self.auto:
                cfg.map_resolution, self.auto_trials, self.maps = self._resolution_by_tolerance()
                self.resolution_rule = (f"auto: tolerance {cfg.tolerance:g} of the diagonal "
                                        "(no sensor known)")
            if self.maps is None:
                self.maps = self.maps_at(cfg.map_resolution)
        if self._all_valid_base() and self.maps is not None:
            bounds = np.array([[*t.positions[:, :2].min(0), *t.positions[:, :2].max(0)]
                               for t in self.tiles])
            layout, self.pruned = base_maps.prune(layout, bounds, self.maps)
            if layout.count == 0:
                raise ValueError("ddm: every tile lies in the invalid region of the base map")
        self.layout = layout
        self.placement = mapping.Placement.from_layout(layout, len(self.tiles))
        self.buffers = mapping.TileBuffers.from_tiles(self.tiles)
        self.exact = mapping.ExactEvaluator(self.base)
        self.chart_orientation = mapping.orientation(self.exact, self.placement)
        self.faces_sign = 0.0          # sign of the w scale the faces are wound for
        self.faces_version = 0         # bumped whenever the faces are rebuilt
        self._wind_faces(_sign(cfg.height * cfg.animation.w_factor(cfg.time)))
        if self.target is not None:
            self._target = mapping.TileBuffers.from_tiles([self.target])
        self.evaluator = mapping.MapsEvaluator(self.maps) if cfg.mode == "maps" else self.exact
        self.vertex_count = self.placement.vertex_total(self.buffers)
        self.face_count = dr.width(self.faces)
        self.build_s = time.perf_counter() - start

    def _resolution_by_tolerance(self):
        """``map_resolution="auto"`` without a sensor: the smallest power of two meeting
        ``tolerance`` (:func:`~mi_displace.ddm.base_maps.choose_resolution`; on a mesh base
        measured on per-chart maps at points whose lookups stay on one chart)."""
        if self._all_valid_base():
            return base_maps.choose_resolution(self.base, self.cfg.tolerance, self._w_max(),
                                               build=self.maps_at)
        return base_maps.choose_resolution(self.base, self.cfg.tolerance, self._w_max(),
                                           build=self.maps_at, error=charts.map_error, order=1.0)

    def fit_to_sensors(self, sensors, to_world) -> bool:
        """``map_resolution="auto"`` from the base's screen footprint: the geometry images
        are a uniform tessellation of S (§3.1), so choose R such that no texel of the
        visible base spans more than ``dicing_rate`` pixels in any of ``sensors`` (Cycles'
        dicing rate, per texel; :func:`mi_displace.ddm.footprint.resolution`).  Rebuilds
        the maps when R changes.

        Returns:
            True when the maps changed (the caller re-maps the vertices).
        """
        if not self.auto or self.cfg.mode != "maps":
            return False
        r, info = footprint.resolution(self.base, sensors, to_world, self.cfg.dicing_rate)
        self.resolution_rule = _footprint_rule(self.cfg.dicing_rate, len(sensors))
        self.footprint = info
        if r == self.maps.ru:
            return False
        self.cfg.map_resolution = r
        self.maps = self.maps_at(r)
        self.evaluator = mapping.MapsEvaluator(self.maps)
        return True

    def maps_at(self, resolution: int):
        """The geometry images of this model's base at ``resolution``: one pair of maps on
        analytic / Bezier bases, per-chart maps (:class:`~mi_displace.ddm.charts.ChartMaps`)
        on mesh bases."""
        if self._all_valid_base():
            return base_maps.build_maps(self.base, resolution)
        return charts.ChartMaps(self.base, base_maps.check_resolution(resolution), self.reach)

    def _wind_faces(self, sign: float) -> None:
        """(Re)build the faces for a w scale of this sign: a negative scale mirrors every
        tile, so its faces turn round with it (cheap: one kernel over the face indices)."""
        if sign == self.faces_sign:
            return
        self.faces = mapping.instance_faces(self.placement, self.buffers,
                                            [t.faces for t in self.tiles],
                                            self.chart_orientation * sign < 0)
        self.faces_sign = sign
        self.faces_version += 1

    def _all_valid_base(self) -> bool:
        from mi_displace.ddm.mesh_base import MeshBase

        return not isinstance(self.base, MeshBase)

    def _w_max(self) -> float:
        """Largest |w| any tile vertex reaches (object units), animation included."""
        z = np.concatenate([t.positions[:, 2] for t in self.tiles])
        h = self.cfg.height * (1 + abs(self.cfg.animation.w_amplitude))
        return max(abs(h * z.max() + self.cfg.w_offset), abs(h * z.min() + self.cfg.w_offset))

    def _w_range(self) -> tuple[float, float]:
        """Smallest and largest w any tile vertex reaches (object units), animation
        included (the w scale swings between height (1 - |a|) and height (1 + |a|))."""
        z = np.concatenate([t.positions[:, 2] for t in self.tiles])
        a = abs(self.cfg.animation.w_amplitude)
        ws = [h * zz + self.cfg.w_offset for h in (self.cfg.height * (1 - a), self.cfg.height * (1 + a))
              for zz in (z.min(), z.max())]
        return min(ws), max(ws)

    def _warn_folding(self) -> None:
        """Warn where T(u, v, w) = S + n w really folds: where det J_T = (T_u x T_v) . n
        changes sign between w = 0 and some w the tiles reach.  det J_T(w) / det J_T(0) =
        (1 + w k1)(1 + w k2) (k1, k2 principal curvatures, positive where n points away
        from the centre of curvature), a quadratic in w checked at both ends of the w range
        and at its extremum — so outward thorns on a small sphere (1 + w / r > 0) or w below
        R - r on a torus do not warn, inward w beyond r does."""
        lo, hi = self._w_range()
        s = self.base.fold_samples() if hasattr(self.base, "fold_samples") else self.base.sample(
            *base_maps.texel_coordinates(129, 129, False, False))
        a = dr.dot(dr.cross(s.dp_du, s.dp_dv), s.n)
        b = dr.dot(dr.cross(s.dp_du, s.dn_dv) + dr.cross(s.dn_du, s.dp_dv), s.n)
        c = dr.dot(dr.cross(s.dn_du, s.dn_dv), s.n)
        a, b, c = (np.broadcast_to(np.asarray(x, np.float64), (dr.width(s.p),)) for x in (a, b, c))
        ok = np.abs(a) > 1e-12 * max(np.abs(a).max(), 1e-30)     # poles / degenerate faces
        a, b, c = a[ok], b[ok], c[ok]
        ratio = [1 + (b / a) * w + (c / a) * w * w for w in (lo, hi)]
        w_star = np.where(c != 0, -b / (2 * np.where(c != 0, c, 1)), lo)
        inside = (w_star > lo) & (w_star < hi)
        ratio.append(np.where(inside, 1 + (b / a) * w_star + (c / a) * w_star ** 2, 1.0))
        folds = np.minimum.reduce(ratio) <= 0
        if folds.any():
            what = "mesh faces" if hasattr(self.base, "fold_samples") else "sampled points of the base"
            warnings.warn(f"ddm: w in [{lo:.4g}, {hi:.4g}] folds T(u, v, w) = S + n w on "
                          f"{int(folds.sum()):,} of {len(folds):,} {what} (det of the Jacobian "
                          "changes sign: tiles turn inside out there; output stays finite)",
                          FoldingWarning, stacklevel=3)

    def tile_buffers_at(self, t: float):
        """The tile arrays at time t: the metamorphosed tile (eq. 3) or the stored ones."""
        if self.target is None:
            return None
        alpha = self.cfg.animation.alpha(t)
        p, n = anim.metamorphose(self.buffers.positions, self.buffers.normals,
                                 self._target.positions, self._target.normals, alpha)
        t1, t2 = anim.tangent_frame(n)
        return p, n, t1, t2

    def map(self, t: float | None = None, height: float | None = None, method: str | None = None,
            evaluator=None):
        """Map every tile vertex (§3.2) at time ``t`` with w scale ``height``.

        Returns:
            ``(positions, normals, uv)`` Dr.Jit arrays (object space).
        """
        cfg = self.cfg
        t = cfg.time if t is None else t
        height = cfg.height if height is None else height
        for name, value in (("time", t), ("height", height)):
            if not math.isfinite(_value(value)):
                raise ValueError(f"ddm: '{name}' must be finite, got {_value(value)}")
        t, height = _scalar(t), _scalar(height)
        a = cfg.animation
        scale = height * a.w_factor(t)
        self._wind_faces(_sign(_value(scale)))
        return mapping.map_tiles(evaluator or self.evaluator, self.placement, self.buffers,
                                 self._periodic_affine(a.affine(t)), scale, cfg.w_offset,
                                 method or cfg.normals, cfg.epsilon, self.tile_buffers_at(t),
                                 self.chart_orientation * self.faces_sign)

    def _periodic_affine(self, affine):
        """The translation reduced by whole periods of a periodic base (in double precision,
        before it reaches float32 texture coordinates: long animations stay exact)."""
        (a, (b0, b1)), (su, sv) = affine, self.placement.size
        # subtract whole periods (a constant: a differentiable b keeps its derivative)
        if getattr(self.base, "periodic_u", False):
            b0 = b0 - (_value(b0) * su - math.fmod(_value(b0) * su, 1.0)) / su
        if getattr(self.base, "periodic_v", False):
            b1 = b1 - (_value(b1) * sv - math.fmod(_value(b1) * sv, 1.0)) / sv
        return a, (b0, b1)

    def clamped_mask(self, uv) -> np.ndarray:
        """Per mapped vertex (``uv``: mi.Point2f, one per mapped vertex), whether it is
        clamped: off its tile's own UV chart of a mesh base (located exactly), or in an
        invalid texel of an analytic base's maps (degenerate normals).  (V,) bool."""
        if not self._all_valid_base():
            inst, _ = mapping.instance_vertex(self.placement, self.buffers)
            valid, _, _, _ = self.base.locate(uv.x, uv.y, self.placement.instance_chart(inst))
            return ~np.asarray(valid)
        if self.maps is not None and not self.maps.valid.all():
            return ~self.maps.texel_valid(np.asarray(uv.x), np.asarray(uv.y))
        return np.zeros(dr.width(uv), bool)

    def clamped_count(self, uv) -> int:
        """How many mapped vertices are clamped (:meth:`clamped_mask`; Dr.Jit count on
        analytic maps)."""
        if self._all_valid_base() and self.maps is not None:
            return self.maps.clamped_count(uv.x, uv.y)
        return int(self.clamped_mask(uv).sum())

    def memory_report(self) -> dict:
        """Bytes HDDM stores (tile(s) + offsets + maps) against the explicit mapped mesh."""
        tile_bytes = sum(t.nbytes for t in self.tiles) + (self.target.nbytes if self.target else 0)
        maps_bytes = self.maps.nbytes if (self.maps is not None and self.cfg.mode == "maps") else 0
        offsets_bytes = self.layout.count * 2 * 4
        mesh_bytes = self.vertex_count * (3 + 3 + 2) * 4 + self.face_count * 3 * 4
        hddm = tile_bytes + maps_bytes + offsets_bytes
        return {"tile_bytes": tile_bytes, "maps_bytes": maps_bytes, "offsets_bytes": offsets_bytes,
                "hddm_bytes": hddm, "mesh_bytes": mesh_bytes, "mesh_over_hddm": mesh_bytes / hddm}

    def stats(self) -> dict:
        """Build figures for ``build_stats`` / the report."""
        s = {"mode": self.cfg.mode, "tiles_placed": self.layout.count, "tiles_pruned": self.pruned,
             **self.chart_stats, "vertices": self.vertex_count, "faces": self.face_count,
             "build_s": self.build_s, **self.memory_report()}
        if self.maps is not None:
            s.update(map_resolution=self.maps.ru, map_resolution_rule=self.resolution_rule,
                     **self.maps.stats, **getattr(self, "footprint", {}))
        if self.auto_trials is not None:
            s["auto_trials"] = [[r, e] for r, e in self.auto_trials]
        return s
