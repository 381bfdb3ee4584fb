"""Baked normal maps decoded by Mitsuba: ``mikk_normalmap`` on the MikkTSpace map and the stock
``normalmap`` on the ``normal_mitsuba`` map reproduce the bake's object-space normals; the stock
BSDF on the MikkTSpace map does not (issue 29's seams)."""
import mitsuba as mi
import numpy as np
import pytest
from bake_meshes import _sphere_mesh

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData
from mi_displace.bake.mitsuba_frames import prepare_scene
from mi_displace.bake.preview import decoded_normals
from mi_displace.bake.trace import OK

RES = 128


def _angle_deg(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1)))


@pytest.fixture
def charts_bake(sphere_pair, built_once, tmp_path_factory):
    """The displaced sphere baked over a coarse sphere that xatlas cuts into several charts
    (float, MikkTSpace and Mitsuba-frame maps at RES^2, aa 1: texel centres): (result, its
    folder), baked once per run (read only)."""
    def build():
        high, _ = sphere_pair
        low = _sphere_mesh(16, 8, 0.0)
        low = MeshData(low.positions, low.faces, name="low")     # no UVs: the baker unwraps
        out = tmp_path_factory.mktemp("charts_bake")
        return bake(high, low, res=RES, out_dir=out, max_distance=0.2, pad=4,
                    map_formats=["float", "normal_tangent", "normal_mitsuba"]), out

    return built_once("charts_bake", build)


def _decoded_by_mitsuba(out_dir, bsdf_type, map_file, low):
    return decoded_normals(out_dir, bsdf_type, map_file, low, RES, RES)


@pytest.mark.parametrize("bsdf_type, map_file, tol_deg", [
    ("mikk_normalmap", "float_normal.exr", 0.02),   # float: only the decode's own error
    ("mikk_normalmap", "normal_tangent.png", 0.6),  # 8 bits per component
    ("normalmap", "normal_mitsuba.png", 0.6),
])
def test_mitsuba_decodes_the_object_space_normals(charts_bake, bsdf_type, map_file, tol_deg):
    r, out = charts_bake
    assert r.record["low"]["notes"], "the low-poly must have been unwrapped (several charts)"
    texel, n, ok = _decoded_by_mitsuba(out, bsdf_type, map_file, r.low)
    truth = r.maps["normal_object"].reshape(-1, 3)[texel]
    use = ok & (r.status.ravel()[texel] == OK)
    assert use.sum() > 0.95 * len(texel) and len(texel) > 0.3 * RES * RES
    assert np.all(np.isfinite(n[use]))
    err = _angle_deg(n[use], truth[use])
    assert _angle_deg(truth[use], r.maps["normal_tangent"].reshape(-1, 3)[texel][use]).max() > 5
    assert err.max() < tol_deg, f"{bsdf_type} on {map_file}: max {err.max():.3f} deg"


@pytest.mark.parametrize("bsdf_type, map_file", [("mikk_normalmap", "float_normal.exr"),
                                                 ("normalmap", "normal_mitsuba.png")])
def test_a_placed_low_poly_decodes_the_rotated_normals(charts_bake, bsdf_type, map_file):
    """to_world = rotation, uniform scale and translation: the decoded normals are the
    object-space ones rotated (the MikkTSpace frame is computed on the placed mesh)."""
    r, out = charts_bake
    from scipy.spatial.transform import Rotation

    rotation = Rotation.from_rotvec(np.radians(50) * np.array([1, 2, 3]) / np.sqrt(14)).as_matrix()
    to_world = np.eye(4)
    to_world[:3, :3], to_world[:3, 3] = 2.5 * rotation, [0.3, -1.0, 2.0]
    texel, n, ok = decoded_normals(out, bsdf_type, map_file, r.low, RES, RES, to_world)
    use = ok & (r.status.ravel()[texel] == OK)
    assert use.sum() > 0.95 * len(texel)
    truth = r.maps["normal_object"].reshape(-1, 3)[texel][use] @ rotation.T
    tol = 0.02 if map_file.endswith(".exr") else 0.6
    assert _angle_deg(n[use], truth).max() < tol


def test_stock_normalmap_on_the_mikktspace_map_is_wrong(charts_bake):
    """The failure the issue reports: Mitsuba's own frame is not MikkTSpace's."""
    r, out = charts_bake
    texel, n, ok = _decoded_by_mitsuba(out, "normalmap", "normal_tangent.png", r.low)
    use = ok & (r.status.ravel()[texel] == OK)
    err = _angle_deg(n[use], r.maps["normal_object"].reshape(-1, 3)[texel][use])
    assert np.percentile(err, 99) > 2.0


