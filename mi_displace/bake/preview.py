"""A bake rendered in Mitsuba next to its high-poly: each way to use it, FLIP per pixel.

:func:`compare_bake` renders the high-poly (the truth) and the bake's scene fragments
(:mod:`fragments`) with Mitsuba's ``path`` integrator (one directional light,
``max_depth`` 2: no noise but the pixel filter's), and measures the FLIP error of each
against the high-poly, over the whole image and separately on pixels whose texel lies on a
UV chart border and inside the charts (a seam shows as a border error above the interior's):

=================  ==============================================================
``displaced``      ``mitsuba_displaced.xml`` (the displacement map, ``displaced``)
``restored``       ``mitsuba_restored.xml`` (``restored``, ``levels="auto"``)
``mikk``           ``mitsuba_normalmap.xml``: ``mikk_normalmap`` on ``normal_tangent.png``
``stock``          ``mitsuba_normalmap_stock.xml``: ``normalmap`` on ``normal_mitsuba.png``
``stock_on_mikk``  Mitsuba's ``normalmap`` on ``normal_tangent.png`` (the frame mismatch)
``no_map``         the low-poly with its own normals
=================  ==============================================================

Ways whose files the bake did not write are skipped.  Pixels within 3 pixels of either
silhouette are left out of the border / interior means (the low-poly's outline is not the
high-poly's, whatever the map).  The chart border is measured on the low-poly's UVs (an
AOV), so the displaced and restored surfaces are classified by the low-poly pixel under them.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.ndimage import binary_erosion

from mi_displace.bake.formats import read_metadata
from mi_displace.bake.meshdata import MeshData, load_mesh, save_obj, vertex_normals
from mi_displace.bake.mitsuba_frames import prepare_scene
from mi_displace.bake.uv_raster import UVLayout, rasterize_rows
from mi_displace.core.dicing import fit_to_sensors
from mi_displace.evaluate.metrics import flip

#: name -> scene fragment, or (BSDF plugin, map file) on ``low.obj`` (None: no normal map)
WAYS = {"displaced": "mitsuba_displaced.xml", "restored": "mitsuba_restored.xml",
        "mikk": "mitsuba_normalmap.xml", "stock": "mitsuba_normalmap_stock.xml",
        "stock_on_mikk": ("normalmap", "normal_tangent.png"), "no_map": (None, None)}
#: the normal-map ways decoded texel by texel (:func:`decode_errors`): (BSDF, map file)
DECODES = {"mikk": ("mikk_normalmap", "normal_tangent.png"),
           "stock": ("normalmap", "normal_mitsuba.png"),
           "stock_on_mikk": ("normalmap", "normal_tangent.png")}


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


def decoded_normals(out_dir, bsdf_type: str, map_file: str, low: MeshData, width: int,
                    height: int, to_world: np.ndarray | None = None, green: str = "+y"
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World normals the BSDF shades with at every texel centre inside a UV triangle.

    A ray along -n hits the low-poly (loaded by Mitsuba from low.obj) at the texel's point;
    the nested BSDF is a smooth mirror, so the sampled direction is the reflection of wi
    about the decoded normal N: N = normalize(wi + wo).

    Args:
        out_dir: the bake's folder (``low.obj``, ``map_file``); bsdf_type: ``mikk_normalmap``
            or ``normalmap``; low: the bake's low-poly; width, height: the map's size [texels];
            to_world: (4, 4) similarity placing ``low.obj`` (None: identity); the rays follow;
            green: the map's green convention, given to ``mikk_normalmap``.

    Returns:
        texel indices (N,) (row-major, row 0 on top), decoded unit normals (N, 3) in world
        space, and (N,) bool: the ray met the texel's own triangle and the BSDF kept the
        reflection."""
    m = np.eye(4) if to_world is None else np.asarray(to_world, np.float64)
    extra = {"green": green} if bsdf_type == "mikk_normalmap" else {}
    scene = mi.load_dict({"type": "scene", "low": {
        "type": "obj", "filename": str(Path(out_dir) / "low.obj"),
        "to_world": mi.ScalarTransform4f(mi.ScalarMatrix4f(m.tolist())),
        "bsdf": {"type": bsdf_type, "normalmap": {"type": "bitmap", "raw": True,
                                                  "filename": str(Path(out_dir) / map_file)},
                 "nested": {"type": "conductor"}, **extra}}})
    prepare_scene(scene)
    s = rasterize_rows(UVLayout(low), width, height, 0, height, 1, conservative=False)
    texel, f = np.asarray(s.texel, np.int64), np.asarray(s.prim, np.int64)
    w = np.stack([1 - np.asarray(s.b1) - np.asarray(s.b2), np.asarray(s.b1), np.asarray(s.b2)], 1)
    p = (low.positions[low.faces[f]] * w[..., None]).sum(1)
    n = (vertex_normals(low.positions, low.faces)[low.faces[f]] * w[..., None]).sum(1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    o = p + 1e-4 * low.diagonal * n
    o, n = o @ m[:3, :3].T + m[:3, 3], n @ m[:3, :3].T        # a similarity keeps n normal
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(o[:, k].copy()) for k in range(3))),
                   mi.Vector3f(*(mi.Float(-n[:, k].copy()) for k in range(3))))
    si = scene.ray_intersect(ray)
    bs, weight = si.bsdf().sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5), si.is_valid())
    decoded = dr.normalize(-ray.d + si.to_world(bs.wo))
    # the texel's own triangle (a centre on an edge may hit the neighbour, across a seam
    # another chart's texels), and a reflection the BSDF kept
    ok = np.asarray(si.is_valid() & (dr.max(weight) > 0)) & (np.asarray(si.prim_index) == f)
    return texel, np.stack([np.asarray(c) for c in decoded], 1), ok


