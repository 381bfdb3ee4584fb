"""``<bsdf type="vdm">``: view-dependent displacement mapping (Wang et al. 2003).

.. code-block:: xml

    <shape type="vdm_mesh">                      <!-- gives curvature + tile size -->
        <string name="base" value="torus"/> ...
        <bsdf type="vdm">
            <texture type="cells" name="height"/>  <!-- H in [0, 1], 1 = reference surface -->
            <float name="depth" value="0.03"/>       <!-- world units below the surface -->
            <float name="tiling_u" value="24"/>      <!-- texture periods per unit u -->
            <float name="tiling_v" value="8"/>
            <integer name="res" value="128"/>        <!-- table sizes (paper: 128, 8, 32, 16) -->
            <integer name="theta" value="8"/>
            <integer name="phi" value="32"/>
            <integer name="curvatures" value="16"/>
            <integer name="svd_terms" value="8"/>   <!-- paper: 8 VDM + 4 MVM -->
            <integer name="mvm_terms" value="4"/>
            <boolean name="shadows" value="true"/>
            <integer name="refine_steps" value="8"/>  <!-- T' refinement; 0 = the paper -->
            <integer name="shadow_verify" value="3"/> <!-- shadow check; 0 = the paper -->
            <bsdf type="diffuse"/>                   <!-- the nested material -->
        </bsdf>
    </shape>

The table is built when the ``vdm_mesh`` shape attaches (curvature range measured on that
mesh, tile size from its UVs); with an explicit ``tile_size`` it is built at once for flat
use on any shape (c_V = 0).  Algorithm: :mod:`mi_displace.vdm`.
"""
from __future__ import annotations

import math
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.texture_height import check_texture_finite
from mi_displace.vdm import auto, build, table
from mi_displace.vdm.lookup import cached_lookup
from mi_displace.plugins._guard import boolean, collector_paused, constructor
from mi_displace.vdm.steps import VDMSteps, placement_scale


def _number(plugin, props, name, default, low=None, high=None, integer=False):
    """Property ``name`` as a finite number in [low, high] (an int with ``integer``), else a
    ValueError naming ``plugin`` and the property."""
    value = props.get(name, default)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{plugin}: '{name}' must be a number, got {value!r}") from None
    if not math.isfinite(x) or (low is not None and x < low) or (high is not None and x > high):
        bounds = f"{'(-inf' if low is None else f'[{low}'}, {'inf)' if high is None else f'{high}]'}"
        raise ValueError(f"{plugin}: '{name}' must be finite and in {bounds}, got {value!r}")
    if integer:
        if x != int(x):
            raise ValueError(f"{plugin}: '{name}' must be an integer, got {value!r}")
        return int(x)
    return x


def nested_objects(props: mi.Properties, cls):
    """The nested objects of type ``cls`` in ``props`` as (name, object) pairs."""
    out = []
    for name in props.keys():
        # read objects only: props.get marks a property as used, and reading every key
        # would hide the user's misspelt parameters from Mitsuba's unreferenced check
        if props.type(name) == mi.Properties.Type.Object:
            value = props.get(name)
            if isinstance(value, cls):
                out.append((name, value))
    return out


