"""`mi-displace bench bake_blender`: our baker against Blender's Cycles bake (optional).

Blender runs in a Python with ``bpy`` (:mod:`mi_displace.bench.peers.blender`, named by
``$MI_DISPLACE_BLENDER_PYTHON``); without one, each pair records our bake alone and
``blender_reason`` ("peer unavailable: ...").

Pairs (meshes of our own choosing): **Spot** (``data/spot``, 5,856 faces) loop-subdivided
twice and displaced along its normals by a procedural relief, and the **Stanford bunny** scan
(69,451 faces, holes at the bottom).  Each low-poly is made by ``bake()`` itself (Taubin
smoothing, fast-simplification, xatlas UVs) and written to ``low.obj``; Blender imports that
file (same UVs, same vertex normals) and the high-poly, and bakes with the same search
distance (:mod:`mi_displace.bench.peers.blender_side`).

Compared per texel where both bakers measured the high-poly:

* object-space normals: angle between the maps;
* tangent-space normals: angle between the maps, and the **MikkTSpace decode test** for
  both: each tangent map decoded with MikkTSpace (:func:`mikktspace.decode_tangent_map`)
  against the same baker's object-space map (texels over 1 degree);
* heights: our displacement against Blender's, d = (P_high - P_low) . n_low from its
  position and normal bakes, in % of the diagonal;
* coverage: texels each baker measured, and those only one did;
* time: our ``bake()`` (acceleration + all maps at once + padding, warm and first call)
  against the sum of Blender's normal (tangent, object) and position bakes;
* DirectX: Blender's ``normal_g = NEG_Y`` map, y negated, against our tangent-space normals
  (angle), and our ``green="-y"`` file against our OpenGL one (G = 1 - G exactly);
* ambient occlusion at equal samples and distance (:data:`AO_SAMPLES`, :data:`AO_DISTANCE_REL`
  of the diagonal): mean and mean absolute difference of the maps, and our AO bake's time
  (projection + AO + padding) against Blender's AO bake in the same run;
* curvature: Blender has no curvature bake; its Geometry > Pointiness baked as emission
  against our mean curvature H: Pearson correlation over the texels both measured;
* albedo (:func:`compare_albedo`): Spot itself (its own UVs) under a procedural sRGB texture
  over a 1,000-face low-poly, our ``albedo`` map against Cycles' DIFFUSE colour bake, and
  both times.

Writes ``bake_blender.json`` under ``--out`` (default outside the checkout).  ``--quick``:
Spot subdivided once alone, 128^2 texels, a 1,000-face low-poly.
"""
from __future__ import annotations

import json as _json
import time
from pathlib import Path

import numpy as np

from mi_displace.bench._timing import output_dir
from mi_displace.core.resources import data_path

SPOT = data_path("spot", "spot_triangulated.obj")
AO_SAMPLES = 32          # AO rays per texel (Blender: render samples of its AO bake)
AO_DISTANCE_REL = 0.1    # AO ray length, fraction of the high-poly's diagonal
BUNNY = data_path("bunny", "stanford-bunny.obj")


def spot_displaced(iterations: int = 2):
    """Spot, loop-subdivided ``iterations`` times (twice: 93,696 faces), displaced along its
    welded normals by 0.4 % of the diagonal x sin sin sin at 8 periods per diagonal."""
    import trimesh

    from mi_displace.bake.meshdata import MeshData, load_mesh, vertex_normals

    spot = load_mesh(SPOT, "spot")
    v, f = trimesh.remesh.subdivide_loop(spot.positions.astype(np.float64), spot.faces,
                                        iterations=iterations)
    n = vertex_normals(v.astype(np.float32), f)
    k = 2 * np.pi * 8 / spot.diagonal
    h = 0.004 * spot.diagonal * np.sin(k * v[:, 0]) * np.sin(k * v[:, 1]) * np.sin(k * v[:, 2])
    return MeshData((v + h[:, None] * n).astype(np.float32), f.astype(np.int64), name="spot_displaced")


def _angle_deg(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1)))


def _stats(x) -> dict:
    x = np.asarray(x, np.float64)
    return {"median": float(np.median(x)), "p99": float(np.percentile(x, 99)), "max": float(x.max())}


