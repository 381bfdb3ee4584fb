"""The DDM / HDDM mapping (eq. 1-2), the normal methods (§3.2) and the extremes."""
import os
import warnings

import numpy as np
import pytest
from ddm_helpers import spherical_cap

from mi_displace.core import tessellate
from mi_displace.ddm import mapping
from mi_displace.ddm import normals as nrm
from mi_displace.ddm.animation import Animation
from mi_displace.ddm.model import DDMConfig, DDMModel, FoldingWarning
from mi_displace.ddm.tiles import get_tile


def _np(v):
    return np.stack([np.asarray(c) for c in v], 1)


def _model(**kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FoldingWarning)
        return DDMModel(DDMConfig(**kw))


def test_plane_mapping_is_the_analytic_map_in_both_modes(variant):
    for mode in ("exact", "maps"):
        m = _model(base="plane", tile="stone:2", tiles_u=4, tiles_v=3, height=0.2, w_offset=0.05,
                   mode=mode, map_resolution=8)
        p, n, uv = m.map(method="jacobian")
        tile = m.tiles[0].positions
        k = np.arange(m.vertex_count) % len(tile)
        inst = np.arange(m.vertex_count) // len(tile)
        u = m.layout.offsets[inst, 0] + m.layout.size[0] * tile[k, 0]
        v = m.layout.offsets[inst, 1] + m.layout.size[1] * tile[k, 1]
        expect = np.stack([2 * u - 1, 2 * v - 1, 0.2 * tile[k, 2] + 0.05], 1)
        assert np.allclose(_np(p), expect, atol=1e-5), mode   # bilinear is exact on a plane
        assert np.allclose(_np(uv), np.stack([u, v], 1), atol=1e-6)
        # a flat plane scales x, y by (2 su, 2 sv) and z by height: normals follow J^-T
        scale = np.array([2 * m.layout.size[0], 2 * m.layout.size[1], 0.2])
        tn = m.tiles[0].normals[k] / scale
        tn /= np.linalg.norm(tn, axis=1, keepdims=True)
        assert np.allclose(_np(n), tn, atol=1e-4)


def test_sphere_exact_mapping_lifts_by_w(variant):
    m = _model(base="sphere", base_params={"radius": 1.5}, tile="hexagon", layout="hex",
               tiles_u=12, tiles_v=8, height=0.1, mode="exact")
    p, _, _ = m.map()
    z = np.tile(m.tiles[0].positions[:, 2], m.layout.count)
    assert np.allclose(np.linalg.norm(_np(p), axis=1), 1.5 + 0.1 * z, atol=2e-5)


def test_maps_converge_to_exact_at_second_order(variant):
    from mi_displace.ddm import accuracy
    rows = accuracy.geometric_accuracy(DDMConfig(**accuracy.THORNS_SPHERE), (32, 64, 128))
    rms = [r["rms_error_rel"] for r in rows]
    assert rms[0] < 2e-3
    for a, b in zip(rms, rms[1:]):
        assert 3.0 < a / b < 5.0            # bilinear geometry image: error ~ 1/R^2
    assert rows[-1]["normal_mean_deg"] < rows[0]["normal_mean_deg"]


def test_normal_methods_against_the_mapped_faces(variant):
    m = _model(base="torus", base_params={"major_radius": 1.0, "minor_radius": 0.4},
               tile="stone:3", tiles_u=24, tiles_v=12, height=0.08, mode="exact")
    faces = np.stack([np.asarray(c) for c in m.faces], 1)
    p, truth, _ = m.map(method="jacobian")
    P = _np(p)
    fn = np.cross(P[faces[:, 1]] - P[faces[:, 0]], P[faces[:, 2]] - P[faces[:, 0]])
    acc = np.zeros_like(P)
    for c in range(3):
        np.add.at(acc, faces[:, c], fn)
    mesh_n = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    # jacobian normals agree with the mapped mesh's own face normals (independent truth)
    agree = np.einsum("ij,ij->i", mesh_n, _np(truth))
    assert np.median(agree) > 0.995 and np.mean(agree > 0.9) > 0.97
    err = {}
    for method in ("tangent", "naive"):
        _, n, _ = m.map(method=method)
        err[method] = np.asarray(nrm.angle_error_deg(n, truth))
    assert err["tangent"].mean() < 0.2 and err["tangent"].max() < 3
    assert err["naive"].mean() > 10 * err["tangent"].mean()    # why the paper rejects it


