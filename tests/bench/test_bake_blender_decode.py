"""The comparison behind `bench bake_blender`'s "Blender decodes our maps", without Blender:
per-texel angle statistics of two normal maps (border / interior) on maps with a known
rotation, and the folds where Cycles flips its decode, on a mesh built here."""
import numpy as np

from mi_displace.bake.meshdata import MeshData
from mi_displace.bench.bake_blender import facing_away, normal_agreement


def _rotated(a, axis_seed, degrees):
    """a rotated by ``degrees`` about an axis perpendicular to it (Rodrigues): the angle
    between a and the result is exactly ``degrees``."""
    k = np.cross(a, axis_seed)
    k /= np.linalg.norm(k, axis=-1, keepdims=True)
    t = np.radians(degrees)[..., None]
    return a * np.cos(t) + np.cross(k, a) * np.sin(t)   # k . a = 0


def test_normal_agreement_measures_a_known_rotation():
    rng = np.random.default_rng(3)
    H = W = 40
    a = rng.normal(size=(H, W, 3))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    border = np.zeros((H, W), bool)
    border[:, :8] = True
    measured = np.ones((H, W), bool)
    measured[-4:] = False                                 # left out: 180 degrees there
    degrees = np.where(border, 2.0, 0.25)
    outlier = ~border & (rng.random((H, W)) < 0.1)        # about 10 % of the interior at 3 degrees
    degrees[outlier] = 3.0
    degrees[~measured] = 180.0
    b = 5.0 * _rotated(a, rng.normal(size=(H, W, 3)), degrees)   # length does not matter
    r = normal_agreement(a, b, measured, border)

    inner = measured & ~border
    assert r["all"]["texels"] == measured.sum()
    assert r["border"]["texels"] == (measured & border).sum() == 36 * 8
    assert r["interior"]["texels"] == inner.sum()
    assert abs(r["border"]["median_deg"] - 2.0) < 1e-6 and abs(r["border"]["max_deg"] - 2.0) < 1e-6
    assert r["border"]["pct_over_1deg"] == 100.0
    assert abs(r["interior"]["median_deg"] - 0.25) < 1e-6
    assert abs(r["interior"]["max_deg"] - 3.0) < 1e-6
    share = 100 * (outlier & measured).sum() / inner.sum()
    assert abs(r["interior"]["pct_over_1deg"] - share) < 1e-9 and 5 < share < 15
    assert abs(r["all"]["pct_over_1deg"]
               - 100 * ((border | outlier) & measured).sum() / measured.sum()) < 1e-9
    assert abs(r["interior"]["p95_deg"] - np.percentile(degrees[inner], 95)) < 1e-6
    empty = normal_agreement(a, b, measured & ~border, border)["border"]
    assert empty["texels"] == 0 and empty["median_deg"] is None


def test_facing_away_finds_the_fold(variant_llvm):
    # triangle A (normal +z) and a larger triangle B folded back over it across their shared
    # edge (normal about -z): the shared vertices' area-weighted normals point about -z, so
    # inside A the interpolated normal turns away from A near that edge
    p = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-3, -3, 0.2]])
    faces = np.int64([[0, 1, 2], [2, 1, 3]])
    uv = np.float32([[0.05, 0.05], [0.45, 0.05], [0.05, 0.45], [0.45, 0.45]])
    res = 64
    away = facing_away(MeshData(p, faces, uv), res, res)

    # independent truth: texel centres in A's UV triangle, barycentrics from the UVs
    c, r = np.meshgrid(np.arange(res), np.arange(res))
    u, v = (c + 0.5) / res, 1 - (r + 0.5) / res
    w1, w2 = (u - 0.05) / 0.4, (v - 0.05) / 0.4
    in_a = (w1 > 0) & (w2 > 0) & (w1 + w2 < 1)
    fa = np.cross(p[1] - p[0], p[2] - p[0])
    fb = np.cross(p[1] - p[2], p[3] - p[2])
    shared = (fa + fb) / np.linalg.norm(fa + fb)
    nz = (1 - w1 - w2) * 1.0 + (w1 + w2) * shared[2]     # n . (0, 0, 1) inside A
    truth = in_a & (nz < 0)
    assert truth.sum() > 20 and (in_a & ~truth).sum() > 20   # part of A, not all of it
    # float32 rasterisation decides texel centres on the sign change or on the shared edge
    clear = (np.abs(nz) > 1e-3) & (np.abs(w1 + w2 - 1) > 0.01)
    assert np.array_equal(away[clear], truth[clear]) and (~clear & in_a).sum() < 5