def parse_mesostructure(props: mi.Properties, plugin: str):
    """Common parameters of the mesostructure BSDFs (vdm, horizon, relief).

    Returns:
        dict with ``nested`` (mi.BSDF), ``height`` (mi.Texture), ``depth`` [world units],
        ``tiling`` (u, v), ``tile_size`` [world units] or None.
    """
    height = props.get("height", None)
    if not isinstance(height, mi.Texture):
        raise ValueError(f"{plugin}: 'height' must be a nested texture (H in [0, 1])")
    check_texture_finite(height)
    bsdfs = nested_objects(props, mi.BSDF)
    if len(bsdfs) > 1:
        raise ValueError(f"{plugin}: expected at most one nested BSDF, got {len(bsdfs)}")
    nested = bsdfs[0][1] if bsdfs else mi.load_dict({"type": "diffuse"})
    depth = props.get("depth", 0.05)
    try:
        depth = float(depth)
    except (TypeError, ValueError):
        raise ValueError(f"{plugin}: 'depth' must be a number, got {depth!r}") from None
    if not math.isfinite(depth) or depth < 0:
        raise ValueError(f"{plugin}: 'depth' must be finite and >= 0 (world units below the "
                         f"reference surface), got {depth!r}")
    tiling = props.get("tiling", None)
    tu = _number(plugin, props, "tiling_u", 1.0 if tiling is None else tiling, 1e-6)
    tv = _number(plugin, props, "tiling_v", 1.0 if tiling is None else tiling, 1e-6)
    tile_size = props.get("tile_size", None)
    if tile_size is not None:
        tile_size = _number(plugin, props, "tile_size", tile_size, 1e-9)
    return dict(nested=nested, height=height, depth=depth, tiling=(tu, tv), tile_size=tile_size)



def _round_out(x: float, direction, digits: int = 4) -> float:
    """``x`` rounded to ``digits`` significant digits with ``direction`` (math.floor/ceil)."""
    if x == 0 or not math.isfinite(x):
        return x
    step = 10.0 ** (math.floor(math.log10(abs(x))) - digits + 1)
    return direction(x / step) * step