def test_tiles_crossing_the_seam_wrap_without_cracks(variant):
    for mode in ("exact", "maps"):
        kw = dict(base="sphere", tile="thorn", tiles_u=8, tiles_v=4, height=0.2, mode=mode,
                  map_resolution=64)
        m = _model(u0=0.5 / 8, **kw)          # the last column straddles u = 1
        p, _, uv = m.map()
        P, UV = _np(p), _np(uv)
        assert np.all(np.isfinite(P)) and UV[:, 0].max() > 1.0
        tile = m.tiles[0].positions
        nv = len(tile)
        plate = tile[:, 2] == 0
        right = np.flatnonzero(plate & np.isclose(tile[:, 0], 1.0))
        left = np.flatnonzero(plate & np.isclose(tile[:, 0], 0.0))
        right = right[np.argsort(tile[right, 1])]
        left = left[np.argsort(tile[left, 1])]
        for row in range(4):                  # instances are row-major, u fastest
            last, first = row * 8 + 7, row * 8
            crack = np.abs(P[last * nv + right] - P[first * nv + left]).max()
            assert crack < 2e-5, (mode, row, crack)
        # the same layout shifted by a whole period maps to the same points
        p2, _, _ = _model(u0=0.5 / 8 - 1.0, **kw).map()
        assert np.abs(_np(p2) - P).max() < 2e-5


@pytest.mark.parametrize("base, params, height", [
    ("sphere", {"radius": 0.3}, 0.45),     # outward thorns on a small sphere: (r + w) n
    ("sphere", {"radius": 0.3}, -0.45),    # inward beyond the radius: folds
    ("torus", {"major_radius": 1.0, "minor_radius": 0.3}, 0.45),   # w < R - r
    ("torus", {"major_radius": 1.0, "minor_radius": 0.3}, 0.9),    # w > R - r: inner side
    ("torus", {"major_radius": 1.0, "minor_radius": 0.3}, -0.35),  # inward beyond r
    ("plane", {}, 5.0),
])
def test_folding_is_flagged_only_where_the_map_folds(variant, base, params, height):
    """Truth from the principal curvatures (n outward): 1 + w k <= 0 for some reached w —
    sphere k = 1/r; torus k in {1/r, cos(psi)/(R + r cos(psi))}, smallest -1/(R - r)."""
    z = get_tile("thorn").positions[:, 2]
    w = np.array([height * z.min(), height * z.max()])
    if base == "sphere":
        kappas = [1 / params["radius"]]
    elif base == "torus":
        kappas = [1 / params["minor_radius"], -1 / (params["major_radius"] - params["minor_radius"])]
    else:
        kappas = [0.0]
    expected = any((1 + w * k <= 0).any() for k in kappas)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = DDMModel(DDMConfig(base=base, base_params=params, tile="thorn", tiles_u=8, tiles_v=4,
                               height=height, mode="maps", map_resolution=16))
    flagged = [c for c in caught if issubclass(c.category, FoldingWarning)]
    assert bool(flagged) == expected, (base, height, w, [str(c.message) for c in flagged])
    if flagged:
        assert "det of the Jacobian" in str(flagged[0].message)
    p, n, _ = m.map()
    assert np.all(np.isfinite(_np(p))) and np.all(np.isfinite(_np(n)))
    assert np.allclose(np.linalg.norm(_np(n), axis=1), 1, atol=1e-4)


