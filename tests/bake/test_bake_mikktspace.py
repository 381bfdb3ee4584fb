"""MikkTSpace: the port against the reference C code, its rules, and a bake decoded with it."""
from pathlib import Path

import numpy as np
import pytest
from bake_meshes import _sphere_mesh, plane, tilted_plane

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData, vertex_normals
from mi_displace.bake.mikktspace import mikktspace
from mi_displace.bake.trace import OK

REFERENCE = Path(__file__).parent / "data" / "mikktspace_reference.npz"


def _angle_deg(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1)))


def _uv_area2(uvs, faces):
    u = uvs[faces]
    return ((u[:, 1, 0] - u[:, 0, 0]) * (u[:, 2, 1] - u[:, 0, 1])
            - (u[:, 1, 1] - u[:, 0, 1]) * (u[:, 2, 0] - u[:, 0, 0]))


def test_port_matches_the_reference_implementation():
    # tangents of mikktspace.c itself (tests/bake/make_mikktspace_reference.py) on a sphere
    # with a mirrored region (fans of both orientations), collapsed UVs and a non-manifold fin
    ref = np.load(REFERENCE)
    t, s = mikktspace(ref["positions"], ref["faces"], ref["normals"], ref["uvs"])
    area = _uv_area2(ref["uvs"], ref["faces"])
    assert min((area < 0).sum(), (area > 0).sum()) > 50 and (area == 0).sum() >= 5   # both rules
    used = area != 0        # zero-UV-area triangles cover no texel (documented order rule)
    ang = _angle_deg(t[used], ref["tangents"][used])
    assert ang.max() < 1e-3
    assert np.array_equal(s[used], ref["signs"][used])
    assert np.all(np.isfinite(t)) and np.allclose(np.linalg.norm(t, axis=-1), 1, atol=1e-5)


def test_port_matches_the_binding_on_an_unwrapped_mesh(variant):
    C = pytest.importorskip("mikktspace")       # pymikktspace, where it was built (docs/bake.md)
    from mi_displace.bake.unwrap import unwrap

    m = _sphere_mesh(24, 12, 0.05)
    m = unwrap(MeshData(m.positions, m.faces), resolution=256)
    n = vertex_normals(m.positions, m.faces)
    P, N, U = (a[m.faces].reshape(-1, a.shape[1]).astype(np.float32) for a in (m.positions, n, m.uvs))
    out = np.frombuffer(C.gen_default(list(range(len(P))), P.ravel().copy(), N.ravel().copy(),
                                      U.ravel().copy()), np.float32).reshape(-1, 3, 4)
    t, s = mikktspace(m.positions, m.faces, n, m.uvs)
    assert _angle_deg(t, out[..., :3]).max() < 1e-3 and np.array_equal(s, out[..., 3])


def test_plane_tangent_is_dp_du_and_mirroring_flips_the_sign():
    lo = plane(n=2)
    n = np.tile([0.0, 0.0, 1.0], (len(lo.positions), 1))
    t, s = mikktspace(lo.positions, lo.faces, n, lo.uvs)
    assert np.allclose(t, [1, 0, 0]) and np.all(s == 1)
    t, s = mikktspace(lo.positions, lo.faces, n, lo.uvs * [-1, 1])
    assert np.allclose(t, [-1, 0, 0]) and np.all(s == -1)    # b = s (n x t) stays +y


def test_a_fan_with_both_orientations_splits_at_the_vertex():
    # 2 x 1 quads; the right column's UVs mirrored about x = 0.5, so the middle vertices are
    # shared by triangles of both orientations: MikkTSpace gives their corners two frames
    lo = plane(n=2)
    uv = lo.uvs.copy()
    right = lo.positions[:, 0] > 0.5
    uv[right, 0] = 1.0 - uv[right, 0]
    n = np.tile([0.0, 0.0, 1.0], (len(lo.positions), 1))
    t, s = mikktspace(lo.positions, lo.faces, n, uv)
    face_right = lo.positions[lo.faces].mean(1)[:, 0] > 0.5
    assert np.allclose(t[~face_right], [1, 0, 0]) and np.all(s[~face_right] == 1)
    assert np.allclose(t[face_right], [-1, 0, 0]) and np.all(s[face_right] == -1)


