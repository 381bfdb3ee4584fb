"""Sub-command ``recover`` of ``mi-displace`` (issue 14, inverse displacement).

``recover --out DIR [--iterations N] [--map-size M] [--image-size S] [--views V]
[--lights L] [--spp K] [--integrator prb_projective|direct_projective] [--learning-rate R]``
recovers the Bricks102 height map (box-downsampled to M^2) from V x L renders of a
``displaced`` plane, starting flat, and writes ``DIR/recovery.json`` (settings, summary,
per-iteration loss / height RMS / seconds), ``DIR/recovery_curves.png`` (loss and RMS against
iterations) and ``DIR/recovery_maps.png`` (start, result, truth, error).

``recover-bunny --out DIR [--iterations N] [--learning-rate R]``: the same on the bunny
(:mod:`mi_displace.inverse.bunny`): the map of its low-poly recovered from renders of the
scan, against the baked map, with the restoration error of each in ``recovery.json``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def add_commands(sub) -> dict:
    """Add ``recover`` to ``sub``; returns {command: handler}."""
    from mi_displace.core.cli_args import positive_int
    p = sub.add_parser("recover", help="recover a height map from renders (inverse displacement)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--iterations", type=positive_int, default=40, help="Adam steps (default 40)")
    p.add_argument("--map-size", type=positive_int, default=64, help="height map texels per side (default 64)")
    p.add_argument("--image-size", type=positive_int, default=64, help="render pixels per side (default 64)")
    p.add_argument("--views", type=positive_int, default=3, help="cameras (default 3)")
    p.add_argument("--lights", type=int, choices=(1, 2), default=2, help="directional lights (default 2)")
    p.add_argument("--spp", type=positive_int, default=8, help="samples per pixel per render (default 8)")
    p.add_argument("--integrator", choices=("prb_projective", "direct_projective"),
                   default="prb_projective", help="differentiable integrator (default prb_projective)")
    p.add_argument("--learning-rate", type=_positive_float, default=0.05, help="Adam step (default 0.05)")
    p = sub.add_parser("recover-bunny", help="recover the bunny's map from renders of the scan "
                       "and compare it with the baked map (inverse displacement on a mesh)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--iterations", type=positive_int, default=30, help="Adam steps (default 30)")
    p.add_argument("--learning-rate", type=_positive_float, default=0.002, help="Adam step (default 0.002)")
    return {"recover": _recover, "recover-bunny": _recover_bunny}


def _recover(args) -> int:
    from mi_displace.figures.inverse import write
    from mi_displace.inverse import recover

    truth = recover.load_height_map(size=args.map_size)
    rec = recover.recover(truth, iterations=args.iterations, views=args.views,
                          lights=args.lights, image_size=args.image_size, spp=args.spp,
                          integrator=args.integrator, learning_rate=args.learning_rate, log=print)
    write(rec, Path(args.out))
    print(json.dumps(rec.summary(), indent=2))
    return 0


def _recover_bunny(args) -> int:
    from mi_displace.figures.inverse import BUNNY_LABELS, write
    from mi_displace.inverse import bunny

    rec = bunny.recover_bunny(iterations=args.iterations, learning_rate=args.learning_rate,
                              log=print)
    write(rec, Path(args.out), **BUNNY_LABELS)
    print(json.dumps(rec.summary(), indent=2))
    return 0