class MesostructureBSDF(mi.BSDF):
    """Base of the per-pixel mesostructure BSDFs: flags, nested BSDF plumbing.

    Subclasses implement ``_setup(tile_size, meshes)`` (precomputation once the tile size is
    known: at construction when ``tile_size`` is given, else when a ``vdm_mesh`` attaches),
    ``_prepare(si, active) -> (state, blocked, si_shading)`` and
    ``_lit(state, wo_world, active) -> mi.Bool`` (only the ``active`` lanes' answers are
    read: a light walk leaves the others out).  ``HAS_SILHOUETTE = False`` techniques never pass
    rays through (no null transmission, no march inside the raster alpha test).
    """

    PLUGIN = "mesostructure"
    HAS_SILHOUETTE = False

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        p = parse_mesostructure(props, self.PLUGIN)
        self.nested, self.height, self.depth = p["nested"], p["height"], p["depth"]
        self.tiling, self.tile_size = p["tiling"], p["tile_size"]
        comps = [self.nested.flags(i) for i in range(self.nested.component_count())]
        null = mi.BSDFFlags.Null | mi.BSDFFlags.FrontSide
        self.null_index = len(comps)
        self.m_components = comps + [int(null)]
        flags = int(null)
        for c in comps:
            flags |= int(c)
        self.m_flags = flags | int(mi.BSDFFlags.SpatiallyVarying)

        self.stats: dict = {}
        self._meshes: list[dict] = []

    def attach(self, mesh_info: dict) -> None:
        """Called by ``vdm_mesh``: measured tile size and per-vertex principal curvatures.

        Args:
            mesh_info: ``tile_size`` [world], ``tile_spread`` (relative), ``c_max``, ``c_min``
                (V,) [1 / world units], ``name``.
        """
        self._meshes.append(mesh_info)
        tile = self.tile_size if self.tile_size is not None else float(
            np.mean([m["tile_size"] for m in self._meshes]))
        self._setup(tile, self._meshes)
        spread = max(m["tile_spread"] for m in self._meshes)
        self.stats["tile_spread"] = spread
        if spread > 0.25:
            mi.Log(mi.LogLevel.Warn,
                   f"{self.PLUGIN}: the texture tile's world size varies by {100 * spread:.0f}% "
                   f"over mesh {mesh_info.get('name')!r} (UV scale mismatch): the table assumes "
                   f"one tile size ({tile:.4g}); expect stretched relief there")

    def _check_periodic(self, heights) -> None:
        """Warn (once) when one tile is not one period of the height texture."""
        message = table.periodicity_warning(heights, self.PLUGIN, self.tiling)
        if message and message != self.stats.get("periodicity_warning"):
            self.stats["periodicity_warning"] = message
            warnings.warn(message)
            mi.Log(mi.LogLevel.Warn, message)

    @property
    def build_stats(self) -> dict:
        """What was built and why (``render --explain``): table dims, bytes, build time,
        cache hit, the tile size and, with ``"auto"`` sizes, the projected tile size."""
        keys = ("res", "theta", "phi", "curvatures", "svd_terms", "mvm_terms", "auto",
                "table_bytes", "compressed_bytes", "build_time_s", "load_time_s", "cached",
                "tile_size", "depth_tile", "c_range_tile", "n_curvatures", "azimuths",
                "steps", "shadow_steps")
        merged = dict(self.stats, **self._sizes())
        return {k: merged[k] for k in keys if k in merged}

    def _sizes(self) -> dict:
        """The plugin's own size parameters (subclasses)."""
        return {}

    def _world_tile(self, si, tile_size: float, active) -> mi.Float:
        """World size of one tile at ``si``: ``tile_size`` (the mesh's own units) times the
        placement scale of a ``vdm_mesh`` (its to_world, an instance); ``tile_size`` as
        given on other shapes."""
        if not self._meshes:
            return dr.full(mi.Float, tile_size, dr.width(si.t))
        return tile_size * placement_scale(si, active)

    def setup_problem(self) -> str | None:
        """Why this BSDF cannot render its mesostructure (one line), or ``None`` when it can.

        Scene loaders call it after loading (``mi_displace.render.scene.load``, the CLI) and
        turn a message into an error before anything renders."""
        if self._ready():
            return None
        return (f"{self.PLUGIN}: BSDF {self.id()!r} is not set up: put it inside a "
                "<shape type=\"vdm_mesh\"> (tile size and curvature measured there) or give "
                "'tile_size' [world units of one texture tile]")

    def _require(self, ready: bool) -> None:
        if not ready:
            raise ValueError(self.setup_problem())

    def _ready(self) -> bool:
        """Whether the precomputation is done (subclasses that set up late)."""
        return True

    def _unused(self) -> bool:
        """True for a BSDF that is not set up: it traces as its nested material.

        Never an exception inside a trace: Dr.Jit traces every live BSDF into each
        vectorised call, also those of other scenes still alive (a reference cycle, a
        notebook's last traceback), so a raise here would break renders of scenes that do
        not hold this BSDF.  The user hears of it once, by a warning naming the fix; our
        loaders refuse such a scene before rendering (``setup_problem``)."""
        if self._ready():
            return False
        if not self.stats.get("not_set_up_warned"):
            self.stats["not_set_up_warned"] = True
            message = self.setup_problem() + "; it renders as its nested BSDF"
            warnings.warn(message)
            mi.Log(mi.LogLevel.Warn, message)
        return True

    def _state(self, si, active):
        """``_prepare(si, active)``; for an unused BSDF (``_unused``) the nested material's
        own interaction, nothing blocked, and state ``None`` (lit everywhere)."""
        if self._unused():
            return None, dr.zeros(mi.Bool, dr.width(si.t)), si
        return self._prepare(si, active)

    def _lit_state(self, state, wo_world, active) -> mi.Bool:
        return mi.Bool(True) if state is None else self._lit(state, wo_world, active)

    # -- to implement --------------------------------------------------------------------
    def _setup(self, tile_size: float, meshes) -> None:
        raise NotImplementedError

    def _prepare(self, si, active):
        raise NotImplementedError

    def _lit(self, state, wo_world, active):
        raise NotImplementedError

    def _facing(self, w: mi.Vector3f) -> mi.Bool:
        """Whether local direction ``w`` lies on the front side of the proxy surface (a
        technique whose proxy is a volume boundary, not a surface, overrides it)."""
        return w.z > 0

    def _blocked(self, si, active) -> mi.Bool:
        """Where the ray passes through (only for HAS_SILHOUETTE techniques)."""
        return active & self._state(si, active)[1]

    # -- mi.BSDF -------------------------------------------------------------------------
    def _eval_radiance(self, ctx, si, wo, active):
        """f cos(theta_o) with the view along si.wi and the light along wo (radiance)."""
        active = mi.Bool(active) & self._facing(si.wi)
        state, blocked, si2 = self._state(si, active)
        wo_world = si.to_world(wo)
        ok = active & ~blocked & self._facing(wo)
        f = self.nested.eval(ctx, si2, si2.to_local(wo_world), ok)
        ok &= self._lit_state(state, wo_world, ok)
        return dr.select(ok, mi.Spectrum(f), 0.0)

    @collector_paused
    def eval(self, ctx, si, wo, active=True):
        if ctx.mode != mi.TransportMode.Importance:
            return self._eval_radiance(ctx, si, wo, active)
        # adjoint transport (ptracer): the path towards the sensor leaves along wo, so wo
        # is the view (T', silhouettes) and si.wi the light; the value is the radiance
        # one with the roles swapped, times Veach's shading-normal correction
        # |wo.Ng| / |wi.Ng| (the meso normal is a shading normal of the coarse mesh)
        si_v = mi.SurfaceInteraction3f(si)
        si_v.wi = wo
        radiance = mi.BSDFContext(mi.TransportMode.Radiance, ctx.type_mask, ctx.component)
        f = self._eval_radiance(radiance, si_v, si.wi, active)
        ng = si.to_local(si.n)
        correction = dr.abs(dr.dot(wo, ng)) / dr.maximum(dr.abs(dr.dot(si.wi, ng)), 1e-6)
        return f * correction

    @collector_paused
    def pdf(self, ctx, si, wo, active=True):
        active = mi.Bool(active) & self._facing(si.wi)
        _, blocked, si2 = self._state(si, active)
        ok = active & ~blocked
        return dr.select(ok, self.nested.pdf(ctx, si2, si2.to_local(si.to_world(wo)), ok), 0.0)

    @collector_paused
    def eval_pdf(self, ctx, si, wo, active=True):
        active = mi.Bool(active) & self._facing(si.wi)
        state, blocked, si2 = self._state(si, active)
        wo_world = si.to_world(wo)
        ok = active & ~blocked
        f, pdf = self.nested.eval_pdf(ctx, si2, si2.to_local(wo_world), ok)
        pdf = dr.select(ok, pdf, 0.0)
        if ctx.mode == mi.TransportMode.Importance:
            return self.eval(ctx, si, wo, active), pdf
        lit = ok & self._facing(wo)
        lit &= self._lit_state(state, wo_world, lit)
        return dr.select(lit, mi.Spectrum(f), 0.0), pdf

    @collector_paused
    def sample(self, ctx, si, sample1, sample2, active=True):
        active = mi.Bool(active)
        state, blocked, si2 = self._state(si, active)
        front = active & ~blocked & self._facing(si.wi)
        bs, weight = self.nested.sample(ctx, si2, sample1, sample2, front)
        wo_world = si2.to_world(bs.wo)
        wo = si.to_local(wo_world)
        keep = front & self._facing(wo)
        keep &= self._lit_state(state, wo_world, keep)
        weight = dr.select(keep, mi.Spectrum(weight), 0.0)
        if ctx.mode == mi.TransportMode.Importance:
            # sampled in the frame seen from wi, weighted by the adjoint value (eval)
            keep = front & self._facing(wo) & (bs.pdf > 0)
            weight = dr.select(keep, self.eval(ctx, si, wo, keep) / dr.maximum(bs.pdf, 1e-30), 0.0)
        passes = active & blocked  # silhouette: the ray goes on (Null component)
        bs.wo = dr.select(passes, -si.wi, wo)
        bs.pdf = dr.select(passes, 1.0, dr.select(keep, bs.pdf, 0.0))
        bs.eta = dr.select(passes, 1.0, bs.eta)
        bs.sampled_type = dr.select(passes, mi.UInt32(int(mi.BSDFFlags.Null)), bs.sampled_type)
        bs.sampled_component = dr.select(passes, mi.UInt32(self.null_index), bs.sampled_component)
        return bs, dr.select(passes, 1.0, weight)

    @collector_paused
    def eval_null_transmission(self, si, active=True):
        active = mi.Bool(active)
        if not self.HAS_SILHOUETTE:
            return dr.zeros(mi.Spectrum, dr.width(si.uv))
        return mi.Spectrum(dr.select(self._blocked(si, active), 1.0, 0.0))

    @collector_paused
    def eval_diffuse_reflectance(self, si, active=True):
        active = mi.Bool(active)
        _, blocked, si2 = self._state(si, active)
        albedo = self.nested.eval_diffuse_reflectance(si2, active & ~blocked)
        return dr.select(active & ~blocked, mi.Spectrum(albedo), 0.0)

    def traverse(self, cb):
        # the nested material's parameters (nested.*), editable and differentiable as on
        # any Mitsuba BSDF; the table itself is not a parameter (it depends on the height
        # texture only through a precomputation)
        cb.put("nested", self.nested, mi.ParamFlags.Differentiable)


