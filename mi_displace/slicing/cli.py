"""Slicing sub-commands of ``mi-displace``.

* ``slicing-capture SOURCE --out DIR [--resolution R] [--color R,G,B]``: the six
  orthographic colour + depth + normal images of a PLY/OBJ mesh (or ``cup``, the procedural
  cup of :func:`mi_displace.slicing.assets.cup_mesh`) on a cube around it, written as
  ``DIR/cube.json`` + EXR/PNG files for ``<shape type="depth_object">``.
* ``slicing-cup --out FILE.ply``: write the procedural cup mesh.
* ``slicing-memory MESH [--direction best|screen] [--slices N|auto] [--scale F]
  [--resolution R] [--max-memory-mb M]``: load ``<shape type="slicing">`` on the OBJ/PLY mesh under a
  camera that frames it and print what the build reported (per family slices, triangles,
  bytes, seconds; ``direction`` best by default) and how twisted its prisms are
  (:func:`memory_report`).

The measured figures of docs/slicing.md: ``mi-displace figures slicing``
(:mod:`mi_displace.figures.slicing`).
"""
from __future__ import annotations

import argparse
from pathlib import Path


def _color(text: str):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3 or not all(0 <= v <= 1 for v in values):
        raise argparse.ArgumentTypeError(f"expected R,G,B in [0, 1], got {text!r}")
    return values


def _cmd_capture(args) -> int:
    from mi_displace.slicing import assets, depth_object

    source = assets.source_shape(args.source, args.color)
    images = depth_object.capture(source, args.resolution)
    path = depth_object.write(images, args.out)
    hit = float((images.depth < float("inf")).mean())
    print(f"wrote {path}: six {args.resolution}x{args.resolution} images, cube centre "
          f"{images.center.round(4).tolist()}, half size {images.half:.4g}, {100 * hit:.1f}% pixels hit")
    return 0


def _cmd_cup(args) -> int:
    from mi_displace.slicing import assets

    mesh = assets.cup_mesh()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    mesh.export(args.out)
    print(f"wrote {args.out}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
          f"watertight={mesh.is_watertight}")
    return 0


def memory_report(mesh: str, slices, scale_fraction: float, resolution: int,
                  max_memory_mb: float = 512.0, direction: str = "best") -> dict:
    """Load ``direction`` slicing on ``mesh`` (OBJ / PLY path) under a 40° perspective
    camera of ``resolution``² pixels framing its bounding sphere from (0, 0.5, 1), with the
    maximum displacement ``scale_fraction`` x the bounding box diagonal and a bricks map.

    Returns:
        ``build_stats`` of the shape plus ``load_s`` (seconds of ``mi.load_dict``) and
        ``prisms`` (:func:`mi_displace.slicing.geometry.prism_shape`: how far from straight
        the mesh's prisms are, which screen-space slicing inverts by iteration).
    """
    import math
    import time

    import mitsuba as mi
    import numpy as np

    from mi_displace.slicing import geometry as geo

    box = mi.load_dict({"type": Path(mesh).suffix[1:].lower(), "filename": mesh}).bbox()
    lo, hi = np.array(box.min), np.array(box.max)
    centre, radius = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
    view = np.array([0.0, 0.5, 1.0]) / math.sqrt(1.25)
    cam = {"type": "perspective", "fov": 40.0,
           "to_world": mi.ScalarTransform4f().look_at(
               origin=(centre + view * 1.1 * radius / math.tan(math.radians(20))).tolist(),
               target=centre.tolist(), up=[0, 1, 0]),
           "film": {"type": "hdrfilm", "width": resolution, "height": resolution}}
    start = time.perf_counter()
    shape = mi.load_dict({"type": "slicing", "base": "mesh", "filename": mesh, "direction": direction,
                          "slices": slices, "scale": scale_fraction * 2 * radius,
                          "sensor": mi.load_dict(cam), "max_memory_mb": max_memory_mb,
                          "height": {"type": "bricks"}})
    load_s = time.perf_counter() - start
    return {**shape.build_stats, "load_s": load_s,
            "prisms": geo.prism_shape(shape.volume.bm, shape.volume.scale)}


def _cmd_memory(args) -> int:
    import json

    slices = args.slices if args.slices == "auto" else int(args.slices)
    report = memory_report(str(args.mesh), slices, args.scale, args.resolution, args.max_memory_mb,
                           args.direction)
    print(json.dumps(report, indent=1, default=float))
    return 0


def add_commands(sub) -> dict:
    p = sub.add_parser("slicing-capture", help="six orthographic colour+depth images of a mesh")
    p.add_argument("source", help="PLY/OBJ mesh, or 'cup' (the procedural cup)")
    p.add_argument("--out", type=Path, required=True, help="output folder (cube.json + images)")
    p.add_argument("--resolution", type=int, default=256, help="pixels per image edge (default 256)")
    p.add_argument("--color", type=_color, default=[0.7, 0.7, 0.7], help="diffuse albedo R,G,B")
    p = sub.add_parser("slicing-cup", help="write the procedural cup mesh")
    p.add_argument("--out", type=Path, required=True, help="output .ply")
    p = sub.add_parser("slicing-memory", help="size and build time of slicing on a mesh")
    p.add_argument("mesh", type=Path, help="OBJ/PLY mesh with texture coordinates")
    p.add_argument("--slices", default="auto", help="surface-aligned slices, or auto (default)")
    p.add_argument("--scale", type=float, default=0.005,
                   help="maximum displacement / bounding box diagonal (default 0.005)")
    p.add_argument("--resolution", type=int, default=1024, help="camera pixels per edge (default 1024)")
    p.add_argument("--max-memory-mb", type=float, default=512.0, help="the shape's max_memory_mb")
    p.add_argument("--direction", choices=("best", "screen"), default="best", help="slice direction")
    return {"slicing-capture": _cmd_capture, "slicing-cup": _cmd_cup, "slicing-memory": _cmd_memory}
