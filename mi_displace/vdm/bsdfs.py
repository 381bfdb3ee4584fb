"""The mesostructure BSDFs: view-dependent displacement mapping (Wang et al. 2003, §3) and
its baselines, horizon mapping (Max 1988) and relief / parallax occlusion mapping.

Each is a :class:`~mi_displace.vdm.mesostructure.MesostructureBSDF` built from a plugin's
properties as read by its spec (``plugins/vdm.py``, ``horizon.py``, ``relief.py``).
``VDM`` owns the table policy: the curvature range measured on the attached meshes, the
table sizes (given or ``"auto"`` from the projected tile size), the build and its cache.
"""
from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.vdm import auto, build, table
from mi_displace.vdm.frame import TiledHeight, TileFrame, shading_interaction
from mi_displace.vdm.horizon import HorizonLookup, horizon_table
from mi_displace.vdm.lookup import cached_lookup
from mi_displace.vdm.mesostructure import MesostructureBSDF
from mi_displace.vdm.relief import march_shadow, march_view
from mi_displace.vdm.steps import VDMSteps


def _round_out(x: float, direction, digits: int = 4) -> float:
    """``x`` rounded to ``digits`` significant digits with ``direction`` (math.floor/ceil)."""
    if x == 0 or not math.isfinite(x):
        return x
    step = 10.0 ** (math.floor(math.log10(abs(x))) - digits + 1)
    return direction(x / step) * step