def test_memory_report_and_too_many_tiles(variant):
    m = _model(base="sphere", tile="thorn", tiles_u=16, tiles_v=8, mode="maps", map_resolution=64)
    r = m.memory_report()
    assert r["maps_bytes"] == 64 * 64 * 25
    assert r["tile_bytes"] == m.tiles[0].vertex_count * 48 + m.tiles[0].face_count * 12
    assert r["mesh_bytes"] == m.vertex_count * 32 + m.face_count * 12
    assert r["hddm_bytes"] == r["tile_bytes"] + r["maps_bytes"] + 128 * 8
    with pytest.raises(ValueError, match="tiles_u"):
        DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=200000, tiles_v=100000))


def test_metamorphosis_follows_eq3_and_extrapolates(variant):
    m = _model(base="plane", tile="thorn", tile_target="flower", tiles_u=2, tiles_v=2,
               height=0.5, mode="exact", animation=Animation(alpha0=0.0, alpha_rate=1.0))
    a, b = m.tiles[0].positions, m.target.positions
    for t in (0.0, 1.0, 2.0, -0.5):
        p, n, _, _ = m.tile_buffers_at(t)
        assert np.allclose(_np(p), a * (1 - t) + b * t, atol=1e-5)
        assert np.allclose(np.linalg.norm(_np(n), axis=1), 1, atol=1e-5)
    p, _, _ = m.map(t=2.0)
    assert np.all(np.isfinite(_np(p)))
    with pytest.raises(ValueError, match="compatible"):
        DDMModel(DDMConfig(base="plane", tile="thorn", tile_target="chain"))


def test_texture_space_animation_translates_tiles(variant):
    anim = Animation(velocity_u=0.5, rotation_rate=0.0, w_amplitude=0.5, w_frequency=0.25)
    m = _model(base="plane", tile="hexagon", tiles_u=4, tiles_v=4, height=0.1, mode="exact",
               animation=anim)
    p0, _, uv0 = m.map(t=0.0)
    p1, _, uv1 = m.map(t=1.0)
    du = _np(uv1) - _np(uv0)
    assert np.allclose(du[:, 0], 0.5 * m.layout.size[0], atol=1e-6) and np.allclose(du[:, 1], 0)
    z = np.tile(m.tiles[0].positions[:, 2], m.layout.count)
    assert np.allclose(_np(p1)[:, 2], 0.1 * 1.5 * z, atol=1e-5)   # sin(2 pi 0.25) = 1
    # and along v (the translation's second component)
    m = _model(base="plane", tile="hexagon", tiles_u=4, tiles_v=4, height=0.1, mode="exact",
               animation=Animation(velocity_v=-0.25, rotation_rate=0.0))
    dv = _np(m.map(t=2.0)[2]) - _np(m.map(t=0.0)[2])
    assert np.allclose(dv[:, 1], -0.5 * m.layout.size[1], atol=1e-6) and np.allclose(dv[:, 0], 0)


@pytest.mark.parametrize("tiles", ["thorn,hexagon,stone:4", "thorn,hexagon"])
def test_multi_tile_layouts_map_each_instance_with_its_own_tile(variant, tiles):
    m = _model(base="plane", tile=tiles, layout="random", seed=3, tiles_u=5,
               tiles_v=4, height=0.3, mode="maps", map_resolution=4)
    assert len(m.placement.groups) == len(tiles.split(","))
    p, _, _ = m.map()
    P = _np(p)
    su, sv = m.layout.size
    order = np.argsort(m.layout.tile_index, kind="stable")   # instances grouped by tile
    start = 0
    for i in order:
        tile = m.tiles[m.layout.tile_index[i]].positions
        u0, v0 = m.layout.offsets[i]
        expect = np.stack([2 * (u0 + su * tile[:, 0]) - 1, 2 * (v0 + sv * tile[:, 1]) - 1,
                           0.3 * tile[:, 2]], 1)
        assert np.allclose(P[start:start + len(tile)], expect, atol=1e-5)
        start += len(tile)
    assert start == m.vertex_count
    faces = np.stack([np.asarray(c) for c in m.faces], 1)
    assert faces.max() == m.vertex_count - 1 and len(faces) == m.face_count