def _decode_object_normals(low: MeshData, normal_tangent: np.ndarray, tangents, signs):
    """Object-space normals from a tangent-space map, decoded as a MikkTSpace renderer does:
    per texel centre, the covering low-poly triangle (the highest-numbered one where UVs
    overlap, as the bake's layout), interpolated unnormalised n and t, b = sign (n x t),
    N = normalize(x t + y b + z n).  NumPy brute force; returns (normals (H, W, 3), inside)."""
    H, W, _ = normal_tangent.shape
    r, c = np.mgrid[0:H, 0:W]
    q = np.stack([(c.ravel() + 0.5) / W, 1.0 - (r.ravel() + 0.5) / H], 1)       # (T, 2)
    uv = low.uvs[low.faces].astype(np.float64)                                  # (F, 3, 2)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    d = q[:, None, :] - uv[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        b1 = (d[..., 0] * e2[:, 1] - d[..., 1] * e2[:, 0]) / det
        b2 = (e1[:, 0] * d[..., 1] - e1[:, 1] * d[..., 0]) / det
    inside = (np.minimum(np.minimum(b1, b2), 1 - b1 - b2) > 1e-4) & (det != 0)
    tri = np.where(inside.any(1), inside.shape[1] - 1 - np.argmax(inside[:, ::-1], 1), -1)
    ok = tri >= 0
    k = np.arange(len(q))[ok]
    f, w1, w2 = tri[ok], b1[k, tri[ok]], b2[k, tri[ok]]
    w = np.stack([1 - w1 - w2, w1, w2], 1)[..., None]
    nv = vertex_normals(low.positions, low.faces)
    n = (nv[low.faces[f]] * w).sum(1)
    t = (tangents[f] * w).sum(1)
    s = np.sign((signs[f] * w[..., 0]).sum(1))[:, None]
    b = s * np.cross(n, t)
    x = normal_tangent.reshape(-1, 3)[ok]
    out = np.zeros((H * W, 3))
    v = x[:, :1] * t + x[:, 1:2] * b + x[:, 2:3] * n
    out[ok] = v / np.linalg.norm(v, axis=1, keepdims=True)
    return out.reshape(H, W, 3), ok.reshape(H, W)


def test_bake_decoded_with_mikktspace_gives_the_object_space_normals(sphere_pair):
    """Issue 16 (1): every texel's tangent-space normal, decoded in MikkTSpace's frame, is the
    object-space normal of the same bake.  The low-poly has folded UV charts: three vertices'
    UVs pushed 3 cells sideways flip some of their triangles, so neighbouring fans hold both
    orientations (MikkTSpace splits them; a per-vertex tangent does not)."""
    high, low = sphere_pair
    low = _sphere_mesh(24, 12, 0.0)
    uv = low.uvs.copy()
    for v in (24 * 3 + 5, 25 * 6 + 11, 25 * 8 + 17):
        uv[v, 0] += 3.0 / 24
    low.uvs = uv
    assert (_uv_area2(uv, low.faces) < 0).sum() >= 3
    with pytest.warns(UserWarning, match="overlapping"):     # the folds overlap in UV
        r = bake(high, low, res=128, max_distance=0.2, pad=0)
    normals = vertex_normals(low.positions, low.faces)
    t, s = mikktspace(low.positions, low.faces, normals, low.uvs)
    decoded, inside = _decode_object_normals(low, r.maps["normal_tangent"], t, s)
    use = inside & (r.status == OK)
    assert use.sum() > 0.3 * 128 * 128
    assert np.all(np.isfinite(r.maps["normal_tangent"])) and np.all(np.isfinite(decoded))
    err = _angle_deg(decoded[use], r.maps["normal_object"][use])
    assert _angle_deg(r.maps["normal_tangent"][use], [0, 0, 1]).max() > 5    # a real relief
    assert int((err > 1.0).sum()) == 0, f"{int((err > 1).sum())} texels over 1 deg (max {err.max():.2f})"


@pytest.mark.parametrize("mirror", [False, True])
def test_decode_tangent_map_gives_the_object_normals(variant, mirror):
    # a tilted high-poly z = 0.02 + 0.1 x + 0.05 y: its normal is (-0.1, -0.05, 1) / |.|;
    # decoding the tangent-space map in MikkTSpace's frame (mikktspace.decode_tangent_map)
    # gives it back, also with the UVs mirrored in u (bitangent sign -1)
    from mi_displace.bake.mikktspace import decode_tangent_map

    low = plane(n=2)
    if mirror:
        low.uvs[:, 0] = 1 - low.uvs[:, 0]
    r = bake(tilted_plane(slope_y=0.05), low, res=16, max_distance=0.2, pad=0)
    out, inside = decode_tangent_map(r.low, r.maps["normal_tangent"])
    truth = np.float32([-0.1, -0.05, 1]) / np.linalg.norm([-0.1, -0.05, 1])
    assert inside.sum() == 256
    assert np.allclose(out[inside], truth, atol=1e-4)
    assert np.allclose(r.maps["normal_object"][inside], truth, atol=1e-4)


def test_degenerate_triangles_copy_the_tangent_of_their_vertex(variant):
    # MikkTSpace's DegenEpilogue: a triangle with two corners at one position takes, per
    # corner, the tangent of a good corner of the same (welded) vertex.  UVs (y, x): the
    # tangent dP/du is +y everywhere, not the default (1, 0, 0)
    from mi_displace.bake.meshdata import vertex_normals
    from mi_displace.bake.mikktspace import mikktspace

    low = plane(n=2)
    uvs = low.uvs[:, ::-1].copy()
    for bad in ([4, 5, 4], [4, 4, 5], [5, 4, 4]):
        faces = np.concatenate([low.faces, [bad]])
        t, s = mikktspace(low.positions, faces, vertex_normals(low.positions, low.faces), uvs)
        assert np.allclose(t[:-1], [0, 1, 0], atol=1e-6)
        assert np.allclose(t[-1], [0, 1, 0], atol=1e-6), bad
        assert np.all(s[-1] == s[0, 0])
