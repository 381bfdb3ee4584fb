"""``mi-displace`` sub-commands of the volume technique.

* ``volume-animate SCENE.xml --param volume.map0_angle --start 0 --stop 80 --frames 12
  [-D k=v] [--spp N] --out DIR``: a progressing cut or peel (Figs. 1, 6) in one call; the
  parameter is stepped through ``mi.traverse`` (the object textures are not rebuilt).
* ``volume-figures [--out DIR] [--quick]``: the sweeps of docs/volume.md
  (:mod:`mi_displace.volume.figures`).
"""
from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _cmd_animate(args) -> int:
    from mi_displace.render.scene import load
    from mi_displace.volume.animation import frame_values, render_frames

    scene, timings = load(args.scene, **dict(args.defines))
    records = render_frames(scene, args.param, frame_values(args.start, args.stop, args.frames),
                            args.out, spp=args.spp)
    (args.out / "frames.json").write_text(json.dumps(records, indent=2))
    mean_update = sum(r["update_s"] for r in records) / len(records)
    print(f"wrote {len(records)} frames to {args.out} (scene build {timings['build_s']:.3f} s, "
          f"mean parameter update {mean_update:.3f} s)")
    return 0


def _cmd_figures(args) -> int:
    from mi_displace.volume.figures import write_figures

    record = write_figures(args.out, quick=args.quick)
    print(f"wrote {args.out}/volume_figures.json and volume_figures.md ({len(record)} tables)")
    return 0


def add_commands(sub) -> dict:
    from mi_displace.cli import _define, _positive_int

    p = sub.add_parser("volume-animate", help="render frames of a map parameter (progressing cut/peel)")
    p.add_argument("scene", type=Path, help="scene XML with a displaced_volume")
    p.add_argument("--param", required=True, help="mi.traverse key, e.g. volume.map0_angle")
    p.add_argument("--start", type=float, required=True, help="first value")
    p.add_argument("--stop", type=float, required=True, help="last value")
    p.add_argument("--frames", type=_positive_int, default=12, help="number of frames (12)")
    p.add_argument("--spp", type=_positive_int, default=None, help="samples per pixel (volpath)")
    p.add_argument("-D", dest="defines", action="append", type=_define, default=[],
                   metavar="NAME=VALUE", help="scene parameter")
    p.add_argument("--out", type=Path, required=True, help="output folder")

    p = sub.add_parser("volume-figures", help="volume trade-off sweeps (docs/volume.md)")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "figures", help="output folder")
    p.add_argument("--quick", action="store_true", help="small images and references")
    return {"volume-animate": _cmd_animate, "volume-figures": _cmd_figures}