def decode_errors(out_dir, low: MeshData, normal_object: np.ndarray, measured: np.ndarray,
                  border: float = 2) -> dict:
    """Per-texel decode error of each normal-map way (:data:`DECODES`) against the bake's
    object-space normals, at the texel centres inside a UV triangle.

    Args:
        normal_object: (H, W, 3) the bake's object-space normals (float, the truth).
        measured: (H, W) bool, texels that found the high-poly.

    Returns:
        ``{way: {"texels", "max_deg", "p99_deg", "mean_deg", "over_1deg",
        "border_mean_deg", "interior_mean_deg"}}`` for the ways whose map exists.
    """
    H, W = measured.shape
    out = {}
    for way, (plugin, map_file) in DECODES.items():
        if not (Path(out_dir) / map_file).is_file():
            continue
        green = read_metadata(Path(out_dir) / map_file).get("green", "+y")
        texel, n, ok = decoded_normals(out_dir, plugin, map_file, low, W, H, green=green)
        use = ok & measured.ravel()[texel]
        truth = normal_object.reshape(-1, 3)[texel[use]].astype(np.float64)
        err = np.degrees(np.arctan2(np.linalg.norm(np.cross(n[use], truth), axis=1),
                                    (n[use] * truth).sum(1)))
        covered = np.zeros(H * W, bool)
        covered[texel] = True
        at_border = chart_border(covered.reshape(H, W), border).ravel()[texel[use]]
        out[way] = {"texels": int(use.sum()), "max_deg": float(err.max()),
                    "p99_deg": float(np.percentile(err, 99)), "mean_deg": float(err.mean()),
                    "over_1deg": int((err > 1).sum()),
                    "border_mean_deg": float(err[at_border].mean()),
                    "interior_mean_deg": float(err[~at_border].mean())}
    return out


def _shape(out_dir: Path, way) -> dict | mi.Shape | None:
    """The shape of one way (None: its files are not in ``out_dir``)."""
    if isinstance(way, str):
        if not (out_dir / way).is_file():
            return None
        return mi.load_file(str(out_dir / way)).shapes()[0]
    plugin, map_file = way
    if map_file is not None and not (out_dir / map_file).is_file():
        return None
    bsdf = {"type": "diffuse"} if plugin is None else {
        "type": plugin, "nested": {"type": "diffuse"},
        "normalmap": {"type": "bitmap", "raw": True, "filename": str(out_dir / map_file)}}
    return {"type": "obj", "filename": str(out_dir / "low.obj"), "bsdf": bsdf}


