"""``mi-displace`` sub-commands of the DDM technique.

* ``ddm-animate SCENE.xml --shape ID [--frames N] [--duration T] [--spp N] [-D k=v] --out DIR``
  renders an animation (§4.2): ``animate --edit ID.time=0:T`` — ``ID.time`` stepped through
  ``mi.traverse`` over ``[0, T)`` (no rebuild), ``DIR/frame_NNNN.png`` and ``frames.json``.

The figures of docs/ddm.md: ``mi-displace figures ddm`` (:mod:`mi_displace.figures.ddm`).
"""
from __future__ import annotations

from pathlib import Path


def _cmd_animate(args) -> int:
    import math

    from mi_displace.evaluate.cli import run_animation

    if not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration: must be a positive number, got {args.duration!r}")
    return run_animation(args, [(f"{args.shape}.time", 0.0, args.duration)])


def add_commands(sub) -> dict:
    from mi_displace.evaluate.cli import animation_options

    p = sub.add_parser("ddm-animate", help="render a DDM animation (animate SHAPE.time=0:T)")
    p.add_argument("scene", type=Path, help="scene XML with a ddm shape")
    p.add_argument("--shape", required=True, help="id of the ddm shape")
    p.add_argument("--duration", type=float, default=1.0, help="time span of the frames (1.0)")
    animation_options(p)
    return {"ddm-animate": _cmd_animate}
