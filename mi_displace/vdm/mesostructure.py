"""The per-pixel mesostructure BSDFs' common base (VDM §3, horizon and relief mapping).

A mesostructure BSDF shades a coarse reference surface as if a height field lay under it:
``_prepare`` finds the visible mesostructure point of a ray (or where the ray passes through,
at silhouettes), ``_lit`` whether the light reaches it, and the nested BSDF shades it with
the mesostructure normal.  The tile size (world units of one texture tile) comes from the
``vdm_mesh`` the BSDF sits in (:meth:`MesostructureBSDF.attach`) or from ``tile_size``.

:data:`PARAMS` are the parameters every such plugin shares (``vdm``, ``horizon``,
``relief``, and the slicing BSDFs).
"""
from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.core.properties import REQUIRED, Param, PluginSpec
from mi_displace.core.texture_height import check_texture_finite, warn_if_srgb
from mi_displace.vdm import table
from mi_displace.vdm.steps import placement_scale
from mi_displace.core.collector import collector_paused

#: Parameters shared by the mesostructure BSDFs (a nested ``bsdf`` is the shaded material).
PARAMS = (
    Param("height", "texture", REQUIRED, "height H in [0, 1] (1 = the reference surface)"),
    Param("depth", "float", 0.05, "depth of H = 0 below the reference surface", unit="world", low=0),
    Param("tiling", "float", None, "texture periods per unit u and v (default of both below)", low=0, open_low=True),
    Param("tiling_u", "float", None, "texture periods per unit u (default: tiling, else 1)", low=0, open_low=True),
    Param("tiling_v", "float", None, "texture periods per unit v (default: tiling, else 1)", low=0, open_low=True),
    Param("tile_size", "float", None, "world size of one texture tile, for use outside a "
          "vdm_mesh (else measured by the vdm_mesh)", unit="world", low=0, open_low=True),
)


def read_shared(props: mi.Properties, plugin: str) -> dict:
    """Only the shared :data:`PARAMS` of ``props`` (a BSDF built inside another plugin)."""
    return PluginSpec(plugin, "bsdf", "", PARAMS).read(props)


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



def nested_bsdf(props: mi.Properties, plugin: str) -> mi.BSDF:
    """The one nested BSDF of ``props`` (a ``diffuse`` when none is given)."""
    bsdfs = nested_objects(props, mi.BSDF)
    if len(bsdfs) > 1:
        raise ValueError(f"{plugin}: expected at most one nested BSDF, got {len(bsdfs)}")
    return bsdfs[0][1] if bsdfs else mi.load_dict({"type": "diffuse"})


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

    def __init__(self, props: mi.Properties, values: dict):
        """``values``: the plugin's parameters read by its spec (:data:`PARAMS` and its own)."""
        super().__init__(props)
        check_texture_finite(values["height"])
        warn_if_srgb(values["height"], self.PLUGIN)
        self.nested = nested_bsdf(props, self.PLUGIN)
        self.height, self.depth, self.tile_size = values["height"], values["depth"], values["tile_size"]
        tiling = values["tiling"]
        self.tiling = tuple(1.0 if t is None else t for t in (
            values["tiling_u"] if values["tiling_u"] is not None else tiling,
            values["tiling_v"] if values["tiling_v"] is not None else tiling))
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
        # is the view (T', silhouettes) and si.wi the light.  Mitsuba's ptracer applies
        # Veach's shading-normal correction between si.sh_frame and the geometric normal
        # itself, so the meso normal needs it only relative to si.sh_frame:
        # f*(wi -> wo) = f(wo -> wi) |wi . n_m| |wo . n_s| / |wi . n_s| (Veach 1997, §5.3)
        si_v = mi.SurfaceInteraction3f(si)
        si_v.wi = wo
        radiance = mi.BSDFContext(mi.TransportMode.Radiance, ctx.type_mask, ctx.component)
        f = self._eval_radiance(radiance, si_v, si.wi, active)
        cos_light = dr.abs(mi.Frame3f.cos_theta(si.wi))
        correction = dr.select(cos_light > 0, dr.abs(mi.Frame3f.cos_theta(wo)) / cos_light, 0.0)
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