class VDM(MesostructureBSDF):
    """View-dependent displacement mapping (paper §3)."""

    PLUGIN = "vdm"
    HAS_SILHOUETTE = True

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.auto = {k for k in ("res", "theta") if str(props.get(k, "")).strip() == "auto"}
        self.sensor = props.get("sensor", None) if "sensor" in props else None
        if self.auto and not isinstance(self.sensor, mi.Sensor):
            raise ValueError("vdm: 'res'/'theta' = 'auto' sizes the table from the projected "
                             "size of one tile: give the sensor (<ref name=\"sensor\" "
                             "id=\"...\"/>)")
        self.spec = build.VDMSpec(
            res=128 if "res" in self.auto else _number("vdm", props, "res", 128, 1, 1024, True),
            n_theta=8 if "theta" in self.auto else _number("vdm", props, "theta", 8, 2, 64, True),
            n_phi=_number(self.PLUGIN, props, "phi", 32, 4, 256, True),
            n_curv=_number(self.PLUGIN, props, "curvatures", 16, 1, 64, True),
            theta_oversample=_number(self.PLUGIN, props, "theta_oversample", 1, 1, 8, True))
        self.svd_terms = _number(self.PLUGIN, props, "svd_terms", 8, 1, build.K_STORED, True)
        self.mvm_terms = _number(self.PLUGIN, props, "mvm_terms", 4, 1, build.K_STORED, True)
        self.shadows = boolean(self.PLUGIN, props, "shadows", True)
        self.shadow_bias = _number(self.PLUGIN, props, "shadow_bias", 0.0, 0.0)
        self.shadow_slack = _number(self.PLUGIN, props, "shadow_slack", 0.0, 0.0)
        self.shadow_verify = _number(self.PLUGIN, props, "shadow_verify", 3, 0, 64, True)
        self.refine_steps = _number(self.PLUGIN, props, "refine_steps", 8, 0, 256, True)
        self.refine_window = _number(self.PLUGIN, props, "refine_window", 0.5, 0.0, 10.0)
        self.use_cache = boolean(self.PLUGIN, props, "cache", True)
        self.curvature_percentile = _number(self.PLUGIN, props, "curvature_percentile",
                                            0.0, 0.0, 49.0)
        c_min, c_max = props.get("curvature_min", None), props.get("curvature_max", None)
        self.fixed_range = None
        if (c_min is None) != (c_max is None):
            raise ValueError("vdm: give both 'curvature_min' and 'curvature_max' or neither")
        if c_min is not None:
            lo = _number(self.PLUGIN, props, "curvature_min", c_min)
            hi = _number(self.PLUGIN, props, "curvature_max", c_max)
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


def register():
    mi.register_bsdf("vdm", constructor("vdm", VDM))
