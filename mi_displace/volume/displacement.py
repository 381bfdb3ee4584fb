"""Displacement textures D_k (§4.1), placed maps (§6) and their composition (eq. 9-10).

A :class:`PlacedMap` is one primitive of :mod:`mi_displace.volume.maps` with its own
parameters, D_k resolution and placement M.  Its :class:`SampledMap` holds the §4.1 textures
over the map's support box (node-centred grid, clamp-to-edge addressing):

* ``disp``: the inverse displacement M D(M⁻¹ p') in world units and 1 - α_s (4 channels;
  1 - α so that an all-kept map interpolates to exactly α = 1), α_s the α mask smoothed by a
  Gaussian of ``smoothing`` voxels (§5), all quantised to ``bits`` (8, 16 or 32 = float):
  D normalised to [-1, 1] by its largest component (signed normalised: D = 0 stays exact);
* ``jac``: J_D of the world map by central differences of the *stored* D_k at the voxel
  spacing (9 channels); B = (I + J_D)ᵀ of eq. 6 is formed at lookup (so J = 0 gives B = I
  exactly);
* ``galpha``: ∇α_s in world units (3 channels), for eq. 7.

Each texture stores only its channels that are non-zero at some node (:class:`ChannelTexture`),
and a coarse flag grid (:func:`nonzero_cells`) marks the cells where every channel is zero, so
lookups there read nothing; both are bit-exact.

A :class:`DisplacementChain` composes maps listed in *forward* order (the first acts on the
object first): p = G_1(G_2(... G_n(p'))) (eq. 9), so lookups run from the last map to the
first.  The normal matrix of the chain is B = B_n(p') B_{n-1}(q_{n-1}) ... B_1(q_1) (the chain
rule; eq. 10 writes the same product for two maps), α = Π α_i(q_i), ∇α by the product rule.
``composition="precomputed"`` samples the whole exact chain into one D_k over the union of the
supports instead (no change in the renderer, one lookup, its own resolution).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.volume import maps, objects

BITS = (8, 16, 32)
#: Most voxels of one D_k (refused before anything is allocated).
MAX_MAP_VOXELS = 256 ** 3


def check_resolution(res, what: str) -> tuple[int, int, int]:
    """A D_k resolution (x, y, z): integers >= 2 (central differences), at most MAX_MAP_VOXELS."""
    return objects.check_resolution(res, what, minimum=2, limit=MAX_MAP_VOXELS)


def quantise(values: np.ndarray, bits: int, scale: float) -> np.ndarray:
    """Store ``values`` in [-scale, scale] at ``bits`` (8/16: signed normalised, 2^(bits-1) - 1
    steps each side, as GPU snorm formats, so that 0 and ±scale stay exact; 32: float)."""
    if bits == 32 or scale == 0:
        return values.astype(np.float32)
    levels = 2 ** (bits - 1) - 1
    q = np.round(np.clip(values / scale, -1, 1) * levels)
    return (q / levels * scale).astype(np.float32)


def quantise_unit(values: np.ndarray, bits: int) -> np.ndarray:
    """Store values in [0, 1] at ``bits`` (0 and 1 stay exact)."""
    if bits == 32:
        return values.astype(np.float32)
    levels = 2 ** bits - 1
    return (np.round(np.clip(values, 0, 1) * levels) / levels).astype(np.float32)


def _grid_points(lo, hi, res) -> tuple[mi.Point3f, np.ndarray]:
    """Node-centred grid over [lo, hi] (z slowest): Dr.Jit points and the spacing (3,)."""
    axes = [np.linspace(lo[i], hi[i], res[i]) for i in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    p = mi.Point3f(mi.Float(x.ravel()), mi.Float(y.ravel()), mi.Float(z.ravel()))
    return p, (np.asarray(hi, float) - np.asarray(lo, float)) / (np.array(res) - 1)


#: D_k nodes per axis of one cell of the "D nonzero" flag grid (:func:`nonzero_cells`).
FLAG_NODES = 2


def nonzero_cells(nonzero: np.ndarray) -> np.ndarray:
    """Per cell of FLAG_NODES D_k nodes a side, whether a trilinear read there may touch a
    non-zero node.  ``nonzero``: (z, y, x) node mask.  A read at texel position t = u n - 1/2
    uses nodes floor(t) and floor(t) + 1 (clamped to the grid); with j = clip(floor(t), -1,
    n - 1) + 1 in [0, n] its cell is j // FLAG_NODES, flagged when any node within one more of
    the cell's reads is non-zero (a margin against rounding of t).  Returns a (z, y, x) bool
    array of (n + FLAG_NODES) // FLAG_NODES cells per axis."""
    from numpy.lib.stride_tricks import sliding_window_view

    b, flags = FLAG_NODES, nonzero
    for axis in range(3):
        n = nonzero.shape[axis]
        cells = (n + b) // b
        pad = [(0, 0)] * 3
        pad[axis] = (2, cells * b + 2 - n)   # node k - 2 at index k; cell c reads nodes [cb - 2, cb + b + 1]
        window = sliding_window_view(np.pad(flags, pad, mode="edge"), b + 4, axis=axis).any(-1)
        flags = np.take(window, np.arange(cells) * b, axis=axis)
    return flags


