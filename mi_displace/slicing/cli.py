"""Slicing sub-commands of ``mi-displace``.

* ``slicing-capture SOURCE --out DIR [--resolution R] [--color R,G,B]``: the six
  orthographic colour + depth + normal images of a PLY/OBJ mesh (or ``cup``, the procedural
  cup of :func:`mi_displace.slicing.assets.cup_mesh`) on a cube around it, written as
  ``DIR/cube.json`` + EXR/PNG files for ``<shape type="depth_object">``.
* ``slicing-cup --out FILE.ply``: write the procedural cup mesh.

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


def add_commands(sub) -> dict:
    p = sub.add_parser("slicing-capture", help="six orthographic colour+depth images of a mesh")
    p.add_argument("source", help="PLY/OBJ mesh, or 'cup' (the procedural cup)")
    p.add_argument("--out", type=Path, required=True, help="output folder (cube.json + images)")
    p.add_argument("--resolution", type=int, default=256, help="pixels per image edge (default 256)")
    p.add_argument("--color", type=_color, default=[0.7, 0.7, 0.7], help="diffuse albedo R,G,B")
    p = sub.add_parser("slicing-cup", help="write the procedural cup mesh")
    p.add_argument("--out", type=Path, required=True, help="output .ply")
    return {"slicing-capture": _cmd_capture, "slicing-cup": _cmd_cup}
