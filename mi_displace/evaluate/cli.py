"""``mi-displace`` sub-commands of the trade-off measurements.

* ``tradeoff SCENE.xml --knob NAME=V1,V2 [--knob ...] [-D k=v] --out DIR`` sweeps the knobs
  (:mod:`mi_displace.evaluate.tradeoff`): ``DIR/tradeoff.csv``, ``.json``, ``.png``.
* ``tune SCENE.xml --flip F [--knob ...] --out DIR``: the cheapest measured setting within
  FLIP ``F``, verified by a fresh render, printed as ``-D`` values (``DIR/tune.json``).
* ``atlas --out DIR [--scenes DIR]``: every showcase scene's declared sweep on one HTML page
  (:mod:`mi_displace.evaluate.atlas`).
* ``animate SCENE.xml --edit ID.PARAM=A:B [--edit ...] --frames N [--endpoint] --out DIR``:
  frames of ``mi.traverse`` edits (:mod:`mi_displace.evaluate.frames`), chunks of frames as
  jobs; ``ddm-animate`` and ``volume-animate`` are aliases (:func:`run_animation`).

All four take ``--cluster ADDRESS`` (a Dask scheduler, or ``local:N`` for N local worker
processes); the sweeps also ``--max-spp``, ``--noise-floor FLIP`` (the reference's target)
and ``--cache DIR`` (finished points, keyed by code version).
"""
from __future__ import annotations

from pathlib import Path


def _sweep_options(p) -> None:
    from mi_displace.core.cli_args import DEFAULT_MAX_SPP, positive_int

    p.add_argument("--max-spp", type=positive_int, default=DEFAULT_MAX_SPP,
                   help=f"most reference samples per pixel (default {DEFAULT_MAX_SPP})")
    p.add_argument("--noise-floor", type=float, default=None, metavar="FLIP",
                   help="reference noise-floor target: its spp doubles until the two-seed floor "
                        "is below FLIP (or a fifth of the smallest error), capped at --max-spp")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="run the points on a Dask cluster: tcp://HOST:PORT, or local:N")
    p.add_argument("--cache", type=Path, default=None, metavar="DIR",
                   help="point cache (default $MI_DISPLACE_CACHE/tradeoff or ~/.cache/mi_displace/tradeoff)")


def _knobs(p) -> None:
    p.add_argument("--knob", dest="knobs", action="append", default=[], metavar="NAME=V1,V2,...",
                   help="parameter to sweep: a scene default (-D name) or ID.PARAM (mi.traverse); "
                        "repeatable (the product is swept); default: the scene's "
                        "<!-- tradeoff: ... --> declarations")


def _parsed_knobs(args):
    from mi_displace.evaluate.tradeoff import declared_knobs, parse_knob

    return [parse_knob(k) for k in args.knobs] or declared_knobs(args.scene)


def _cmd_tradeoff(args) -> int:
    from mi_displace.evaluate.tradeoff import tradeoff

    r = tradeoff(args.scene, _parsed_knobs(args), out_dir=args.out, params=dict(args.defines),
                 max_spp=args.max_spp, cluster=args.cluster, cache_dir=args.cache, progress=None,
                 noise_floor=args.noise_floor)
    print(f"reference {r['reference_spp']} spp{' (capped)' if r['spp_capped'] else ''}, "
          f"noise floor FLIP {r['noise_floor_flip']:.4f}")
    for p in r["points"]:
        if not p["ok"]:
            print(f"  {p['label']}: skipped ({p['error']})")
            continue
        cross = (f"path needs {p['path_crossover_s']:.3g} s" if p["path_crossover_s"] is not None
                 else "path does not reach it within the curve")
        print(f"  {p['label']}: FLIP {p['flip']:.4f}, {p['time_warm_s']:.3g} s warm"
              f"{' (Pareto)' if p['pareto'] else ''}; {cross}")
    print(f"wrote {args.out}/tradeoff.csv, tradeoff.json, tradeoff.png")
    return 0


def _cmd_tune(args) -> int:
    from mi_displace.evaluate.tradeoff import tune

    r = tune(args.scene, args.flip, _parsed_knobs(args), out_dir=args.out,
             params=dict(args.defines), max_spp=args.max_spp, cluster=args.cluster,
             cache_dir=args.cache, progress=None, noise_floor=args.noise_floor)
    if r["chosen"] is None:
        print(f"no measured setting meets FLIP {args.flip} (reference noise floor "
              f"{r['noise_floor_flip']:.4f}); see {args.out}/tradeoff.csv")
        return 1
    print(" ".join(r["defines"]))
    print(f"FLIP {r['verified_flip']:.4f} re-rendered from scratch "
          f"({'meets' if r['meets_budget'] else 'MISSES'} the budget {args.flip}), "
          f"{r['verified_time_s']:.3g} s warm; the scene's defaults: FLIP "
          f"{r['default_flip']:.4f}, {r['default_time_s']:.3g} s ({r['speedup_vs_default']:.3g}x)")
    return 0 if r["meets_budget"] else 1