def test_mikk_normalmap_bad_input(variant, tmp_path):
    with pytest.raises(Exception, match="mikk_normalmap: parameter 'normalmap'"):
        mi.load_dict({"type": "mikk_normalmap", "nested": {"type": "diffuse"}})
    def tex():
        return {"type": "bitmap", "data": mi.TensorXf(np.full((2, 2, 3), 0.5, np.float32)), "raw": True}
    with pytest.raises(Exception, match="exactly one nested BSDF"):
        mi.load_dict({"type": "mikk_normalmap", "normalmap": tex()})
    # a scene rendered without prepare_scene: one warning naming the fix, the unperturbed
    # material (never zeros read as a frame, never an exception inside a trace)
    scene = mi.load_dict({"type": "scene", "s": {
        "type": "rectangle", "bsdf": {"type": "mikk_normalmap", "normalmap": tex(),
                                      "nested": {"type": "diffuse"}}},
        "light": {"type": "constant"}, "integrator": {"type": "path"},
        "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4},
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0])}})
    with pytest.warns(UserWarning, match="prepare_scene"):
        img = np.asarray(scene.integrator().render(scene, scene.sensors()[0], spp=1))
    assert np.isfinite(img).all() and img.mean() > 0
    with pytest.raises(ValueError, match="not a triangle mesh|no UVs"):
        prepare_scene(scene)


def _mirror_every_other_chart(low: MeshData) -> int:
    """Mirror the UVs of every second chart in its own box (u -> u_min + u_max - u), as
    artists mirror symmetric parts: MikkTSpace's sign flips there, Mitsuba's frame does not.
    Returns the number of charts."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f, V = low.faces, len(low.positions)
    edges = coo_matrix((np.ones(3 * len(f)), (f.ravel(), np.roll(f, 1, axis=1).ravel())), shape=(V, V))
    count, chart = connected_components(edges, directed=False)
    uv = low.uvs.copy()
    for c in range(1, count, 2):          # a handful of charts
        m = chart == c
        uv[m, 0] = uv[m, 0].min() + uv[m, 0].max() - uv[m, 0]
    low.uvs = uv
    return count


def test_rendered_mikk_map_has_no_seam_and_stock_decode_of_it_does(variant, tmp_path):
    """Low-poly + baked map under ``path`` against the high-poly (FLIP per pixel), on chart
    borders and inside the charts: ours and the stock BSDF on its own map show no seam; the
    stock BSDF on the MikkTSpace map errs most along the borders of the mirrored charts."""
    from mi_displace.bake.preview import compare_bake
    from mi_displace.bake.unwrap import unwrap

    high = _sphere_mesh(400, 200, 0.0)
    p = high.positions.astype(np.float64)
    bumps = 0.015 * np.sin(12 * p[:, 0]) * np.sin(12 * p[:, 1]) * np.sin(12 * p[:, 2])
    high = MeshData((p * (1 + bumps[:, None])).astype(np.float32), high.faces, name="bumpy")
    low = _sphere_mesh(24, 12, 0.0)
    low = unwrap(MeshData(low.positions, low.faces, name="low"), resolution=256)
    assert _mirror_every_other_chart(low) >= 4
    bake(high, low, res=256, out_dir=tmp_path, max_distance=0.1, pad=4,
         map_formats=["normal_tangent", "normal_mitsuba"])
    r = compare_bake(high, tmp_path, res=128, spp=16, ways=("mikk", "stock", "stock_on_mikk", "no_map"))
    for way in ("mikk", "stock", "stock_on_mikk", "no_map"):
        image = r[way]["image"]
        assert np.all(np.isfinite(image)) and image.mean() > 0.01, way
        assert r[way]["border_pixels"] > 200 and r[way]["interior_pixels"] > 2000
    mikk, stock, wrong = r["mikk"], r["stock"], r["stock_on_mikk"]
    for ok in (mikk, stock):       # no seam: the borders are no worse than the interiors
        assert ok["flip_border"] <= 1.1 * ok["flip_interior"]
        assert ok["flip"] < 0.8 * r["no_map"]["flip"]    # and the map does something
    assert wrong["flip_border"] > 1.1 * wrong["flip_interior"]     # the seams
    assert wrong["flip_border"] > 1.5 * mikk["flip_border"]


def test_mikk_normalmap_is_corner_exact_where_a_vertex_holds_two_spaces(sphere_pair, tmp_path):
    """Folded UV charts (three vertices' UVs pushed 3 cells sideways): fans hold both
    orientations, so some vertices carry two MikkTSpace spaces; ``prepare_scene`` splits them
    and the float map decodes to the object-space map there too."""
    high, _ = sphere_pair
    low = _sphere_mesh(24, 12, 0.0)
    uv = low.uvs.copy()
    for v in (24 * 3 + 5, 25 * 6 + 11, 25 * 8 + 17):
        uv[v, 0] += 3.0 / 24
    low.uvs = uv
    with pytest.warns(UserWarning, match="overlapping"):
        r = bake(high, low, res=RES, out_dir=tmp_path, max_distance=0.2, pad=0, map_formats=["float"])
    texel, n, ok = _decoded_by_mitsuba(tmp_path, "mikk_normalmap", "float_normal.exr", r.low)
    use = ok & (r.status.ravel()[texel] == OK)
    assert use.sum() > 0.9 * len(texel)
    err = _angle_deg(n[use], r.maps["normal_object"].reshape(-1, 3)[texel][use])
    assert err.max() < 0.05, f"max {err.max():.3f} deg, {(err > 1).sum()} texels over 1 deg"
