"""`mi-displace bench ddm`: HDDM mapping speed, accuracy, memory and the paper's Table 1.

* ``map_time_warm_s``: mapping >= 3M tile vertices *with their normals* (thorns on a
  sphere, ``maps`` at 256, the paper's ``tangent`` normals: 3 mapped points per vertex),
  warm median, beside the same mapping in ``exact`` mode (``exact_map_time_warm_s``) and
  the other normal methods, in the same process; target 0.25 s.
* ``rms_error_rel`` / ``max_error_rel``: ``maps`` at 256 against ``exact`` on the
  thorns-on-sphere scene (vertex distance / bounding-box diagonal).
* ``maps_bytes`` (two 256² RGB float32 maps + validity), ``hddm_bytes`` (tile + offsets +
  maps), ``mesh_bytes`` (the explicit mapped mesh) for that scene.
* ``table1``: the paper's Table 1 scenes re-created with our assets (sphere for the human
  face, Spot for the camel and the horse, the Stanford bunny for the Buddha statue), with
  tile polygons, tiles after pruning, vertices, our build / map / render (raster 256²)
  times and the paper's frame rates on an Nvidia 6800 / 6600.

``--quick`` runs the same with :data:`QUICK` sizes (every tile count divided by 8, maps at
most 64², renders at 64²); the field names keep the full run's sizes.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bench._timing import median_time, print_record
from mi_displace.core.resources import data_path
from mi_displace.ddm import accuracy
from mi_displace.ddm.animation import Animation
from mi_displace.ddm.model import DDMConfig, DDMModel

SPOT = str(data_path("spot", "spot_triangulated.obj"))
BUNNY = str(data_path("bunny", "bun_zipper_res3.ply"))


class Sizes(NamedTuple):
    """What a run builds: every tile count divided by ``tile_divisor`` (1: the speed test's
    148 x 128 thorns = 3.07M vertices, the paper's Table 1 counts), maps of at most
    ``map_resolution``², renders at ``render_res``² pixels."""
    tile_divisor: int
    map_resolution: int
    render_res: int

    def scaled(self, kw: dict) -> dict:
        """DDM parameters ``kw`` with their tile counts and map resolution cut to these sizes."""
        out = {**kw, "tiles_u": max(1, kw["tiles_u"] // self.tile_divisor),
               "tiles_v": max(1, kw["tiles_v"] // self.tile_divisor)}
        if "map_resolution" in kw:
            out["map_resolution"] = min(kw["map_resolution"], self.map_resolution)
        return out


FULL = Sizes(1, 256, 256)
QUICK = Sizes(8, 64, 64)
SPEED_TILES = {"tiles_u": 148, "tiles_v": 128}     # 18944 thorns x 162 vertices = 3.07M vertices


def _map_timer(model: DDMModel, method: str):
    def run():
        p, n, uv = model.map(method=method)
        dr.eval(p, n, uv)
    return run


def statue_tile_file(out_dir: Path) -> str:
    """The bunny scaled into canonical tile coordinates (x, y in [0, 1], z up), as OBJ."""
    import trimesh

    mesh = trimesh.load(BUNNY, force="mesh", process=False)
    v = np.asarray(mesh.vertices)[:, [0, 2, 1]]          # y-up scan -> z up
    v = (v - v.min(0)) / (v.max(0) - v.min(0))[[0, 1]].max()
    path = out_dir / "ddm_statue_tile.obj"
    trimesh.Trimesh(v, np.asarray(mesh.faces)[:, [0, 2, 1]], process=False).export(path)
    return str(path)


def table1(tmp: Path, sizes: Sizes = FULL) -> list[dict]:
    """Re-create the paper's Table 1 rows; times are ours (2-core CPU)."""
    statue = statue_tile_file(tmp)
    rows = [
        ("Human Face (6)", "Thorn", 224, 640, 430080, 8.5, 8.1,
         dict(base="sphere", tile="thorn", tiles_u=32, tiles_v=20, height=0.25, map_resolution=256)),
        ("Teapot (7)", "Buddha", 41868, 6, 753624, 7.5, 6.9,
         dict(base="teapot", tile=statue, tiles_u=6, tiles_v=1, height=1.0, map_resolution=256)),
        ("Teapot (8)", "Thorn -> Flower", 224, 480, 322560, 12, 10,
         dict(base="teapot", tile="thorn", tile_target="flower", tiles_u=32, tiles_v=15,
              height=0.25, map_resolution=128, time=0.5,
              animation=Animation(alpha_rate=1.0))),
        ("Camel (9)", "Chains", 544, 1789, 2919648, 2, 1.3,
         dict(base="mesh", filename=SPOT, tile="chain", tiles_u=70, tiles_v=70, height=0.03,
              map_resolution=256)),
        ("Horse (10)", "Hair", 384, 2802, 3227904, 1.1, 1.0,
         dict(base="mesh", filename=SPOT, tile="hair", tiles_u=80, tiles_v=80, height=0.05,
              map_resolution=128)),
        ("Human Face (11)", "Hexagonal", 804, 400, 964800, 4, 4,
         dict(base="sphere", tile="hexagon", layout="hex", tiles_u=20, tiles_v=20, height=0.05,
              map_resolution=128)),
    ]
    out = []
    for scene, tile, polys, tiles, verts, fps68, fps66, kw in rows:
        import warnings

        kw = sizes.scaled(kw)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = time.perf_counter()
            model = DDMModel(DDMConfig(mode="maps", **kw))
            dr.sync_thread()
            build = time.perf_counter() - start
        map_s = median_time(_map_timer(model, "naive"), 3)
        load_s, render_s = _render_time(kw, sizes.render_res)
        out.append({
            "scene": scene, "paper_tile": tile, "paper_polygons_per_tile": polys,
            "paper_tiles": tiles, "paper_vertices": verts, "paper_fps_6800": fps68,
            "paper_fps_6600": fps66, "ours_polygons_per_tile": int(model.tiles[0].face_count),
            "ours_tiles": model.layout.count, "ours_tiles_pruned": model.pruned,
            "ours_vertices": model.vertex_count,
            "ours_vertices_paper_count": 3 * model.face_count,   # the paper counts 3 per polygon
            "build_s": build, "scene_load_s": load_s, "map_naive_warm_s": map_s,
            "render_raster_256_s": render_s,
            "ours_fps_map_only": 1 / map_s})
    return out


def _render_time(kw: dict, res: int) -> tuple[float, float]:
    """(scene load incl. the plugin and Mitsuba's acceleration build, warm median of one
    raster render at ``res`` x ``res``, aa = 1) of the shape."""
    shape = {"type": "ddm", **{k: v for k, v in kw.items() if k != "animation"}}
    if "animation" in kw:
        shape["alpha_rate"] = kw["animation"].alpha_rate
    start = time.perf_counter()
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "raster"},
        "sensor": {"type": "perspective", "fov": 35, "to_world": mi.ScalarTransform4f().look_at(
            origin=[0, -6, 3], target=[0, 0, 0.5], up=[0, 0, 1]),
            "film": {"type": "hdrfilm", "width": res, "height": res}},
        "light": {"type": "point", "position": [3, -3, 4], "intensity": {"type": "rgb", "value": 30}},
        "shape": shape})
    dr.sync_thread()
    load_s = time.perf_counter() - start

    def run():
        img = np.asarray(mi.render(scene))
        if not np.all(np.isfinite(img)) or img.max() <= 0:
            raise RuntimeError(f"bench ddm: raster image of {kw} is not finite or black")
    return load_s, median_time(run, 3)