def _cmd_atlas(args) -> int:
    from mi_displace.evaluate.atlas import atlas

    r = atlas(args.out, scenes_dir=args.scenes, max_spp=args.max_spp, cluster=args.cluster,
              cache_dir=args.cache, progress=None, noise_floor=args.noise_floor)
    for name, message in r["failures"].items():
        print(f"  {name}: failed ({message})")
    print(f"wrote {args.out}/index.html ({len(r['scenes'])} scenes)")
    return 1 if r["failures"] else 0


def run_animation(args, edits: list, endpoint: bool = False, spp: int | None = None) -> int:
    """``animate`` with the options of :func:`animation_options` and the given edits: the
    body of ``animate`` and of its aliases (``ddm-animate``, ``volume-animate``)."""
    from mi_displace.evaluate.frames import animate

    r = animate(args.scene, edits, args.frames, args.out, params=dict(args.defines),
                spp=args.spp or spp, chunk=args.chunk, cluster=args.cluster, progress=None,
                endpoint=endpoint)
    for job, message in r["failed"].items():
        print(f"  chunk {job}: failed ({message})")
    written = [p for p in r["frames"] if p is not None]
    times = [t for t in r["render_s"] if t is not None]
    if times:
        print(f"wrote {len(written)} frames to {args.out} "
              f"(median render {sorted(times)[len(times) // 2]:.3g} s per frame, "
              f"frames.json)")
    return 1 if r["failed"] else 0


def _cmd_animate(args) -> int:
    from mi_displace.evaluate.frames import parse_edit

    return run_animation(args, [parse_edit(e) for e in args.edits], endpoint=args.endpoint)


def animation_options(p, frames: int = 24) -> None:
    """The options every frame command shares: ``--frames --spp --chunk --cluster -D --out``."""
    from mi_displace.core.cli_args import define, positive_int

    p.add_argument("--frames", type=positive_int, default=frames,
                   help=f"number of frames ({frames})")
    p.add_argument("--spp", type=positive_int, default=None, help="samples per pixel")
    p.add_argument("--chunk", type=positive_int, default=8, help="frames per job (8)")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="render the chunks on a Dask cluster: tcp://HOST:PORT, or local:N")
    p.add_argument("-D", dest="defines", action="append", type=define, default=[],
                   metavar="NAME=VALUE", help="scene parameter; repeatable")
    p.add_argument("--out", type=Path, required=True, help="output folder")


def add_commands(sub) -> dict:
    from mi_displace.core.cli_args import define

    def defines(p):
        p.add_argument("-D", dest="defines", action="append", type=define, default=[],
                       metavar="NAME=VALUE", help="fixed scene parameter; repeatable")

    p = sub.add_parser("tradeoff", help="sweep quality knobs: error against time")
    p.add_argument("scene", type=Path, help="scene XML following the comparison convention")
    _knobs(p)
    defines(p)
    _sweep_options(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")

    p = sub.add_parser("tune", help="the cheapest measured setting within a FLIP budget")
    p.add_argument("scene", type=Path, help="scene XML following the comparison convention")
    p.add_argument("--flip", type=float, required=True, help="error budget (mean FLIP)")
    _knobs(p)
    defines(p)
    _sweep_options(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")

    p = sub.add_parser("atlas", help="every showcase scene's sweep on one HTML page")
    p.add_argument("--scenes", type=Path, default=None, help="scene folder (default: the repo's)")
    _sweep_options(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")

    p = sub.add_parser("animate", help="render frames of mi.traverse edits (chunks as jobs)")
    p.add_argument("scene", type=Path, help="scene XML")
    p.add_argument("--edit", dest="edits", action="append", default=[], required=True,
                   metavar="ID.PARAM=START:STOP", help="parameter stepped over the frames")
    p.add_argument("--endpoint", action="store_true",
                   help="the last frame at STOP (default: STOP excluded, for loops)")
    animation_options(p)
    return {"tradeoff": _cmd_tradeoff, "tune": _cmd_tune, "atlas": _cmd_atlas,
            "animate": _cmd_animate}