def read_box(nonzero: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Texture-coordinate box (lo (3,), hi (3,), x y z) outside which every trilinear read of a
    D_k touches only zero nodes (so reads exactly D = 0, α = 1, J = 0, ∇α = 0), or None where
    it would cover every coordinate.  ``nonzero``: (z, y, x) node mask.  With the non-zero
    nodes in [k0, k1] along an axis of n nodes, a read at texel position t = u n - 1/2 uses
    nodes floor(t) and floor(t) + 1 (clamped), all zero for t < k0 - 1 or t >= k1 + 1; one
    node more each side covers the rounding of t: u in [(k0 - 3/2) / n, (k1 + 5/2) / n)
    (unbounded where k0 = 0 or k1 = n - 1: clamp-to-edge reads those nodes beyond the face)."""
    if not nonzero.any():
        return np.zeros(3), np.zeros(3)
    lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    for a in range(3):  # x, y, z: array axes 2, 1, 0
        used = np.flatnonzero(nonzero.any(axis=tuple(k for k in range(3) if k != 2 - a)))
        n = nonzero.shape[2 - a]
        if used[0] > 0:
            lo[a] = (used[0] - 1.5) / n
        if used[-1] < n - 1:
            hi[a] = (used[-1] + 2.5) / n
    return None if np.isinf(lo).all() and np.isinf(hi).all() else (lo, hi)


class ChannelTexture:
    """A trilinear, clamp-to-edge 3-D texture of C channels ((z, y, x, C) array) that stores
    only its channels that are non-zero at some node: the others read exactly 0 without a
    gather (a Gaussian pull's D = (0, 0, D_z) and J with one non-zero row are one and three
    channels, not 4 and 9 — Dr.Jit gathers 2^k channels a node, 9 as 16)."""

    def __init__(self, array: np.ndarray):
        self.channels = array.shape[-1]
        self.stored = [c for c in range(self.channels) if np.any(array[..., c] != 0)]
        self.texture = None if not self.stored else mi.Texture3f(
            mi.TensorXf(np.ascontiguousarray(array[..., self.stored], dtype=np.float32)), use_accel=False,
            filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)

    def eval(self, u: mi.Point3f, active=True) -> list:
        """The C channels at texture coordinates u (list of Float)."""
        zero = dr.zeros(mi.Float, dr.width(u.x))
        out = [zero] * self.channels
        if self.texture is not None:
            for c, v in zip(self.stored, self.texture.eval(u, active)):
                out[c] = v
        return out


class SampledMap:
    """The §4.1 textures of one world-space displacement over a local box (module docstring).

    Args:
        inverse: callable(world points p') -> (world D, α exact in {0, 1}), Dr.Jit.
        placement: local frame of the grid (:class:`maps.Placement`).
        lo, hi: local box (3,) sampled by the grid; res: (x, y, z) nodes.
        bits: 8, 16 or 32; smoothing: α smoothing width in voxels (0: none).
    """

    def __init__(self, inverse, placement: maps.Placement, lo, hi, res, bits=16, smoothing=1.5):
        from scipy.ndimage import gaussian_filter

        res = check_resolution(res, "D_k resolution")
        if bits not in BITS:
            raise ValueError(f"bits: must be one of {BITS}, got {bits!r}")
        if not smoothing >= 0:
            raise ValueError(f"smoothing: must be >= 0 voxels, got {smoothing!r}")
        self.placement, self.res, self.bits, self.smoothing = placement, res, bits, smoothing
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        local, h = _grid_points(self.lo, self.hi, res)
        d, alpha = inverse(placement.to_world(local))
        shape = (res[2], res[1], res[0])
        d = np.stack([np.asarray(c, dtype=np.float64).reshape(shape) for c in d], axis=-1)
        alpha = np.asarray(alpha, dtype=np.float64).reshape(shape)
        if not np.isfinite(d).all():
            raise ValueError("displacement map: D is not finite on its grid (check the map parameters)")
        self.scale = float(np.abs(d).max())
        d = quantise(d, bits, self.scale)
        # signed range of the stored D per axis (0 included: lanes outside a bounded grid)
        self.d_min = np.minimum(d.reshape(-1, 3).min(0), 0.0)
        self.d_max = np.maximum(d.reshape(-1, 3).max(0), 0.0)
        if smoothing > 0 and alpha.min() < 1:
            alpha = gaussian_filter(alpha, sigma=smoothing, mode="nearest")
        alpha = quantise_unit(alpha, bits).astype(np.float64)
        # J of the world map: local derivatives of world D, then d/dp' = d/dl L^-1
        lin_inv = placement.inverse[:3, :3]
        dl = np.stack(np.gradient(d, h[2], h[1], h[0], axis=(0, 1, 2))[::-1], axis=-1)  # (..., comp, l_axis)
        jac = np.einsum("...ij,jk->...ik", dl, lin_inv)
        ga_l = np.stack(np.gradient(alpha, h[2], h[1], h[0])[::-1], axis=-1)
        galpha = np.einsum("...j,jk->...k", ga_l, lin_inv)
        self.disp = ChannelTexture(np.concatenate([d, (1.0 - alpha)[..., None]], axis=-1))
        self.jac = ChannelTexture(jac.reshape(*shape, 9))
        self.galpha = ChannelTexture(galpha)
        self.voxels = int(np.prod(res))
        # D_k cells whose trilinear reads give exactly D = 0, α = 1, J = 0, ∇α = 0 (the
        # undisplaced part of the map's region, and beyond its faces by clamp-to-edge):
        # lookups there skip the reads (None: no such cell, or a D/α read of one channel, which
        # costs no more than the flag gather and the branch: 1.00-1.19x as slow with them on
        # the bench's Gaussian pull, 0.81-0.95x on a 3-channel peel; docs/volume.md)
        zero = np.concatenate([d, 1.0 - alpha[..., None], jac.reshape(*shape, 9), galpha], axis=-1)
        nonzero = np.abs(zero).max(-1) > 0
        self.flags = flags = nonzero_cells(nonzero)
        skip = not flags.all() and len(self.disp.stored) > 1
        self.nonzero = mi.Float(flags.astype(np.float32).ravel()) if skip else None
        self.flag_cells = flags.shape[::-1]
        self.read_box = read_box(nonzero)

    def nbytes(self, all_channels: bool = False) -> int:
        """Texture bytes at the stored bit depth: the stored channels of D 3 + α 1 + J 9 +
        ∇α 3 (:class:`ChannelTexture` drops the all-zero ones), or all 16 (the full format)."""
        stored = 16 if all_channels else sum(len(t.stored) for t in (self.disp, self.jac, self.galpha))
        return self.voxels * stored * (self.bits // 8)

    def _coords(self, p: mi.Point3f) -> mi.Point3f:
        l = self.placement.to_local(p)
        n = mi.ScalarVector3f(self.res)
        lo, hi = mi.ScalarPoint3f(self.lo), mi.ScalarPoint3f(self.hi)
        return mi.Point3f((l - lo) / (hi - lo) * (n - 1) / n + 0.5 / n)

    def lookup(self, p: mi.Point3f, active=True):
        """(D, α_s) at world points p' (world units); lanes outside ``active``, or in a cell of
        :func:`nonzero_cells` that is all zero, read nothing (D = 0, α = 1 there: bit for bit
        what the reads would give)."""
        return self._branch(p, active, self._read, self._outside)

    def derivatives(self, p: mi.Point3f, alpha_gradient=True, active=True):
        """(Jᵀ, ∇α_s or None) at world points p' (world units), the normal terms, read apart
        from :meth:`lookup` so that a renderer reads them only where it shades; all-zero cells
        read nothing as in :meth:`lookup` (J = 0, ∇α = 0)."""
        return self._branch(p, active, lambda u, act: self._read_derivatives(u, alpha_gradient, act),
                            lambda u: self._outside_derivatives(u, alpha_gradient))

    def _branch(self, p, active, read, outside):
        """``read(u, active)`` at the texture coordinates u of p', or ``outside(u)`` in the
        all-zero cells of :func:`nonzero_cells` (when the flag grid is in use)."""
        u = self._coords(p)
        if self.nonzero is None and self.read_box is None:
            return read(u, active)
        # a symbolic branch skips the reads in all-zero cells (on the LLVM backend too, a
        # packet of samples with none in a displaced cell jumps over it): outside the box of
        # the flagged cells (a few comparisons) and, for reads wider than one channel, in the
        # unflagged cells inside it (one gather of the flag grid)
        inside = mi.Bool(active)
        if self.read_box is not None:
            lo, hi = (mi.ScalarPoint3f(b) for b in self.read_box)
            inside &= dr.all((u >= lo) & (u < hi))
        if self.nonzero is not None:
            # the cell of texel position t = u n - 1/2 (nonzero_cells): floor((floor(t) + 1) / b)
            n, cx, cy = mi.ScalarVector3f(self.res), int(self.flag_cells[0]), int(self.flag_cells[1])
            c = mi.Vector3u(dr.clip(dr.floor((u * n + 0.5) * (1.0 / FLAG_NODES)), 0.0,
                                    mi.ScalarVector3f(self.flag_cells) - 1.0))
            inside &= dr.gather(mi.Float, self.nonzero, mi.UInt32(c.x + cx * (c.y + cy * c.z)), inside) > 0
        return dr.if_stmt(args=(u,), cond=inside, label="volume_dk_lookup",
                          true_fn=lambda u: read(u, True), false_fn=outside)

    def _read(self, u, active=True):
        """The D/α read of :meth:`lookup` at texture coordinates u."""
        t = self.disp.eval(u, active)
        return mi.Vector3f(t[0], t[1], t[2]), 1.0 - t[3]

    def _read_derivatives(self, u, alpha_gradient, active=True):
        """The J (and ∇α) reads of :meth:`derivatives` at texture coordinates u."""
        j = self.jac.eval(u, active)
        jac_t = mi.Matrix3f(j[0], j[3], j[6], j[1], j[4], j[7], j[2], j[5], j[8])
        if not alpha_gradient:
            return jac_t, None
        g = self.galpha.eval(u, active)
        return jac_t, mi.Vector3f(g[0], g[1], g[2])

    @staticmethod
    def _outside(u):
        """What an all-zero cell reads: D = 0, α = 1."""
        zero = dr.zeros(mi.Float, dr.width(u.x))
        return mi.Vector3f(zero), zero + 1.0

    @staticmethod
    def _outside_derivatives(u, alpha_gradient):
        """What an all-zero cell reads: J = 0, ∇α = 0."""
        zero = dr.zeros(mi.Float, dr.width(u.x))
        return mi.Matrix3f(zero), (mi.Vector3f(zero) if alpha_gradient else None)


def padded_box(lo, hi, res, smoothing) -> tuple[np.ndarray, np.ndarray]:
    """Grow a support box by a margin of nodes (3 smoothing widths + 1) so that the D_k's
    faces hold D = 0, α = 1 and clamp-to-edge addressing continues them outside.  Axes with
    too few nodes for a margin (at most a quarter of them) keep the box."""
    lo, hi = np.asarray(lo, float).copy(), np.asarray(hi, float).copy()
    margin = int(np.ceil(3 * smoothing)) + 1
    for a in range(3):
        m = min(margin, (res[a] - 2) // 4)
        if m > 0:
            h = (hi[a] - lo[a]) / (res[a] - 1 - 2 * m)
            lo[a], hi[a] = lo[a] - m * h, hi[a] + m * h
    return lo, hi


class PlacedMap:
    """One primitive with its parameters, D_k resolution and placement M (§6)."""

    def __init__(self, kind: str, params: dict | None = None, to_world=None, resolution=None):
        self.kind = kind
        self.params = maps.check_params(kind, params or {})
        self.placement = maps.Placement(to_world, what=f"{kind} to_world")
        self.resolution = check_resolution(resolution or maps.DEFAULT_RESOLUTION[kind],
                                           f"{kind} resolution")
        self._sampled = None

    def set(self, params: dict | None = None, to_world=None) -> None:
        """Change parameters and/or M (animation); the D_k is rebuilt on next use."""
        if params:
            self.params = maps.check_params(self.kind, {**self.params, **params})
        if to_world is not None:
            self.placement = maps.Placement(to_world, what=f"{self.kind} to_world")
        self._sampled = None

    def exact(self, p: mi.Point3f) -> tuple[mi.Vector3f, mi.Float]:
        """World inverse displacement M D(M⁻¹ p') and exact α at world points p'."""
        q = {k: dr.opaque(mi.Float, v) for k, v in self.params.items()}
        d, alpha = maps.evaluate(self.kind, q, self.placement.to_local(p))
        return self.placement.vector_to_world(d), alpha

    def support_world(self) -> tuple[np.ndarray, np.ndarray]:
        return self.placement.world_box(*maps.support(self.kind, self.params))

    def sampled(self, bits: int, smoothing: float) -> SampledMap:
        s = self._sampled
        if s is None or s.bits != bits or s.smoothing != smoothing:
            lo, hi = padded_box(*maps.support(self.kind, self.params), self.resolution, smoothing)
            s = SampledMap(self.exact, self.placement, lo, hi, self.resolution, bits, smoothing)
            self._sampled = s
        return s


class Lookup:
    """Result of mapping world points p' through a chain: pre-image p, α (exact or α_s),
    normal matrix B = (I + J)ᵀ of the whole chain and ∇α (None unless asked).  A lookup
    through the D_k also keeps ``points``, the points where each D_k was read (last map
    first), and ``factors``, each map's α there, so that
    :meth:`DisplacementChain.with_normals` adds B and ∇α later without re-reading D."""

    def __init__(self, p, alpha, B=None, galpha=None, points=None, factors=None):
        self.p, self.alpha, self.B, self.galpha = p, alpha, B, galpha
        self.points, self.factors = points, factors


class DisplacementChain:
    """Maps in forward order, evaluated exactly or through their D_k (module docstring).

    Args:
        maps_: list of :class:`PlacedMap` (forward order: the first acts first).
        bits: storage of every D_k; smoothing: α smoothing (voxels of each D_k).
        composition: ``"on_the_fly"`` (one lookup per map) or ``"precomputed"`` (one D_k).
        composite_resolution: (x, y, z) of the precomputed D_k.
    """

    COMPOSITIONS = ("on_the_fly", "precomputed")

    def __init__(self, maps_, bits=16, smoothing=1.5, composition="on_the_fly",
                 composite_resolution=(64, 64, 64)):
        if composition not in self.COMPOSITIONS:
            raise ValueError(f"composition: must be one of {self.COMPOSITIONS}, got {composition!r}")
        if bits not in BITS:
            raise ValueError(f"bits: must be one of {BITS}, got {bits!r}")
        self.maps = list(maps_)
        self.bits, self.smoothing, self.composition = int(bits), float(smoothing), composition
        self.composite_resolution = check_resolution(composite_resolution, "composite_resolution")
        self._composite = None
        self.version = 0

    def changed(self) -> None:
        """Call after editing a map: drops the precomputed composite (and renderer caches)."""
        self._composite = None
        self.version += 1

    def exact(self, p: mi.Point3f) -> Lookup:
        """Pre-images through the procedural maps (reference mode) and the exact α."""
        alpha = dr.full(mi.Float, 1.0, dr.width(p.x))
        q = mi.Point3f(p)
        for m in reversed(self.maps):  # eq. 9: the last map is undone first
            d, a = m.exact(q)
            q, alpha = q + d, alpha * a
        return Lookup(q, alpha)

    def _exact_composite(self, p):
        r = self.exact(p)
        return r.p - p, r.alpha

    def composite(self) -> SampledMap:
        """The precomputed D_k of the whole chain over the union of the supports."""
        if self._composite is None:
            boxes = [m.support_world() for m in self.maps]
            lo, hi = padded_box(np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0),
                                self.composite_resolution, self.smoothing)
            self._composite = SampledMap(self._exact_composite, maps.Placement(), lo, hi,
                                         self.composite_resolution, self.bits, self.smoothing)
        return self._composite

    def sampled_maps(self) -> list[SampledMap]:
        """The D_k textures the approximation reads (one per map, or the composite)."""
        if not self.maps:
            return []
        if self.composition == "precomputed":
            return [self.composite()]
        return [m.sampled(self.bits, self.smoothing) for m in self.maps]

    def approximate(self, p: mi.Point3f, normals: bool = False, active=True,
                    alpha_gradient: bool = True) -> Lookup:
        """Pre-images through the D_k textures (approximation mode), α_s, and optionally the
        chain's B (Matrix3f) and — unless ``alpha_gradient`` is False — ∇α_s (world units)."""
        q = mi.Point3f(p)
        alpha = dr.full(mi.Float, 1.0, dr.width(p.x))
        points, factors = [], []
        for s in reversed(self.sampled_maps()):  # eq. 9: the last map is undone first
            d, a = s.lookup(q, active)
            points.append(q)
            factors.append(a)
            q, alpha = q + d, alpha * a
        r = Lookup(q, alpha, points=points, factors=factors)
        return self.with_normals(r, alpha_gradient, active) if normals else r

    def with_normals(self, r: Lookup, alpha_gradient: bool = True, active=True) -> Lookup:
        """``r`` (from :meth:`approximate`) with the chain's B and ∇α_s, read at the points
        where its D_k were read: bit for bit ``approximate(p, True)`` without its D reads."""
        alpha = dr.full(mi.Float, 1.0, dr.width(r.p.x))
        B = dr.identity(mi.Matrix3f)
        galpha = mi.Vector3f(0.0) if alpha_gradient else None
        for s, q, a in zip(reversed(self.sampled_maps()), r.points, r.factors):
            jac_t, ga = s.derivatives(q, alpha_gradient, active)
            # product rule for ∇(Π α) and the chain rule B <- B (I + J)ᵀ (eq. 6, 10)
            if galpha is not None:
                galpha = galpha * a + alpha * (B @ ga)
            B = B @ (dr.identity(mi.Matrix3f) + jac_t)
            alpha = alpha * a
        return Lookup(r.p, r.alpha, B, galpha, r.points, r.factors)

    def displacement_range(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-axis bounds (low (3,), high (3,)) on p - p' over the chain: the sums of each
        D_k's smallest and largest stored component (trilinear interpolation stays within
        its nodes)."""
        low, high = np.zeros(3), np.zeros(3)
        for s in self.sampled_maps():
            low, high = low + s.d_min, high + s.d_max
        return low, high

    def proxy_box(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """Bounding box of the displaced object (§4.2's proxy): p' = p - (p - p') with p in
        [lo, hi] and p - p' within :meth:`displacement_range`, so only the side that matter
        moves to grows."""
        low, high = self.displacement_range()
        return np.asarray(lo, float) - high, np.asarray(hi, float) - low

    def nbytes(self) -> int:
        return sum(s.nbytes() for s in self.sampled_maps())