def test_zero_height_reproduces_the_base(variant):
    for mode, tol in (("exact", 2e-6), ("maps", 5e-4)):
        m = _model(base="sphere", base_params={"radius": 2.0}, tile="thorn", tiles_u=16,
                   tiles_v=8, height=0.0, mode=mode, map_resolution=128)
        p, n, _ = m.map()
        r = np.linalg.norm(_np(p), axis=1)
        assert np.abs(r - 2.0).max() < tol * 2.0, mode
        assert np.all(np.isfinite(_np(n)))


@pytest.mark.parametrize("radius", [1e-3, 1e3])
def test_extreme_scales_stay_finite_and_relative(variant, radius):
    m = _model(base="sphere", base_params={"radius": radius}, tile="hexagon", layout="hex",
               tiles_u=12, tiles_v=8, height=0.05 * radius, mode="maps", map_resolution=64)
    p, n, _ = m.map(method="jacobian")
    P = _np(p)
    assert np.all(np.isfinite(P)) and np.allclose(np.linalg.norm(_np(n), axis=1), 1, atol=1e-4)
    z = np.tile(m.tiles[0].positions[:, 2], m.layout.count)
    rel = np.linalg.norm(P, axis=1) / radius - (1 + 0.05 * z)
    assert np.abs(rel).max() < 2e-3          # same relative accuracy at every scale


# ---------------------------------------------------------------------------------------
# Mutants that survived the tests above (scripts/mutation.sh, docs/testing.md).


def test_mode_aliases_follow_the_comparison_convention():
    """$mode reference/approximation (README scene convention) is exact/maps."""
    assert DDMConfig(mode="reference").check().mode == "exact"
    assert DDMConfig(mode="approximation").check().mode == "maps"
    assert DDMConfig(mode="exact").check().mode == "exact"
    with pytest.raises(ValueError, match="unknown 'mode' 'approx'"):
        DDMConfig(mode="approx").check()


def _face_normals(P, faces):
    fn = np.cross(P[faces[:, 1]] - P[faces[:, 0]], P[faces[:, 2]] - P[faces[:, 0]])
    return fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)