class VDM(MesostructureBSDF):
    """View-dependent displacement mapping (paper §3)."""

    PLUGIN = "vdm"
    HAS_SILHOUETTE = True

    def __init__(self, props: mi.Properties, values: dict):
        super().__init__(props, values)
        self.auto = {k for k in ("res", "theta") if values[k] == "auto"}
        self.sensor = values["sensor"]
        if self.auto and self.sensor is None:
            raise ValueError("vdm: 'res'/'theta' = 'auto' sizes the table from the projected "
                             "size of one tile: give the sensor (<ref name=\"sensor\" "
                             "id=\"...\"/>)")
        self.spec = build.VDMSpec(
            res=128 if "res" in self.auto else values["res"],
            n_theta=8 if "theta" in self.auto else values["theta"],
            n_phi=values["phi"], n_curv=values["curvatures"],
            theta_oversample=values["theta_oversample"])
        self.svd_terms, self.mvm_terms = values["svd_terms"], values["mvm_terms"]
        self.shadows = values["shadows"]
        self.shadow_bias, self.shadow_slack = values["shadow_bias"], values["shadow_slack"]
        self.shadow_verify = values["shadow_verify"]
        self.refine_steps, self.refine_window = values["refine_steps"], values["refine_window"]
        self.use_cache = values["cache"]
        self.curvature_percentile = values["curvature_percentile"]
        lo, hi = values["curvature_min"], values["curvature_max"]
        self.fixed_range = None
        if (lo is None) != (hi is None):
            raise ValueError("vdm: give both 'curvature_min' and 'curvature_max' or neither")
        if lo is not None:
            if lo > hi:
                raise ValueError(f"vdm: 'curvature_min' ({lo}) > 'curvature_max' ({hi})")
            self.fixed_range = (lo, hi)
        self.steps = None
        if self.tile_size is not None:  # standalone use: flat table (c_V = 0) now
            self._setup(self.tile_size, None)

    # -- table -----------------------------------------------------------------------------
    def _setup(self, tile_size: float, meshes) -> None:
        if self.auto:
            self._auto_sizes(tile_size, meshes)
        curvatures = None
        if meshes:
            curvatures = (np.concatenate([m["c_min"] for m in meshes]),
                          np.concatenate([m["c_max"] for m in meshes]))
        self._build(tile_size, curvatures, bool(meshes))

    def _auto_sizes(self, tile_size: float, meshes) -> None:
        """res / theta from the projected size of one tile (:mod:`mi_displace.vdm.auto`)."""
        if not meshes:
            raise ValueError("vdm: 'res'/'theta' = 'auto' needs the BSDF inside a vdm_mesh")
        tile_px = max(auto.projected_tile_pixels(self.sensor, m["positions"], m["faces"],
                                                 tile_size * m["scale"]) for m in meshes)
        chosen = auto.auto_sizes(tile_px, self.depth / tile_size)
        if "res" in self.auto:
            self.spec.res = chosen["res"]
        if "theta" in self.auto:
            self.spec.n_theta = chosen["theta"]
        self.stats["auto"] = {k: chosen[k] for k in ("tile_px", *sorted(self.auto))}

    def _build(self, tile_size: float, curvatures, use_curvature: bool) -> None:
        lo = hi = 0.0
        clamped = 0
        if curvatures is not None:
            c_min, c_max = curvatures
            q = self.curvature_percentile
            lo_w = float(np.percentile(c_min, q)) if q > 0 else float(c_min.min())
            hi_w = float(np.percentile(c_max, 100 - q)) if q > 0 else float(c_max.max())
            if self.fixed_range is not None:
                lo_w, hi_w = self.fixed_range
            # widened to 4 significant digits: the mesh estimate jitters in the last bits
            # between loads, which would change the cache key and the traced kernels
            lo, hi = _round_out(lo_w * tile_size, math.floor), _round_out(hi_w * tile_size, math.ceil)
            clamped = int(np.count_nonzero((c_min * tile_size < lo - 1e-9)
                                           | (c_max * tile_size > hi + 1e-9)))
        elif self.fixed_range is not None:
            lo, hi = self.fixed_range[0] * tile_size, self.fixed_range[1] * tile_size
        # shadows look up c = 0 (§3.2): the sampled range always contains it
        lo, hi = min(lo, 0.0), max(hi, 0.0)
        spec = build.VDMSpec(res=self.spec.res, n_theta=self.spec.n_theta, n_phi=self.spec.n_phi,
                             n_curv=self.spec.n_curv, depth=self.depth / tile_size,
                             c_range=(lo, hi), theta_oversample=self.spec.theta_oversample)
        if "theta" in self.auto:  # enough columns for the requested eigen-functions
            need = math.ceil(max(self.svd_terms, self.mvm_terms) / len(spec.curvatures())) - 1
            spec.n_theta = self.spec.n_theta = max(spec.n_theta, need)
        # the SVD keeps at most one eigen-function per table column: check before building
        stored = min(build.K_STORED, len(spec.curvatures()) * (spec.n_theta + 1))
        for name, k in (("svd_terms", self.svd_terms), ("mvm_terms", self.mvm_terms)):
            if k > stored:
                raise ValueError(
                    f"vdm: '{name}' = {k} exceeds the {stored} eigen-functions this table keeps "
                    f"({len(spec.curvatures())} curvature(s) x ({spec.n_theta} theta + 1) "
                    f"columns, at most {build.K_STORED}); lower it or raise 'theta'")
        heights = table.sample_heights(self.height, spec.res, self.tiling, self.PLUGIN)
        self._check_periodic(heights)
        self.data = build.build(heights, spec, use_cache=self.use_cache)
        lookup = cached_lookup(self.data, self.svd_terms, self.mvm_terms)
        self.steps = VDMSteps(lookup, self.height, spec.depth, tile_size, self.tiling,
                              use_curvature, self.shadows, self.shadow_bias,
                              self.shadow_slack, self.refine_steps, self.refine_window,
                              self.shadow_verify)
        self.stats.update(self.data.stats)
        self.stats.update(tile_size=tile_size, depth_tile=spec.depth, c_range_tile=(lo, hi),
                          n_curvatures=len(self.data.curvatures),
                          curvature_clamped_vertices=clamped,
                          table_bytes=self.data.table_bytes(), compressed_bytes=lookup.nbytes)

    def _sizes(self) -> dict:
        s = self.spec
        return {"res": s.res, "theta": s.n_theta, "phi": s.n_phi, "curvatures": s.n_curv,
                "svd_terms": self.svd_terms, "mvm_terms": self.mvm_terms}

    def rebuild(self, res=None, theta=None, phi=None, curvatures=None, svd_terms=None,
                mvm_terms=None, use_cache=None) -> None:
        """Rebuild the table with other sizes / term counts (trade-off sweeps); the tile size
        and curvatures of the attached meshes are kept."""
        s = self.spec
        self.spec = build.check_spec(build.VDMSpec(
            res=res or s.res, n_theta=theta or s.n_theta, n_phi=phi or s.n_phi,
            n_curv=curvatures or s.n_curv, theta_oversample=s.theta_oversample))
        self.svd_terms = svd_terms or self.svd_terms
        self.mvm_terms = mvm_terms or self.mvm_terms
        if use_cache is not None:
            self.use_cache = bool(use_cache)
        self._require(self.stats.get("tile_size") is not None)
        self._setup(self.stats["tile_size"], self._meshes)

    def _ready(self) -> bool:
        return self.steps is not None

    def _prepare(self, si, active):
        fp = self.steps.footprint(si, active)
        return fp, fp.silhouette, self.steps.shading(si, fp)

    def _lit(self, state, wo_world, active):
        return self.steps.lit(state, wo_world, active)

    def _blocked(self, si, active):
        if self._unused():
            return dr.zeros(mi.Bool, dr.width(si.t))
        return self.steps.silhouette(si, active)

    def to_string(self):
        s = self.spec
        return (f"VDM[res={s.res}, theta={s.n_theta}, phi={s.n_phi}, curvatures={s.n_curv}, "
                f"svd_terms={self.svd_terms}, mvm_terms={self.mvm_terms}, depth={self.depth}]")


