"""``mi-displace`` sub-commands of the DDM technique.

* ``ddm-animate SCENE.xml --shape ID [--frames N] [--duration T] [--spp N] [-D k=v] --out DIR``
  renders an animation (§4.2): ``animate --edit ID.time=0:T`` — ``ID.time`` stepped through
  ``mi.traverse`` over ``[0, T)`` (no rebuild), ``DIR/frame_NNNN.png`` and ``frames.json``.
* ``ddm-figures [--out DIR] [--quick]`` writes the accuracy table and plot (``maps`` at
  32...1024 against ``exact``), the normal-method table and the ``map_resolution`` sweep of
  ``scenes/ddm_thorns_sphere.xml`` (default ``docs/figures``); ``--charts``: only the
  UV-chart table (``maps`` against ``exact`` on two mesh bases, ``ddm_charts.md``).
"""
from __future__ import annotations

from pathlib import Path

from mi_displace.core.resources import FIGURES_DIR, scene_path


def _cmd_animate(args) -> int:
    import math

    from mi_displace.evaluate.cli import run_animation

    if not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration: must be a positive number, got {args.duration!r}")
    return run_animation(args, [(f"{args.shape}.time", 0.0, args.duration)])


def _cmd_figures(args) -> int:
    from mi_displace.ddm.accuracy import chart_accuracy, write_figures

    if args.charts:
        chart_accuracy(args.out)
        print((args.out / "ddm_charts.md").read_text())
        return 0
    record = write_figures(args.out, scene_path("ddm_thorns_sphere.xml"), quick=args.quick)
    for row in record["accuracy"]:
        print(f"R={row['resolution']:5d}  rms/diag {row['rms_error_rel']:.3g}  "
              f"max/diag {row['max_error_rel']:.3g}  normal mean {row['normal_mean_deg']:.3g} deg")
    print(f"wrote {args.out}/ddm_accuracy.png, ddm_sweep.png, ddm_figures.json, ddm_figures.md")
    return 0


def add_commands(sub) -> dict:
    from mi_displace.evaluate.cli import animation_options

    p = sub.add_parser("ddm-animate", help="render a DDM animation (animate SHAPE.time=0:T)")
    p.add_argument("scene", type=Path, help="scene XML with a ddm shape")
    p.add_argument("--shape", required=True, help="id of the ddm shape")
    p.add_argument("--duration", type=float, default=1.0, help="time span of the frames (1.0)")
    animation_options(p)

    p = sub.add_parser("ddm-figures", help="DDM accuracy table/plot and map_resolution sweep")
    p.add_argument("--out", type=Path, default=FIGURES_DIR, help="output folder")
    p.add_argument("--quick", action="store_true", help="fewer resolutions, low-spp reference")
    p.add_argument("--charts", action="store_true",
                   help="only the UV-chart table (maps vs exact on Spot and the genus-1 mesh)")
    return {"ddm-animate": _cmd_animate, "ddm-figures": _cmd_figures}