@pytest.mark.parametrize("base, params", [
    ("sphere", {"radius": 0.1}),                 # (S_u x S_v) . n < 0, tiles at both poles
    ("cylinder", {"radius": 0.1, "length": 0.5}),  # (S_u x S_v) . n = 2 pi r L > 0, below 1
])
def test_tiles_face_outwards_on_small_bases_up_to_the_poles(variant, base, params):
    """The orientation sign is that of (S_u x S_v) . n whatever its size, taken inside each
    tile (a sphere's first and last tile rows touch the poles, beyond which the
    parametrisation mirrors): the tops of the stones face away from the axis, and every
    row's faces are wound like its normals."""
    m = _model(base=base, base_params=params, tile="stone:1", tiles_u=8, tiles_v=3,
               height=0.02, mode="exact")
    for method in ("tangent", "jacobian"):
        p, n, _ = m.map(method=method)
        P, N = _np(p), _np(n)
        radial = P if base == "sphere" else P * [1, 1, 0]
        radial = radial / np.linalg.norm(radial, axis=1, keepdims=True)
        tile_z = np.tile(m.tiles[0].positions[:, 2], m.layout.count)
        up = tile_z > 0.9 * tile_z.max()
        row = (np.arange(m.vertex_count) // m.tiles[0].vertex_count) // 8
        faces = np.stack([np.asarray(c) for c in m.faces], 1).astype(np.int64)
        agree = np.einsum("ij,ij->i", _face_normals(P, faces), N[faces].mean(1))
        for r in range(3):
            assert np.mean(np.einsum("ij,ij->i", N, radial)[up & (row == r)] > 0) > 0.97, (method, r)
            assert np.median(agree[row[faces[:, 0]] == r]) > 0.9, (method, r)


def test_check_size_counts_the_bytes_of_the_mapped_mesh(variant):
    """check_size's figure is the size of the buffers map() returns (float32 positions,
    normals, uvs) plus the uint32 faces, measured on a built model."""
    m = _model(base="plane", tile="thorn", tiles_u=3, tiles_v=2, mode="exact")
    p, n, uv = m.map()
    measured = sum(np.asarray(c).nbytes for x in (p, n, uv, m.faces) for c in x)
    assert mapping.check_size(m.vertex_count, m.face_count) == measured
    too_many = tessellate.MAX_VERTICES + 1
    with pytest.raises(ValueError, match=rf"^ddm: tiles_u x tiles_v gives {too_many:,} vertices "
                                         r"and 1 triangles \(4\.0 GiB for the mapped mesh"):
        mapping.check_size(too_many, 1)


def test_check_size_limits_at_their_boundaries(monkeypatch):
    """Three limits, each passed exactly at its bound: the vertex index range, 3 indices per
    face in 32 bits, and 3x the mapped mesh within half the physical memory (a 72 GiB
    machine: faces of 12 bytes up to 12 GiB); without sysconf the memory is taken as 16 GiB."""
    pages = {"SC_PAGE_SIZE": 4096, "SC_PHYS_PAGES": 2**40 // 4096}   # 1 TiB first
    monkeypatch.setattr(os, "sysconf", lambda name: pages[name])
    mapping.check_size(tessellate.MAX_VERTICES, 0)
    with pytest.raises(ValueError, match="more than fits"):
        mapping.check_size(tessellate.MAX_VERTICES + 1, 0)
    mapping.check_size(0, (2**32 - 1) // 3)
    with pytest.raises(ValueError, match="more than fits"):
        mapping.check_size(0, (2**32 - 1) // 3 + 1)
    pages["SC_PHYS_PAGES"] = 72 * 2**30 // 4096
    assert mapping.check_size(0, 2**30) == 12 * 2**30
    with pytest.raises(ValueError, match=r"^ddm: tiles x gives 0 vertices and 1,073,741,825 "
                       r"triangles \(12\.0 GiB for the mapped mesh, ~3x that while building\), "
                       r"more than fits \(limit [0-9,]+ vertices, half of 72 GiB memory\); use "
                       r"fewer tiles or a smaller tile$"):
        mapping.check_size(0, 2**30 + 1, "tiles x")

    def no_sysconf(name):
        raise ValueError(name)
    monkeypatch.setattr(os, "sysconf", no_sysconf)
    limit = 8 * 2**30 // 36                    # 3 * 12 bytes per face within 8 GiB
    mapping.check_size(0, limit)
    with pytest.raises(ValueError, match="half of 16 GiB memory"):
        mapping.check_size(0, limit + 1)


def test_normal_methods_on_an_affine_map(variant):
    """On a plane the map T is affine, J = diag(2 su, 2 sv, height): the tangent method is
    then exact, (J T1) x (J T2) = cof(J) N, like the cofactor (jacobian) method, while the
    naive one maps the normal as a vector, J N (the error the paper rejects it for)."""
    m = _model(base="plane", tile="stone:2", tiles_u=4, tiles_v=3, height=0.2, w_offset=0.05,
               mode="exact")
    k = np.arange(m.vertex_count) % m.tiles[0].vertex_count
    J = np.array([2 * m.layout.size[0], 2 * m.layout.size[1], 0.2])
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)
    # tolerances: float32 rounding, and for the two finite offsets (eps = 1e-3 tile units)
    # its cancellation, ~ulp(T) / (eps |J|) ~ 5e-4
    expect = {"jacobian": (unit(m.tiles[0].normals[k] / J), 1e-5),
              "tangent": (unit(m.tiles[0].normals[k] / J), 2e-3),
              "naive": (unit(m.tiles[0].normals[k] * J), 2e-3)}
    for method, (e, tol) in expect.items():
        _, n, _ = m.map(method=method)
        assert np.abs(_np(n) - e).max() < tol, method
    # tiles turned by 30 degrees: J = diag(2 su, 2 sv, h) [R 0; 0 1]
    m = _model(base="plane", tile="stone:2", tiles_u=4, tiles_v=3, height=0.2, mode="exact",
               animation=Animation(rotation_rate=np.radians(30.0)))
    c, s_ = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    J = np.diag([2 * m.layout.size[0], 2 * m.layout.size[1], 0.2]) @ np.array(
        [[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    N = m.tiles[0].normals[k]
    for method, e, tol in (("jacobian", unit(N @ np.linalg.inv(J)), 1e-5),
                           ("naive", unit(N @ J.T), 2e-3)):
        _, n, _ = m.map(t=1.0, method=method)
        assert np.abs(_np(n) - e).max() < tol, method
    with pytest.raises(ValueError, match=r"^ddm: unknown 'normals' 'bent'; expected one of "
                                         r"tangent, jacobian, naive$"):
        m.map(method="bent")


def test_model_size_check_for_one_column_and_no_refit_without_auto(variant):
    """A single column of 2^40 cells is refused by the cell-count bound, before any layout
    array is allocated (8 TiB); a model with a given map_resolution does not change its
    maps for sensors (fit_to_sensors: True only when the maps changed)."""
    import warnings

    from mi_displace.ddm.model import DDMConfig, DDMModel

    with pytest.raises(ValueError, match="tiles_u"):
        DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=1, tiles_v=2 ** 40))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="sphere", tile="stone:1", tiles_u=4, tiles_v=4,
                               map_resolution=16))
    maps = m.maps
    assert m.fit_to_sensors([], None) is False and m.maps is maps


def test_model_w_max_rule_and_memory_ratio(variant):
    """_w_max is the largest |w| of the mapped tiles (exact mode on the plane: the mapped z),
    an offset below the surface included; the rule of a given map_resolution is "given";
    mesh_over_hddm is the ratio of the two byte counts; an unknown base is named."""
    import warnings

    from mi_displace.ddm.model import DDMConfig, DDMModel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="plane", tile="thorn", tiles_u=2, tiles_v=2, height=0.1,
                               w_offset=-0.5, mode="exact"))
        maps = DDMModel(DDMConfig(base="sphere", tile="stone:1", tiles_u=4, tiles_v=4,
                                  map_resolution=16))
    p, _, _ = m.map()
    assert m._w_max() == pytest.approx(np.abs(np.asarray(p.z)).max(), rel=1e-5)
    assert maps.resolution_rule == "given" and maps.stats()["map_resolution_rule"] == "given"
    r = maps.memory_report()
    assert r["mesh_over_hddm"] == pytest.approx(r["mesh_bytes"] / r["hddm_bytes"])
    with pytest.raises(ValueError, match=r"^ddm: unknown 'base' 'cube'; expected one of .* or 'mesh'$"):
        DDMConfig(base="cube").check()