def compare_pair(high, res: int, out: Path, target_faces: int) -> dict:
    from mi_displace.bake.baker import bake
    from mi_displace.bake.meshdata import load_mesh, save_obj
    from mi_displace.bake.mikktspace import decode_tangent_map
    from mi_displace.bake.trace import AMBIGUOUS, OK
    from mi_displace.bench.peers import blender, measure

    out.mkdir(parents=True, exist_ok=True)
    save_obj(out / "high.obj", high.positions, high.faces)
    start = time.perf_counter()
    first = bake(out / "high.obj", None, res=res, out_dir=out / "ours", target_faces=target_faces,
                 map_formats=["float", "normal_tangent"])
    first_call = time.perf_counter() - start
    # warm: the same bake again over the low-poly it made (no simplification / unwrapping)
    r = bake(out / "high.obj", out / "ours" / "low.obj", res=res, map_formats=["float"],
             max_distance=first.record["settings"]["max_distance"])
    dist = r.record["settings"]["max_distance"]
    low = load_mesh(out / "ours" / "low.obj", "low-poly")
    ours_hit = (r.status == OK) | (r.status == AMBIGUOUS)
    ours_bake = r.record["timings"]["bake_s"]
    pair = {"high_faces": int(len(high.faces)), "low_faces": int(len(low.faces)), "res": res,
            "search_distance": dist, "search_distance_rel": dist / high.diagonal,
            "ours_measured": int(ours_hit.sum()), "ours_covered": int(r.covered.sum()),
            "ours_bake_s": ours_bake, "ours_first_call_s": first_call,
            "ours_warm_call_s": r.record["timings"]["total_s"]}
    ao_distance = AO_DISTANCE_REL * high.diagonal
    rao = bake(out / "high.obj", out / "ours" / "low.obj", res=res, map_formats=["ao"],
               max_distance=dist, ao_samples=AO_SAMPLES, ao_distance=ao_distance)
    rcurv = bake(out / "high.obj", out / "ours" / "low.obj", res=res, max_distance=dist,
                 map_formats=["curvature_float"])
    pair.update({"ao_samples": AO_SAMPLES, "ao_distance": ao_distance,
                 "ours_ao_bake_s": rao.record["timings"]["bake_s"],
                 "ours_curvature_bake_s": rcurv.record["timings"]["bake_s"]})
    cycles, reason = measure(blender.bake, out / "high.obj", out / "ours" / "low.obj", res, dist, out,
                             AO_SAMPLES, ao_distance)
    if cycles is None:
        return {**pair, "blender_reason": reason}
    b = cycles["maps"]
    # Cycles clears what it does not bake to (0, 0, 0); no unit normal encodes as 0
    b_cov = np.any(b["normal_low"][..., :3] != 0, axis=-1)
    b_hit = b_cov & np.any(b["normal_object"][..., :3] != 0, axis=-1)
    both = ours_hit & b_hit
    diag = high.diagonal
    b_obj = b["normal_object"][..., :3] * 2 - 1
    b_tan = b["normal_tangent"][..., :3] * 2 - 1
    ang_obj = _angle_deg(r.maps["normal_object"][both], b_obj[both])
    ang_tan = _angle_deg(r.maps["normal_tangent"][both], b_tan[both])
    dec_ours, inside = decode_tangent_map(low, r.maps["normal_tangent"])
    b_tan_unit = b_tan / np.maximum(np.linalg.norm(b_tan, axis=-1, keepdims=True), 1e-12)
    dec_b, _ = decode_tangent_map(low, b_tan_unit)
    m_ours = inside & ours_hit
    m_b = inside & b_hit
    err_ours = _angle_deg(dec_ours[m_ours], r.maps["normal_object"][m_ours])
    err_b = _angle_deg(dec_b[m_b], b_obj[m_b] / np.linalg.norm(b_obj[m_b], axis=-1, keepdims=True))
    n_low = b["normal_low"][..., :3] * 2 - 1
    n_low = n_low / np.maximum(np.linalg.norm(n_low, axis=-1, keepdims=True), 1e-12)
    d_b = ((b["position_high"][..., :3] - b["position_low"][..., :3]) * n_low).sum(-1)
    dh = np.abs(r.maps["displacement"][both] - d_b[both]) / diag * 100
    blender_s = sum(cycles["seconds"][k] for k in ("normal_tangent", "normal_object", "position_high"))
    b_dx = b["normal_tangent_directx"][..., :3] * 2 - 1
    b_dx[..., 1] *= -1
    ang_dx = _angle_deg(r.maps["normal_tangent"][both], b_dx[both])
    ao_ours, ao_b = rao.maps["ao"][both], b["ao"][both, 0]
    pointiness = b["pointiness"][both, 0]
    H = rcurv.maps["curvature"][both]
    return {
        **pair, "blender": cycles["version"],
        "coverage": {"blender_measured": int(b_hit.sum()),
                     "both": int(both.sum()), "only_ours": int((ours_hit & ~b_hit).sum()),
                     "only_blender": int((b_hit & ~ours_hit).sum()),
                     "blender_covered": int(b_cov.sum())},
        "normal_object_angle_deg": {**_stats(ang_obj), "over_1deg": int((ang_obj > 1).sum()),
                                    "over_5deg": int((ang_obj > 5).sum())},
        "normal_tangent_angle_deg": {**_stats(ang_tan), "over_1deg": int((ang_tan > 1).sum()),
                                     "over_5deg": int((ang_tan > 5).sum())},
        "mikktspace_decode_over_1deg": {"ours": int((err_ours > 1).sum()), "ours_texels": int(m_ours.sum()),
                                        "ours_max_deg": float(err_ours.max()),
                                        "blender": int((err_b > 1).sum()), "blender_texels": int(m_b.sum()),
                                        "blender_max_deg": float(err_b.max())},
        "height_abs_diff_pct_diag": {**_stats(dh), "over_0.1pct": int((dh > 0.1).sum())},
        "directx_normal_tangent_angle_deg": {**_stats(ang_dx), "over_1deg": int((ang_dx > 1).sum())},
        "ao": {"ours_mean": float(ao_ours.mean()), "blender_mean": float(ao_b.mean()),
               "mean_abs_diff": float(np.abs(ao_ours - ao_b).mean()),
               "ours_s": rao.record["timings"]["bake_s"], "blender_s": cycles["seconds"]["ao"],
               "ratio_ours_over_blender": rao.record["timings"]["bake_s"] / cycles["seconds"]["ao"]},
        "curvature_vs_pointiness": {"pearson": float(np.corrcoef(H, pointiness)[0, 1]),
                                    "ours_s": rcurv.record["timings"]["bake_s"],
                                    "blender_pointiness_s": cycles["seconds"]["pointiness"]},
        "time": {"blender_normal_tangent_object_position_s": blender_s,
                 "blender_each_s": cycles["seconds"], "ratio_ours_bake_over_blender": ours_bake / blender_s},
    }


