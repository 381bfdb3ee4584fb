"""The displaced object O'(p') = O(G(p')) masked by α (§4.2), its transfer function, its
majorant and the four normal methods of §4.3.

Density seen by both renderers: ``sigma_t(p') = density_scale · τ(O(p)) · [α(p') >= 1/2]``
with p the pre-image of p' through the chain (exact maps in ``reference`` mode, the D_k
textures in ``approximation`` mode, §4.2's "transparent if the alpha mask is less than 0.5")
and τ the linear transfer ramp ``clip((v - tf_low) / (tf_high - tf_low), 0, 1)``.

Majorant: τ <= τ(max O) and the mask is 0 or 1, whatever the displacement does, so
``density_scale · τ(max of the voxels)`` bounds sigma_t everywhere (trilinear interpolation
never exceeds the largest voxel — up to float32 rounding, hence a 1e-5 relative margin;
displacement only moves where O is read, and the proxy box holds every displaced point).

Normals (unit, pointing out of dense matter, i.e. along -∇):

* ``gradient``: the undisplaced precomputed gradient ∇O(p) (wrong under displacement, Fig. 4b);
* ``jacobian``: eq. 6, B ∇O(p) with the chain's B = (I + J_D)ᵀ;
* ``blend``: eq. 7, ω B∇O/|B∇O| + (1 - ω) ∇α_s/|∇α_s| with ω = clip(2 α_s - 1, 0, 1), so
  ω = 0 on the cut face (α_s = 1/2) and 1 where α_s = 1;
* ``fd``: central differences of the displaced field τ(O(G(p'))) α_s(p') at one object
  voxel (six more chain evaluations): the expensive truth.

Zero vectors (singular B at breaks, flat regions) fall back to ``fallback`` (the renderer
passes -ray direction), so every normal is finite.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.volume.displacement import DisplacementChain
from mi_displace.volume.objects import ObjectVolume

MODES = ("reference", "approximation")
NORMALS = ("gradient", "jacobian", "blend", "fd")


def safe_normalize(v: mi.Vector3f, fallback: mi.Vector3f) -> mi.Vector3f:
    """v / |v|, or ``fallback`` where |v| is zero or not finite."""
    n2 = dr.squared_norm(v)
    ok = (n2 > 1e-20) & dr.isfinite(n2)
    return dr.select(ok, v * dr.rsqrt(dr.select(ok, n2, 1.0)), fallback)


class DisplacedVolume:
    """An object volume seen through a displacement chain (module docstring).

    Args:
        obj: the object O_j; chain: the displacement maps; mode: reference/approximation.
        tf_low, tf_high: transfer ramp on the normalised density, 0 <= tf_low < 1 and
        tf_low < tf_high (τ(0) = 0: empty space stays empty); density_scale: sigma_t at τ = 1
        (world units⁻¹).
    """

    def __init__(self, obj: ObjectVolume, chain: DisplacementChain, mode="reference",
                 tf_low=0.1, tf_high=0.6, density_scale=20.0):
        if mode not in MODES:
            raise ValueError(f"mode: must be one of {MODES}, got {mode!r}")
        if not (np.isfinite(tf_low) and np.isfinite(tf_high) and tf_high > tf_low):
            raise ValueError(f"tf_low/tf_high: need finite tf_low < tf_high, got {tf_low}, {tf_high}")
        if not 0 <= tf_low < 1:   # τ(0) = 0 keeps empty voxels and the outside of the box empty
            raise ValueError(f"tf_low: must lie in [0, 1), the range of the normalised density (below 0, "
                             f"empty space and everything outside the object's box gets density; from 1 "
                             f"on, nothing does), got {tf_low}")
        if not (np.isfinite(density_scale) and density_scale > 0):
            raise ValueError(f"density_scale: must be finite and > 0, got {density_scale}")
        self.obj, self.chain, self.mode = obj, chain, mode
        self.tf_low, self.tf_high, self.density_scale = float(tf_low), float(tf_high), float(density_scale)

    def prepare(self) -> None:
        """Build every texture now (they cannot be built inside a symbolic loop)."""
        self.obj.textures()
        self.chain.sampled_maps()

    def transfer(self, v: mi.Float) -> mi.Float:
        """τ(v): the linear transfer ramp."""
        return dr.clip((v - self.tf_low) / (self.tf_high - self.tf_low), 0.0, 1.0)

    def lookup(self, p: mi.Point3f):
        """Pre-image lookup through the chain in this volume's mode (exact maps or D_k)."""
        if self.mode == "reference":
            return self.chain.exact(p)
        return self.chain.approximate(p)

    def density(self, p: mi.Point3f, lookup=None) -> mi.Float:
        """τ(O(p)) · [α >= 1/2] at world points p' (dimensionless, in [0, 1])."""
        r = lookup if lookup is not None else self.lookup(p)
        return dr.select(r.alpha >= 0.5, self.transfer(self.obj.density(r.p)), 0.0)

    def sigma_t(self, p: mi.Point3f) -> mi.Float:
        return self.density_scale * self.density(p)

    def majorant(self) -> float:
        """density_scale · τ(largest voxel), raised by 1e-5 relative: bounds sigma_t (module
        docstring; float32 trilinear weights can sum to a few ulp above 1)."""
        top = float(np.clip((self.obj.data.max() - self.tf_low) / (self.tf_high - self.tf_low), 0, 1))
        return self.density_scale * top * (1 + 1e-5)

    def proxy_box(self) -> tuple[np.ndarray, np.ndarray]:
        """World bounding box of the displaced object (§4.2 proxy geometry)."""
        return self.chain.proxy_box(self.obj.bbox_min, self.obj.bbox_max)

    def resample(self, lo, hi, shape) -> np.ndarray:
        """sigma_t (world units⁻¹) at the cell centres of a grid of ``shape`` (nz, ny, nx)
        cells over the world box [lo, hi] (3,): what a Mitsuba ``gridvolume`` whose
        ``to_world`` maps the unit cube onto that box holds to show this volume (its
        trilinear reconstruction of the field, not the field: cut faces and the α = 1/2
        threshold blur over one cell).  Returns float32 (nz, ny, nx)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        nz, ny, nx = (int(s) for s in shape)
        axes = [lo[a] + (np.arange(n) + 0.5) * (hi[a] - lo[a]) / n for a, n in enumerate((nx, ny, nz))]
        z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        p = mi.Point3f(mi.Float(x.ravel()), mi.Float(y.ravel()), mi.Float(z.ravel()))
        return np.asarray(self.sigma_t(p), dtype=np.float32).reshape(nz, ny, nx)

    def smooth_field(self, p: mi.Point3f, active=True) -> mi.Float:
        """τ(O(G(p'))) α_s(p'): the displaced field without the hard 1/2 threshold (for FD)."""
        r = self.chain.approximate(p, active=active) if self.mode == "approximation" else self.chain.exact(p)
        return self.transfer(self.obj.density(r.p, active)) * r.alpha

    def normal(self, p: mi.Point3f, method: str, fallback: mi.Vector3f, lookup=None,
               active=True) -> mi.Vector3f:
        """Unit normal at world points p' by ``method`` (module docstring); texture reads are
        masked by ``active``.  ``lookup``: the D_k lookup of p' (:meth:`DisplacementChain.approximate`,
        e.g. the renderer's density step at that sample), whose pre-image and read points are
        reused, so only J (and ∇α) are read here; without it the D_k are read again."""
        if method not in NORMALS:
            raise ValueError(f"normals: must be one of {NORMALS}, got {method!r}")
        if method == "fd":
            h = float(self.obj.voxel_size.min())
            g = []
            for axis in range(3):
                e = [0.0, 0.0, 0.0]
                e[axis] = h
                step = mi.Vector3f(e)
                g.append((self.smooth_field(p + step, active) - self.smooth_field(p - step, active)) / (2 * h))
            return safe_normalize(-mi.Vector3f(g[0], g[1], g[2]), fallback)
        # the D_k pre-image: ``lookup`` if it is one (the renderer's density step), else read now
        r = lookup if lookup is not None and lookup.points is not None else self.chain.approximate(p, active=active)
        grad = self.obj.gradient(r.p, active)
        if method == "gradient":
            return safe_normalize(-grad, fallback)
        if r.B is None or (method == "blend" and r.galpha is None):
            r = self.chain.with_normals(r, alpha_gradient=method == "blend", active=active)
        bent = safe_normalize(r.B @ grad, -fallback)  # eq. 6
        if method == "jacobian":
            return -bent
        omega = dr.clip(2.0 * r.alpha - 1.0, 0.0, 1.0)  # eq. 7
        cut = safe_normalize(r.galpha, bent)
        return safe_normalize(-(omega * bent + (1.0 - omega) * cut), fallback)

    def nbytes(self) -> dict:
        return {"object": self.obj.nbytes(), "maps": self.chain.nbytes()}


class AlbedoField:
    """The colour of a displaced object (the ``albedo`` of a ``heterogeneous`` medium, or the
    slicer's reflectance): a colour transfer of a scalar field F read at the *same* pre-image
    p = G(p') as the density, so that colour moves with the displacement, cut faces show the
    colour of what was cut and the inside shows its own colour:

        albedo(p') = low + (high - low) · clip((F(p) - a) / (b - a), 0, 1)

    F is the volume's own object O (a transfer function on density) or a second object volume
    on its own world box (e.g. a label field), read trilinearly, 0 outside its box.

    Args:
        volume: the :class:`DisplacedVolume` whose chain and mode give p.
        low, high: RGB albedo at F <= a and F >= b, each in [0, 1].
        value_range: (a, b), a < b; default the volume's (tf_low, tf_high).
        field: the second object volume F, or None for O.
    """

    def __init__(self, volume: DisplacedVolume, low, high, value_range=None, field: ObjectVolume | None = None):
        low, high = (np.asarray(c, float).reshape(-1) for c in (low, high))
        for name, c in (("albedo_low", low), ("albedo_high", high)):
            if c.shape != (3,) or not (np.isfinite(c).all() and (c >= 0).all() and (c <= 1).all()):
                raise ValueError(f"{name}: an RGB albedo needs three values in [0, 1], got {c}")
        a, b = (volume.tf_low, volume.tf_high) if value_range is None else (float(v) for v in value_range)
        if not (np.isfinite(a) and np.isfinite(b) and b > a):
            raise ValueError(f"albedo_range_low/high: need finite low < high, got {a}, {b}")
        self.volume, self.low, self.high, self.range = volume, low, high, (a, b)
        self.field = field if field is not None else volume.obj

    def prepare(self) -> None:
        """Build the textures now (not inside a symbolic loop)."""
        self.volume.prepare()
        self.field.textures()

    def albedo(self, p: mi.Point3f, lookup=None) -> mi.Color3f:
        """RGB albedo at world points p' (``lookup``: a pre-image lookup of p' to reuse)."""
        r = lookup if lookup is not None else self.volume.lookup(p)
        a, b = self.range
        t = dr.clip((self.field.density(r.p) - a) / (b - a), 0.0, 1.0)
        low, high = mi.Color3f(self.low.tolist()), mi.Color3f((self.high - self.low).tolist())
        return dr.fma(t, high, low)   # exact where low == high (a constant albedo)

    def max(self) -> float:
        return float(max(self.low.max(), self.high.max()))