def test_model_stats_clamped_mask_and_fold_message(variant):
    """An exact-mode model prunes nothing (tiles_pruned 0); on a mesh base (a sphere cap
    with a disc-shaped UV layout) a mapped vertex is clamped exactly when its uv lies off the
    layout (the disc of radius ~0.47 about (0.5, 0.5)); the fold warning of an analytic base
    counts "sampled points of the base"."""
    import warnings

    from mi_displace.ddm.mesh_base import MeshBase
    from mi_displace.ddm.model import DDMConfig, DDMModel, FoldingWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = DDMModel(DDMConfig(base="mesh", tile="stone:1", tiles_u=6, tiles_v=6, height=0.05,
                               mode="exact"), base=MeshBase(*spherical_cap(2.0)))
    assert m.stats()["tiles_pruned"] == m.pruned
    _, _, uv = m.map()
    clamped = m.clamped_mask(uv)
    radius = np.hypot(np.asarray(uv.x) - 0.5, np.asarray(uv.y) - 0.5)
    assert clamped.shape == radius.shape and clamped.any() and not clamped.all()
    assert not clamped[radius < 0.44].any() and clamped[radius > 0.48].all()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exact = DDMModel(DDMConfig(base="sphere", tile="stone:1", tiles_u=4, tiles_v=4,
                                   mode="exact"))
    assert exact.stats()["tiles_pruned"] == 0
    with pytest.warns(FoldingWarning, match=r" of [0-9,]+ sampled points of the base \(det"):
        DDMModel(DDMConfig(base="sphere", tile="thorn", tiles_u=4, tiles_v=4, height=-4.0,
                           mode="exact"))
