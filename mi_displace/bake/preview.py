"""A bake rendered in Mitsuba next to its high-poly: the normal map in each frame, FLIP per pixel.

:func:`compare_normal_maps` renders the high-poly (the truth) and the low-poly of a bake
under three normal-map BSDFs with Mitsuba's ``path`` integrator (one directional light,
``max_depth`` 2: no noise but the pixel filter's), and measures the FLIP error of each
against the high-poly, separately on pixels whose texel lies on a UV chart border and on
the charts' interiors (a seam shows as a border error above the interior's):

=================  ==============================================================
``mikk``           ``mikk_normalmap`` on ``normal_tangent.png`` (MikkTSpace)
``stock``          Mitsuba's ``normalmap`` on ``normal_mitsuba.png`` (its frame)
``stock_on_mikk``  Mitsuba's ``normalmap`` on ``normal_tangent.png`` (the mismatch)
``no_map``         the low-poly with its own normals
=================  ==============================================================

Pixels within 3 pixels of either silhouette are left out of the border / interior means
(the low-poly's outline is not the high-poly's, whatever the map).
"""
from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.meshdata import MeshData, load_mesh, save_obj
from mi_displace.bake.mitsuba_frames import prepare_scene
from mi_displace.bake.uv_raster import UVLayout, rasterize_rows

#: name -> (BSDF plugin, map file) of the low-poly renders (None: no normal map)
WAYS = {"mikk": ("mikk_normalmap", "normal_tangent.png"),
        "stock": ("normalmap", "normal_mitsuba.png"),
        "stock_on_mikk": ("normalmap", "normal_tangent.png"),
        "no_map": (None, None)}


def chart_border(covered: np.ndarray, width: float = 2) -> np.ndarray:
    """(H, W) bool: covered texels within ``width`` texels (chessboard) of an uncovered one."""
    from scipy.ndimage import distance_transform_cdt

    return covered & (distance_transform_cdt(covered, metric="chessboard") <= width)


def _scene(shape: dict, centre, radius: float, res: int, light_dir) -> mi.Scene:
    eye = np.asarray(centre) + np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0]) * 2.4 * radius
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(eye.tolist(), list(centre), [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}},
        "sun": {"type": "directional", "direction": list(light_dir), "irradiance": 3.0},
        "shape": shape})


def compare_normal_maps(high: MeshData, out_dir, res: int = 128, spp: int = 16,
                        border: float = 2, ways=tuple(WAYS)) -> dict:
    """Render the bake in ``out_dir`` (``low.obj`` + its normal maps) against ``high``.

    Args:
        high: the high-poly the bake was made from [object units].
        out_dir: the bake's folder (needs ``normal_tangent`` / ``normal_mitsuba`` maps for
            the ways that use them).
        res: image side [pixels]; spp: samples per pixel; border: chart-border width [texels].
        ways: names from :data:`WAYS`.

    Returns:
        ``{"reference": (res, res, 3) image, way: {"image", "flip_map" (res, res),
        "flip", "flip_border", "flip_interior", "border_pixels", "interior_pixels"}}``.
    """
    out_dir = Path(out_dir)
    lo, hi = high.positions.min(0), high.positions.max(0)
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)
    light = (-0.45, -0.35, -0.82)      # from the upper right, behind the camera
    high_path = save_obj(out_dir / "preview_high.obj", high.positions, high.faces,
                         normals=high.normals())

    def render(shape):
        scene = _scene(shape, centre, radius, res, light)
        prepare_scene(scene)
        return np.asarray(mi.render(scene, spp=spp), np.float32)[..., :3]

    reference = render({"type": "obj", "filename": str(high_path)})
    low = {"type": "obj", "filename": str(out_dir / "low.obj")}
    # the texel under every pixel: the low-poly's UVs as an AOV
    aov = _scene({**low}, centre, radius, res, light)
    uv = np.asarray(mi.render(aov, spp=1, integrator=mi.load_dict(
        {"type": "aov", "aovs": "uv:uv,hit:shape_index"})), np.float32)
    H, W = np.asarray(mi.Bitmap(str(out_dir / "valid.png"))).shape[:2]
    col = np.clip((uv[..., 0] * W).astype(np.int64), 0, W - 1)
    row = np.clip((uv[..., 1] * H).astype(np.int64), 0, H - 1)
    s = rasterize_rows(UVLayout(load_mesh(out_dir / "low.obj", "low-poly")), W, H, 0, H, 1,
                       conservative=False)
    covered = np.zeros(H * W, bool)
    covered[np.asarray(s.texel, np.int64)] = True      # texel centres inside a UV triangle
    covered = covered.reshape(H, W)
    # pixels on both surfaces, 3 pixels clear of either silhouette (the low-poly's outline
    # differs from the high-poly's whatever the map)
    from scipy.ndimage import binary_erosion

    inside = binary_erosion((uv[..., 2] >= 0) & (reference.sum(-1) > 0), iterations=3)
    at_border = chart_border(covered, border)[row, col] & inside
    interior = ~at_border & inside
    from mi_displace.evaluate.metrics import flip

    result = {"reference": reference}
    for way in ways:
        plugin, map_file = WAYS[way]
        bsdf = {"type": "diffuse"} if plugin is None else {
            "type": plugin, "nested": {"type": "diffuse"},
            "normalmap": {"type": "bitmap", "raw": True, "filename": str(out_dir / map_file)}}
        image = render({**low, "bsdf": bsdf})
        mean, error = flip(reference, image)
        result[way] = {"image": image, "flip_map": error, "flip": mean,
                       "flip_border": float(error[at_border].mean()),
                       "flip_interior": float(error[interior].mean()),
                       "border_pixels": int(at_border.sum()), "interior_pixels": int(interior.sum())}
    return result