def run(sizes: Sizes = FULL) -> dict:
    import tempfile
    import warnings

    # speed: >= 3M vertices with normals
    speed_kw = sizes.scaled({**accuracy.THORNS_SPHERE, **SPEED_TILES, "map_resolution": 256})
    models = {mode: DDMModel(DDMConfig(**speed_kw, mode=mode)) for mode in ("maps", "exact")}
    speed = {f"{mode}_{method}": median_time(_map_timer(models[mode], method))
             for mode in ("maps", "exact") for method in ("tangent", "jacobian", "naive")}
    vertices = models["maps"].vertex_count
    del models
    # accuracy and memory of the thorns-on-sphere scene
    thorns = sizes.scaled({**accuracy.THORNS_SPHERE, "map_resolution": 256})
    maps_res = thorns.pop("map_resolution")
    acc = accuracy.geometric_accuracy(DDMConfig(**thorns), (maps_res,))[0]
    scene_model = DDMModel(DDMConfig(**thorns, mode="maps", map_resolution=maps_res))
    mem = scene_model.memory_report()
    methods = accuracy.normal_methods(DDMConfig(**thorns))
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = table1(Path(tmp), sizes)
    return {
        "variant": mi.variant(),
        "vertices": vertices,
        "map_time_warm_s": speed["maps_tangent"],
        "map_time_warm_by_method_s": speed,
        "maps_vs_exact": speed["maps_tangent"] / speed["exact_tangent"],
        "mvertices_per_s": vertices / speed["maps_tangent"] / 1e6,
        "paper_mvertices_per_s": {"camel_6800": 2919648 * 2 / 1e6, "horse_6800": 3227904 * 1.1 / 1e6},
        "rms_error_rel": acc["rms_error_rel"],
        "max_error_rel": acc["max_error_rel"],
        "normal_mean_deg": acc["normal_mean_deg"],
        "normal_methods_vs_jacobian_deg": methods,
        "scene_vertices": scene_model.vertex_count,
        "maps_bytes": mem["maps_bytes"],
        "tile_bytes": mem["tile_bytes"],
        "hddm_bytes": mem["hddm_bytes"],
        "mesh_bytes": mem["mesh_bytes"],
        "mesh_over_hddm": mem["mesh_over_hddm"],
        "table1": rows,
        "targets": {"map_time_warm_s": 0.25, "vertices": 3_000_000},
    }


def main(json: bool = False, quick: bool = False) -> int:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and print its record; 1 when
    the full run maps fewer than 3M vertices or its time is not finite."""
    record = run(QUICK if quick else FULL)
    print_record(record, json)
    ok = (quick or record["vertices"] >= 3_000_000) and np.isfinite(record["map_time_warm_s"])
    return 0 if ok else 1