def compare_bake(high: MeshData, out_dir, res: int = 128, spp: int = 16,
                 border: float = 2, ways=tuple(WAYS)) -> dict:
    """Render the bake in ``out_dir`` (its fragments, ``low.obj`` and maps) against ``high``.

    Args:
        high: the high-poly the bake was made from [object units].
        out_dir: the bake's folder.
        res: image side [pixels]; spp: samples per pixel; border: chart-border width [texels].
        ways: names from :data:`WAYS` (those whose files are missing are skipped).

    Returns:
        ``{"reference": (res, res, 3) image, way: {"image", "flip_map" (res, res),
        "flip", "flip_border", "flip_interior", "border_pixels", "interior_pixels"}}``.
    """
    out_dir = Path(out_dir).resolve()
    lo, hi = high.positions.min(0), high.positions.max(0)
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)
    light = (-0.45, -0.35, -0.82)      # from the upper right, behind the camera

    def render(shape):
        scene = _scene(shape, centre, radius, res, light)
        prepare_scene(scene)
        fit_to_sensors(scene)            # restored levels="auto" for this camera
        return np.asarray(mi.render(scene, spp=spp), np.float32)[..., :3]

    with tempfile.TemporaryDirectory() as tmp:
        high_path = save_obj(Path(tmp) / "high.obj", high.positions, high.faces,
                             normals=high.normals())
        reference = render({"type": "obj", "filename": str(high_path)})

    # the texel under every pixel: the low-poly's UVs as an AOV
    aov = _scene({"type": "obj", "filename": str(out_dir / "low.obj")}, centre, radius, res, light)
    uv = np.asarray(mi.render(aov, spp=1, integrator=mi.load_dict(
        {"type": "aov", "aovs": "uv:uv,depth:depth"})), np.float32)
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
    inside = binary_erosion((uv[..., 2] > 0) & (reference.sum(-1) > 0), iterations=3)
    at_border = chart_border(covered, border)[row, col] & inside
    interior = ~at_border & inside
    result = {"reference": reference}
    for way in ways:
        shape = _shape(out_dir, WAYS[way])
        if shape is None:
            continue
        image = render(shape)
        mean, error = flip(reference, image)
        result[way] = {"image": image, "flip_map": error, "flip": mean,
                       "flip_border": float(error[at_border].mean()),
                       "flip_interior": float(error[interior].mean()),
                       "border_pixels": int(at_border.sum()), "interior_pixels": int(interior.sum())}
    return result


def write_preview(result: dict, out_dir, decodes: dict | None = None) -> tuple[Path, Path]:
    """``preview.png`` (top: the high-poly, then each way; bottom: each way's FLIP map, white =
    1) and ``preview.json`` (the numbers of ``result`` and, under ``decode``, ``decodes``
    of :func:`decode_errors`) in ``out_dir``; returns both paths."""
    import json

    ways = [k for k in result if k != "reference"]
    top = np.concatenate([result["reference"]] + [result[w]["image"] for w in ways], 1)
    flips = [np.repeat(result[w]["flip_map"][..., None], 3, 2) for w in ways]
    bottom = np.concatenate([np.zeros_like(result["reference"])] + flips, 1)
    png = Path(out_dir) / "preview.png"
    mi.util.write_bitmap(str(png), np.concatenate([top, bottom], 0), write_async=False)
    numbers = {w: {k: v for k, v in result[w].items() if not isinstance(v, np.ndarray)} for w in ways}
    js = Path(out_dir) / "preview.json"
    js.write_text(json.dumps({"columns": ["high-poly", *ways], **numbers,
                              "decode": decodes or {}}, indent=2))
    return png, js