def albedo_texture(path: Path, size: int = 512) -> Path:
    """An 8-bit sRGB PNG of ``size``^2: a 16 x 16 checker of orange and blue, its red
    channel ramping with u (smooth and sharp colour changes both)."""
    import mitsuba as mi

    u = (np.arange(size) + 0.5) / size
    cell = (np.arange(size) * 16 // size)
    odd = (cell[:, None] + cell[None, :]) % 2 == 1
    rgb = np.where(odd[..., None], [0.8, 0.3, 0.1], [0.1, 0.4, 0.8]).astype(np.float32)
    rgb[..., 0] *= 0.3 + 0.7 * u[None, :]
    srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * rgb ** (1 / 2.4) - 0.055)
    bitmap = mi.Bitmap(np.round(srgb * 255).astype(np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB)
    bitmap.set_srgb_gamma(True)
    bitmap.write(str(path))
    return path


def compare_albedo(res: int, out: Path) -> dict:
    """Albedo transfer from textured Spot (see the module docstring)."""
    from mi_displace.bake.baker import bake
    from mi_displace.bake.meshdata import load_mesh, save_obj
    from mi_displace.bake.trace import AMBIGUOUS, OK
    from mi_displace.bench.peers import blender, measure

    out.mkdir(parents=True, exist_ok=True)
    spot = load_mesh(SPOT, "spot")
    save_obj(out / "high.obj", spot.positions, spot.faces, spot.uvs)
    texture = albedo_texture(out / "texture.png")
    first = bake(out / "high.obj", None, res=res, out_dir=out / "ours", target_faces=1000,
                 map_formats=["d16"])
    dist = first.record["settings"]["max_distance"]
    r = bake(out / "high.obj", out / "ours" / "low.obj", res=res, max_distance=dist,
             map_formats=["albedo"], high_texture=texture)
    record = {"res": res, "high_faces": int(len(spot.faces)), "low_faces": first.record["low"]["faces"],
              "ours_albedo_bake_s": r.record["timings"]["bake_s"]}
    cycles, reason = measure(blender.bake, out / "high.obj", out / "ours" / "low.obj", res, dist,
                             out, texture=texture)
    if cycles is None:
        return {**record, "blender_reason": reason}
    b = cycles["maps"]["albedo"][..., :3]
    both = ((r.status == OK) | (r.status == AMBIGUOUS)) & np.any(b != 0, axis=-1)
    diff = np.abs(r.maps["albedo"][both] - b[both]).max(-1)
    return {**record, "texels_both": int(both.sum()),
            "abs_diff_max_channel": {**_stats(diff), "mean": float(diff.mean()),
                                     "over_0.01": int((diff > 0.01).sum())},
            "blender_albedo_s": cycles["seconds"]["albedo"],
            "ratio_ours_over_blender": r.record["timings"]["bake_s"] / cycles["seconds"]["albedo"]}


def run(out=None, quick: bool = False) -> dict:
    """Both pairs at 1024^2 (``quick``: Spot subdivided once alone, 128^2, 1,000 low-poly
    faces); the
    record, also written to ``out/bake_blender.json``."""
    from mi_displace.bake.meshdata import load_mesh

    out = output_dir("bake_blender", out)
    if quick:
        record = {"spot_displaced": compare_pair(spot_displaced(1), 128, out / "spot", 1000),
                  "spot_albedo": compare_albedo(128, out / "albedo")}
    else:
        record = {"spot_displaced": compare_pair(spot_displaced(), 1024, out / "spot", 3000),
                  "bunny": compare_pair(load_mesh(BUNNY, "bunny"), 1024, out / "bunny", 5000),
                  "spot_albedo": compare_albedo(1024, out / "albedo")}
    (out / "bake_blender.json").write_text(_json.dumps(record, indent=2))
    record["out"] = str(out)
    return record


def main(json: bool = False, quick: bool = False, out=None) -> int:
    record = run(out, quick)
    print(_json.dumps(record, indent=2) if json else
          "\n".join(f"{k}: {v}" for k, v in record.items()))
    return 0
