"""``mi-displace`` sub-commands of the volume technique.

* ``volume-animate SCENE.xml --param volume.map0_angle --start 0 --stop 80 --frames 12
  [-D k=v] [--spp N] --out DIR``: a progressing cut or peel (Figs. 1, 6) in one call:
  ``animate --edit PARAM=START:STOP --endpoint`` (the parameter stepped through
  ``mi.traverse``, the object textures not rebuilt; 1 spp unless ``--spp``).

The sweeps of docs/volume.md: ``mi-displace figures volume`` (:mod:`mi_displace.figures.volume`).
"""
from __future__ import annotations

from pathlib import Path


def _cmd_animate(args) -> int:
    from mi_displace.evaluate.cli import run_animation
    from mi_displace.evaluate.frames import parse_edit

    return run_animation(args, [parse_edit(f"{args.param}={args.start}:{args.stop}")],
                         endpoint=True, spp=1)


def add_commands(sub) -> dict:
    from mi_displace.evaluate.cli import animation_options

    p = sub.add_parser("volume-animate", help="render frames of a map parameter (progressing "
                                              "cut/peel; animate --endpoint)")
    p.add_argument("scene", type=Path, help="scene XML with a displaced_volume")
    p.add_argument("--param", required=True, help="mi.traverse key, e.g. volume.map0_angle")
    p.add_argument("--start", type=float, required=True, help="first value")
    p.add_argument("--stop", type=float, required=True, help="last value")
    animation_options(p, frames=12)
    return {"volume-animate": _cmd_animate}
