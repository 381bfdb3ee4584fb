"""Build (or load from the cache) a compressed VDM + MVM for one height field.

Pipeline (paper §3.1, appendix, §3.3): flat ray casting (:mod:`.table`) -> curvature
resampling with the MVM (:mod:`.curvature`, :mod:`.mvm`) -> SVD with shared weights
(:mod:`.compression`).  Sizes follow the paper's names: ``res`` texels per side, ``n_theta``
polar and ``n_phi`` azimuthal view samples, ``n_curv`` curvature samples over the range the
mesh has (one sample when that range is a single value).

The VDM block of the compressed matrix stores ``h = d_VDM cos(theta)`` (for a flat table,
the depth of P' below the reference surface), not d itself: d grows like 1 / cos(theta)
towards grazing views, so linear interpolation between the 8 theta samples overshot it by
up to 20 % (T' beyond the true hit, on the far side of relief edges), while h is constant
along theta over flat relief.  The lookup divides by cos(theta_V) again
(:meth:`mi_displace.vdm.lookup.VDMLookup.d`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import mitsuba as mi
import numpy as np

from mi_displace.vdm import cache, compression, curvature, table

#: Weight columns always stored, so that svd_terms / mvm_terms up to this need no rebuild.
K_STORED = 16


@dataclass
class VDMSpec:
    """Inputs that determine a table (all validated by :func:`check_spec`).

    Attributes:
        res: texels per side of one tile.
        n_theta, n_phi, n_curv: view polar, view azimuth and curvature sample counts.
        depth: D, mesostructure depth [tile units] (>= 0).
        c_range: (c_lo, c_hi) curvature range [1 / tile units].
        theta_oversample: flat rays per table theta sample (>= 1; more = finer resampling).
    """

    res: int = 128
    n_theta: int = 8
    n_phi: int = 32
    n_curv: int = 16
    depth: float = 0.1
    c_range: tuple[float, float] = (0.0, 0.0)
    theta_oversample: int = 1

    def curvatures(self) -> np.ndarray:
        lo, hi = self.c_range
        n = 1 if hi - lo <= 1e-9 * max(1.0, abs(hi)) else self.n_curv
        return curvature.curvature_grid(lo, hi, n)


MAX_THETA_PAIRS = 1024   # theta^2 * theta_oversample (paper: 8 * 8 * 1 = 64)


def _positive_int(name: str, value, low: int = 1, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float)) or \
            int(value) != value or value < low or (high is not None and value > high):
        bound = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise ValueError(f"vdm: '{name}' must be an integer {bound}, got {value!r}")
    return int(value)


def check_spec(spec: VDMSpec) -> VDMSpec:
    """Validate a spec (ValueError naming the parameter); returns it."""
    spec.res = _positive_int("res", spec.res, 1, 1024)
    spec.n_theta = _positive_int("theta", spec.n_theta, 2, 64)
    spec.n_phi = _positive_int("phi", spec.n_phi, 4, 256)
    spec.n_curv = _positive_int("curvatures", spec.n_curv, 1, 64)
    spec.theta_oversample = _positive_int("theta_oversample", spec.theta_oversample, 1, 8)
    pairs = spec.n_theta * spec.n_theta * spec.theta_oversample
    if pairs > MAX_THETA_PAIRS:
        # the appendix's re-sampling is unrolled over (source, target) angle pairs: the
        # kernel grows with their product and compiles for minutes beyond this
        raise ValueError(f"vdm: 'theta'^2 x 'theta_oversample' = {pairs} exceeds "
                         f"{MAX_THETA_PAIRS}; lower 'theta' or 'theta_oversample'")
    if not math.isfinite(spec.depth) or spec.depth < 0:
        raise ValueError(f"vdm: 'depth' must be finite and >= 0, got {spec.depth!r}")
    lo, hi = spec.c_range
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise ValueError(f"vdm: curvature range must be finite with lo <= hi, got {spec.c_range}")
    rows = spec.n_phi * spec.res * spec.res
    if rows * spec.n_curv * spec.n_theta * spec.theta_oversample > 2**31 - 1:
        raise ValueError("vdm: table too large (res^2 * phi * theta * curvatures >= 2^31)")
    return spec


@dataclass
class VDMData:
    """A built table: compressed weights/eigen-functions, the full MVM and build stats."""

    spec: VDMSpec
    curvatures: np.ndarray      # (n_c,) [1 / tile units]
    compressed: compression.Compressed
    mvm_full: np.ndarray        # (n_rows, n_c) float32 [rad]
    stats: dict = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        return self.spec.n_phi * self.spec.res * self.spec.res

    def table_bytes(self) -> int:
        """Bytes of the uncompressed float32 VDM + MVM (the paper's '68 MB')."""
        n_c = len(self.curvatures)
        return 4 * self.n_rows * n_c * (self.spec.n_theta + 1)

    def reconstruction_rmse(self, svd_terms: int, mvm_terms: int) -> tuple[float, float]:
        """RMSE of the compressed VDM block (h = d cos theta) [tile units] and MVM [rad]
        against the full table.

        Exact from the eigen data: W^T W = diag(lambda), so the squared residual of a block
        truncated at k terms is sum_{i >= k} lambda_i |E_block^i|^2.
        """
        c = self.compressed
        c.check_terms(svd_terms, mvm_terms)
        ev, nv = c.eigvecs, c.n_vdm_cols
        res_vdm = float(np.sum(c.eigvals[svd_terms:] * np.sum(ev[:nv, svd_terms:] ** 2, 0)))
        res_mvm = float(np.sum(c.eigvals[mvm_terms:] * np.sum(ev[nv:, mvm_terms:] ** 2, 0)))
        n_mvm = ev.shape[0] - nv
        return (math.sqrt(max(res_vdm, 0) / (self.n_rows * nv)),
                math.sqrt(max(res_mvm, 0) / (self.n_rows * n_mvm)))

    def silhouette_mismatch(self, mvm_terms: int) -> float:
        """Fraction of (x, y, phi, c, theta) samples whose silhouette test (theta >
        theta_MVM) differs between the compressed and the full MVM."""
        c = self.compressed
        _, e_mvm = c.eigen_functions(1, mvm_terms)
        thetas = table.theta_grid(self.spec.n_theta).astype(np.float32)
        wrong = 0
        for start in range(0, self.n_rows, compression.CHUNK_ROWS):  # row chunks
            rows = slice(start, start + compression.CHUNK_ROWS)
            with compression.single_threaded_blas():
                rec = c.weights[rows, :e_mvm.shape[1]] @ e_mvm.T
            full = self.mvm_full[rows]
            wrong += int(np.count_nonzero((thetas[None, None, :] > full[..., None])
                                          != (thetas[None, None, :] > rec[..., None])))
        return wrong / (self.n_rows * len(self.curvatures) * self.spec.n_theta)


def build(heights: np.ndarray, spec: VDMSpec, use_cache: bool = True) -> VDMData:
    """Build the compressed VDM of a (res, res) height grid, or load it from the cache.

    ``stats`` holds ``build_time_s`` (0 on a cache hit plus the load time in
    ``load_time_s``), ``cast_s``, ``resample_s``, ``svd_s``, ``flat_misses``, ``cached``.
    """
    spec = check_spec(spec)
    heights = table.check_heights(heights)
    if heights.shape != (spec.res, spec.res):
        raise ValueError(f"vdm: height grid shape {heights.shape} != (res, res) = "
                         f"({spec.res}, {spec.res})")
    curv = spec.curvatures()
    digest = cache.key(heights, depth=float(spec.depth), n_theta=spec.n_theta,
                       n_phi=spec.n_phi, curvatures=curv, theta_oversample=spec.theta_oversample,
                       k_stored=K_STORED)
    start = time.perf_counter()
    if use_cache:
        hit = cache.load(digest)
        if hit is not None and hit["weights"].shape[0] == spec.n_phi * spec.res ** 2:
            comp = compression.Compressed(hit["weights"], hit["eigvecs"], hit["eigvals"],
                                          int(hit["n_vdm_cols"]))
            stats = {k: float(v) for k, v in zip(hit["stat_names"], hit["stat_values"])}
            stats.update(cached=True, load_time_s=time.perf_counter() - start, key=digest)
            return VDMData(spec, curv, comp, hit["mvm_full"], stats)
    n_rows = spec.n_phi * spec.res * spec.res
    n_src = spec.n_theta * spec.theta_oversample
    t0 = time.perf_counter()
    t_flat = table.flat_distances(heights, spec.depth, n_src, spec.n_phi)
    misses = int(np.count_nonzero(t_flat < 0))
    t1 = time.perf_counter()
    d, mvm = curvature.resample(mi.Float(t_flat.ravel()), n_rows, table.theta_grid(n_src),
                                table.theta_grid(spec.n_theta), curv, spec.depth,
                                spec.depth * (1.0 - float(heights.min())))
    del t_flat
    n_c = len(curv)
    A = np.empty((n_rows, n_c * (spec.n_theta + 1)), np.float32)
    # stored as h = d cos(theta) (module doc): linear in theta where d ~ 1 / cos(theta) is not
    cos_t = np.cos(table.theta_grid(spec.n_theta)).astype(np.float32)
    A[:, :n_c * spec.n_theta] = (np.asarray(d, np.float32).reshape(n_rows, n_c, spec.n_theta)
                                 * cos_t).reshape(n_rows, -1)
    A[:, n_c * spec.n_theta:] = np.asarray(mvm, np.float32).reshape(n_rows, n_c)
    del d, mvm
    t2 = time.perf_counter()
    comp = compression.compress(A, n_c * spec.n_theta, K_STORED)
    mvm_full = np.ascontiguousarray(A[:, n_c * spec.n_theta:])
    del A
    t3 = time.perf_counter()
    stats = {"build_time_s": t3 - start, "cast_s": t1 - t0, "resample_s": t2 - t1,
             "svd_s": t3 - t2, "flat_misses": misses}
    data = VDMData(spec, curv, comp, mvm_full, dict(stats, cached=False, key=digest))
    if use_cache:
        cache.save(digest, {"weights": comp.weights, "eigvecs": comp.eigvecs,
                            "eigvals": comp.eigvals, "n_vdm_cols": np.int64(comp.n_vdm_cols),
                            "mvm_full": mvm_full, "stat_names": np.array(list(stats)),
                            "stat_values": np.array(list(stats.values()), np.float64)})
    return data