class Horizon(MesostructureBSDF):
    """Bump mapping with horizon-map self-shadows (no occlusion, no silhouettes)."""

    PLUGIN = "horizon"

    def __init__(self, props: mi.Properties, values: dict):
        super().__init__(props, values)
        self.res, self.azimuths = values["res"], values["azimuths"]
        self.max_distance = values["max_distance"]
        self.lookup = None
        self.tiled = TiledHeight(self.height, self.tiling, 0.25 / self.res)
        if self.tile_size is not None:
            self._setup(self.tile_size, None)

    def _setup(self, tile_size, meshes):
        start = time.perf_counter()
        self.used_tile = float(tile_size)
        heights = table.sample_heights(self.height, self.res, self.tiling, self.PLUGIN)
        self._check_periodic(heights)
        self.D = self.depth / self.used_tile
        self.lookup = HorizonLookup(horizon_table(heights, self.D, self.azimuths, self.max_distance))
        self.stats.update(build_time_s=time.perf_counter() - start, table_bytes=self.lookup.nbytes,
                          tile_size=self.used_tile)

    def _ready(self) -> bool:
        return self.lookup is not None

    def _prepare(self, si, active):
        frame = TileFrame(si, self.tiling)
        T = mi.Point2f(si.uv.x * self.tiling[0], si.uv.y * self.tiling[1])
        _, grad = self.tiled(T)
        normal = frame.meso_normal(grad, self.D * self._world_tile(si, self.used_tile, active))
        return (frame, T), dr.zeros(mi.Bool, dr.width(T.x)), shading_interaction(si, si.uv, normal, frame.a)

    def _lit(self, state, wo_world, active):
        frame, T = state
        ct, theta, phi, _ = frame.direction(wo_world)
        return (ct > 0) & (dr.pi / 2 - theta > self.lookup.beta(T, phi))

    def _sizes(self) -> dict:
        return {"res": self.res, "azimuths": self.azimuths}

    def to_string(self):
        return f"Horizon[res={self.res}, azimuths={self.azimuths}, depth={self.depth}]"


class Relief(MesostructureBSDF):
    """Relief mapping on the (locally flat) reference surface."""

    PLUGIN = "relief"

    def __init__(self, props: mi.Properties, values: dict):
        super().__init__(props, values)
        self.steps, self.refine = values["steps"], values["refine"]
        self.shadow_steps = values["shadow_steps"]
        self.tiled = TiledHeight(self.height, self.tiling, 1e-3)
        self.used_tile = None
        if self.tile_size is not None:
            self._setup(self.tile_size, None)

    def _setup(self, tile_size, meshes):
        self.used_tile = float(tile_size)
        self._check_periodic(table.sample_heights(self.height, 64, self.tiling, self.PLUGIN))
        self.stats.update(tile_size=self.used_tile, table_bytes=0)

    def _ready(self) -> bool:
        return self.used_tile is not None

    def _prepare(self, si, active):
        D = self.depth / self.used_tile
        frame = TileFrame(si, self.tiling)
        ct, _, _, step = frame.direction(si.to_world(si.wi))
        tile = self._world_tile(si, self.used_tile, active)
        T = mi.Point2f(si.uv.x * self.tiling[0], si.uv.y * self.tiling[1])
        if D > 0:
            T, h = march_view(self.tiled, T, ct, step * tile, D, self.steps, self.refine)
        else:
            h = dr.zeros(mi.Float, dr.width(T.x))
        _, grad = self.tiled(T)
        normal = frame.meso_normal(grad, D * tile)
        uv = self.tiled.uv(T)
        return (frame, T, h, D, tile), dr.zeros(mi.Bool, dr.width(T.x)), shading_interaction(si, uv, normal, frame.a)

    def _lit(self, state, wo_world, active):
        frame, T, h, D, tile = state
        ct, _, _, step = frame.direction(wo_world)
        if self.shadow_steps == 0 or D == 0:
            return ct > 0
        return (ct > 0) & ~march_shadow(self.tiled, T, h, ct, step * tile, D,
                                        self.shadow_steps, mi.Bool(active) & (ct > 0))

    def _sizes(self) -> dict:
        return {"steps": self.steps, "shadow_steps": self.shadow_steps}

    def to_string(self):
        return f"Relief[steps={self.steps}, refine={self.refine}, depth={self.depth}]"
