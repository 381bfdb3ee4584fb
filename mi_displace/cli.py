"""Command line interface: ``mi-displace [--variant V] [--quiet] {render,compare,showcase,bench} ...``.

* ``render SCENE.xml [-D name=value ...] [--spp N] [--seed S] --out IMG.(exr|png) [--explain]``
  (``--explain`` prints every shape's and BSDF's ``build_stats``; alone it only loads)
* ``compare SCENE.xml --out DIR [-D name=value ...] [--quick] [--max-spp N] [--target-ratio R]``
  runs the comparison protocol (:mod:`mi_displace.evaluate.compare`); ``--quick`` caps the
  reference at :data:`QUICK_MAX_SPP` samples per pixel, as for ``showcase``.
* ``showcase --out DIR [--quick] [--scenes DIR] [--max-spp N]`` compares every scene marked
  ``<!-- showcase -->`` under the packaged scene folder (or ``--scenes``), writes
  ``DIR/<scene>/...`` and ``DIR/summary.md`` and prints the summary table.  ``--quick``
  caps the reference at :data:`QUICK_MAX_SPP` samples per pixel.
* ``bench NAME [--json] [--quick] [--out DIR]`` runs ``mi_displace.bench.NAME.main(json=...,
  quick=..., out=...)`` (JSON or plain-text report on stdout; ``--quick``: small sizes, the
  same code paths, seconds instead of minutes, for checking that a benchmark runs).
* ``figures TECHNIQUE [--out DIR] [--quick] [options]`` re-makes the documentation's figures
  of a technique (:mod:`mi_displace.figures`, lab code; default ``--out docs/figures``);
  ``figures --list`` prints the techniques.
* technique commands: every module in :data:`COMMAND_MODULES` defines
  ``add_commands(sub) -> dict[str, Callable[[argparse.Namespace], int]]``, which adds its
  sub-parsers to ``sub`` and returns the handler of each command name it added.

Long work reports a line per stage with its time on stderr when stderr is a terminal
(:mod:`mi_displace.core.progress`); ``--quiet`` silences it, ``MI_DISPLACE_PROGRESS=1``
forces it into logs.

Bad input (missing file, bad parameter, unknown name, a variant this machine lacks, an option
whose extra is not installed) prints one line to stderr and exits with status 2, like
argparse's own usage errors; a missing or too old LLVM exits with 1.  Any other exception is a bug in mi_displace: its traceback is
printed with a line asking to report it (:data:`BUG_HINT`), exit status 1.
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import pkgutil
import sys
import traceback
from pathlib import Path

from mi_displace.core import progress
from mi_displace.core.cli_args import (DEFAULT_MAX_SPP, QUICK_MAX_SPP, UsageError, define,
                                       denoise_option, positive_int, seed, showcase_scenes)
from mi_displace.core.progress import stage

SUMMARY_COLUMNS = (
    ("scene", "scene"), ("FLIP", "flip_mean"), ("noise floor", "noise_floor_flip"),
    ("relMSE", "relmse"), ("PSNR (dB)", "psnr"), ("reference spp", "reference_spp"),
    ("reference time (s)", "reference_time_s"), ("approx. warm time (s)", "approx_time_warm_s"),
    ("speed-up", "speedup"),
)


# Modules contributing sub-commands (see the module docstring).
COMMAND_MODULES = [
    "mi_displace.ddm.cli",
    "mi_displace.bake.cli",
    "mi_displace.evaluate.cli",
    "mi_displace.slicing.cli",
    "mi_displace.volume.cli",
    "mi_displace.inverse.cli",
]


BUG_HINT = ("mi-displace: internal error (a bug in mi_displace, not in your input): please "
            "report it with the command line and the traceback above")


def default_scenes_dir() -> Path:
    """The packaged scene folder (:func:`mi_displace.core.resources.scenes_dir`)."""
    from mi_displace.core.resources import scenes_dir

    return scenes_dir()


def _version() -> str:
    from mi_displace import __version__

    return __version__


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``mi-displace``."""
    parser = argparse.ArgumentParser(
        prog="mi-displace", description="Displacement mapping for Mitsuba 3: render, compare, benchmark.")
    parser.add_argument("--variant", help="Mitsuba variant (default: $MI_DISPLACE_VARIANT or llvm_ad_rgb)")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress lines (default: shown when stderr is a terminal)")
    parser.add_argument("--version", action="version", version=f"mi-displace {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    def quick_and_max_spp(p):
        p.add_argument("--quick", action="store_true", help=f"cap references at {QUICK_MAX_SPP} spp")
        p.add_argument("--max-spp", type=positive_int, default=None,
                       help=f"most reference spp (default {DEFAULT_MAX_SPP}, {QUICK_MAX_SPP} with --quick)")

    def defines(p):
        p.add_argument("-D", dest="defines", metavar="NAME=VALUE", action="append", type=define,
                       default=[], help="scene parameter ($NAME in the XML); repeatable")

    p = sub.add_parser("render", help="render a scene to an image")
    p.add_argument("scene", type=Path, help="scene XML file")
    defines(p)
    p.add_argument("--spp", type=positive_int, help="samples per pixel (default: the scene's)")
    p.add_argument("--seed", type=seed, default=0, help="sampler seed (default 0)")
    p.add_argument("--bits", type=int, choices=(8, 16), default=8, help="bits per channel of a PNG")
    p.add_argument("--out", type=Path, help="output image, .exr (linear) or .png (sRGB)")
    p.add_argument("--explain", action="store_true",
                   help="print what each plugin built and why (its build_stats), per shape/BSDF; "
                        "without --out, only load and explain")

    p = sub.add_parser("compare", help="compare a scene's approximation with its reference")
    p.add_argument("scene", type=Path, help="scene XML file following the comparison convention")
    defines(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")
    quick_and_max_spp(p)
    p.add_argument("--target-ratio", type=float, default=0.2,
                   help="required noise floor / FLIP ratio (default 0.2)")
    denoise_option(p)

    p = sub.add_parser("showcase", help="compare every scene marked <!-- showcase -->")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--scenes", type=Path, default=None,
                   help=f"scene folder (default {default_scenes_dir()})")
    quick_and_max_spp(p)
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="compare the scenes as jobs on a Dask cluster (tcp://HOST:PORT, or local:N)")

    p = sub.add_parser("bench", help="run a benchmark module mi_displace.bench.NAME")
    p.add_argument("name", help="benchmark name")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--quick", action="store_true",
                   help="small sizes, same code paths (checks that it runs; numbers not comparable)")
    p.add_argument("--out", default=None,
                   help="folder for the benchmark's figures (benchmarks that write files; "
                        "default: a folder in the system's temporary directory)")

    figures_parser(sub)
    for name in COMMAND_MODULES:
        for command, handler in importlib.import_module(name).add_commands(sub).items():
            sub.choices[command].set_defaults(handler=handler)
    return parser


def figures_parser(sub) -> None:
    """``figures TECHNIQUE``: one sub-parser per technique of :data:`mi_displace.figures.TECHNIQUES`,
    with the common ``--out`` / ``--quick`` and the technique's own options."""
    from mi_displace import figures
    from mi_displace.core.resources import FIGURES_DIR

    p = sub.add_parser("figures", help="re-make a technique's documentation figures "
                                       "(figures --list: the techniques)")
    p.add_argument("--list", action="store_true", help="print the techniques and exit")
    techniques = p.add_subparsers(dest="technique", metavar="TECHNIQUE")
    for name, description in figures.TECHNIQUES.items():
        q = techniques.add_parser(name, help=description, description=description)
        q.add_argument("--out", type=Path, default=FIGURES_DIR,
                       help=f"output folder (default {FIGURES_DIR})")
        q.add_argument("--quick", action="store_true",
                       help="the same code at tiny sizes (checks that it runs; numbers not comparable)")
        figures.module(name).add_options(q)


def _cmd_figures(args) -> int:
    from mi_displace import figures

    if args.list:
        width = max(map(len, figures.TECHNIQUES))
        print("\n".join(f"{name:{width}}  {text}" for name, text in figures.TECHNIQUES.items()))
        return 0
    if args.technique is None:
        raise UsageError(f"figures: name a technique ({', '.join(figures.TECHNIQUES)}), "
                         "or --list")
    return figures.module(args.technique).run(args)


def _fmt(value, digits: int = 4) -> str:
    """A number for a table cell."""
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def summary_table(rows: list[dict]) -> str:
    """Markdown table of comparison results (one row per scene, ``error`` rows allowed)."""
    lines = ["| " + " | ".join(title for title, _ in SUMMARY_COLUMNS) + " |",
             "|" + "|".join("---" for _ in SUMMARY_COLUMNS) + "|"]
    for row in rows:
        if "error" in row:
            cells = [row["scene"], f"failed: {row['error']}"] + [""] * (len(SUMMARY_COLUMNS) - 2)
        else:
            cells = [row["scene"]] + [_fmt(row[key]) for _, key in SUMMARY_COLUMNS[1:]]
            if row.get("spp_capped"):
                cells[5] += " (capped)"
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _cmd_render(args) -> int:
    from mi_displace.core.io import image_format, write_image
    from mi_displace.evaluate.metrics import assert_finite
    from mi_displace.render.scene import explain, load, render

    if args.out is None and not args.explain:
        raise UsageError("render: --out is required (or --explain alone to load and explain)")
    if args.out is not None:
        image_format(args.out, "--out")
    with stage(f"loading {args.scene}"):
        scene, timings = load(args.scene, **dict(args.defines))
    if args.explain:
        print(explain_text(explain(scene), timings["build_s"]))
    if args.out is None:
        return 0
    with stage(f"rendering {args.scene.name}"):
        image, seconds = render(scene, spp=args.spp, seed=args.seed, progress=None)
    assert_finite(image, f"rendered image of {args.scene}")
    write_image(args.out, image, bits=args.bits)
    spp = args.spp or timings["spp"]
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]}, {spp} spp): "
          f"build {timings['build_s']:.3f} s, render {seconds:.3f} s")
    return 0


def _max_spp(args) -> int:
    """The reference spp cap of ``compare`` / ``showcase``: ``--max-spp``, else by ``--quick``."""
    return args.max_spp or (QUICK_MAX_SPP if args.quick else DEFAULT_MAX_SPP)


def explain_text(rows: list[dict], build_s: float) -> str:
    """``render --explain`` report: one block per plugin with ``build_stats``."""
    lines = [f"scene build (XML, plugins, acceleration structure): {build_s:.3f} s"]
    if not rows:
        lines.append("no plugin reports build_stats")
    for row in rows:
        lines.append(f"{row['kind']} {row['id']!r} ({row['type']}):")
        for key, value in row.items():
            if key in ("id", "kind", "type"):
                continue
            if isinstance(value, list) and value and all(isinstance(v, str) for v in value):
                lines += [f"  {key}:"] + [f"    - {v}" for v in value]
            else:
                lines.append(f"  {key}: {_fmt(value)}")
    return "\n".join(lines)


def _cmd_compare(args) -> int:
    from mi_displace.evaluate.compare import compare

    r = compare(args.scene, args.out, params=dict(args.defines), max_spp=_max_spp(args),
                target_ratio=args.target_ratio, progress=None, denoise=args.denoise)
    capped = ", capped" if r["spp_capped"] else ""
    print(f"{args.scene}: FLIP {r['flip_mean']:.4f} (noise floor {r['noise_floor_flip']:.4f}), "
          f"relMSE {r['relmse']:.4g}, PSNR {_fmt(r['psnr'])} dB, SSIM {r['ssim']:.4f}\n"
          f"reference {r['reference_spp']} spp{capped}: {r['reference_time_s']:.3f} s; "
          f"approximation {r['approx_time_warm_s']:.3f} s warm, {r['approx_time_cold_s']:.3f} s cold; "
          f"speed-up {r['speedup']:.3g}x\nwrote {args.out}/panel.png, metrics.json")
    if args.denoise:
        print(f"{r['path_verdict']}\n{r['denoised_verdict']}")
    return 0


def _cmd_showcase(args) -> int:
    from mi_displace.evaluate.compare import compare_job, write_job_files
    from mi_displace.evaluate.jobs import check_cluster, run_jobs

    check_cluster(args.cluster)
    scenes_dir = args.scenes or default_scenes_dir()
    max_spp = _max_spp(args)
    paths = showcase_scenes(scenes_dir)
    names = [p.relative_to(scenes_dir).with_suffix("").as_posix() for p in paths]
    rows: list[dict | None] = [None] * len(paths)

    def done(index, outcome):  # one broken scene must not hide the others' results
        if outcome["ok"]:
            write_job_files(args.out / names[index], outcome["value"]["files"])
            rows[index] = {**outcome["value"]["info"], "scene": names[index]}
            print(f"{progress.PREFIX} showcase {names[index]}: FLIP {rows[index]['flip_mean']:.4f}, "
                  f"speed-up {rows[index]['speedup']:.3g}x ({outcome['job_s']:.1f} s on "
                  f"{outcome['host']})", file=sys.stderr, flush=True)
        else:
            if outcome.get("error_type") not in ("ValueError", "FileNotFoundError"):
                print(f"{progress.PREFIX} showcase {names[index]}: "
                      f"{outcome.get('traceback', outcome['error'])}{BUG_HINT}", file=sys.stderr)
            rows[index] = {"scene": names[index], "error": outcome["error"]}

    run_jobs(compare_job, [{"scene_path": str(p), "max_spp": max_spp, "progress": None}
                           for p in paths],
             cluster=args.cluster, on_result=done, progress=None, desc="showcase")
    failed = sum("error" in r for r in rows)
    table = summary_table(rows)
    panels = "\n".join(f"![{r['scene']}]({r['scene']}/panel.png)" for r in rows if "error" not in r)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.md").write_text(
        f"# mi-displace showcase\n\nReferences capped at {max_spp} spp.\n\n{table}\n{panels}\n")
    print(table, end="")
    return 1 if failed else 0


def bench_names() -> list[str]:
    """Benchmark modules under ``mi_displace.bench`` (not its private helpers, not the
    ``peers`` subpackage)."""
    try:
        package = importlib.import_module("mi_displace.bench")
    except ModuleNotFoundError:
        return []
    return sorted(m.name for m in pkgutil.iter_modules(package.__path__)
                  if not m.name.startswith("_") and not m.ispkg)


def _cmd_bench(args) -> int:
    available = bench_names()
    if args.name not in available:
        raise UsageError(f"unknown benchmark {args.name!r}; available: {', '.join(available) or 'none'}")
    module = importlib.import_module(f"mi_displace.bench.{args.name}")
    kwargs = {"quick": True} if args.quick else {}
    if args.out is not None:
        if "out" not in inspect.signature(module.main).parameters:
            raise UsageError(f"benchmark {args.name!r} writes no files; it takes no --out")
        kwargs["out"] = args.out
    result = module.main(json=args.json, **kwargs)
    return result if isinstance(result, int) else 0


COMMANDS = {"render": _cmd_render, "compare": _cmd_compare, "showcase": _cmd_showcase,
            "bench": _cmd_bench, "figures": _cmd_figures}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``mi-displace`` console script.

    Returns 0 on success; raises ``SystemExit(2)`` on bad input (one line on stderr),
    ``SystemExit(1)`` when the LLVM backend is unusable or on a bug (traceback + hint).
    """
    import mi_displace
    from mi_displace.core.backend import LLVMVersionError
    from mi_displace.core.extras import MissingExtraError

    args = build_parser().parse_args(argv)
    progress.set_enabled(False if args.quiet else None)
    try:
        mi_displace.init(args.variant)
        handler = getattr(args, "handler", None) or COMMANDS[args.command]
        return handler(args)
    except (ValueError, FileNotFoundError, MissingExtraError) as e:
        print(f"mi-displace: error: {' '.join(str(e).split())}", file=sys.stderr)
        raise SystemExit(2) from None
    except LLVMVersionError as e:
        print(f"mi-displace: error: {e}", file=sys.stderr)
        raise SystemExit(1) from None
    except KeyboardInterrupt:
        print("mi-displace: interrupted", file=sys.stderr)
        raise SystemExit(130) from None
    except Exception:
        traceback.print_exc()
        print(BUG_HINT, file=sys.stderr)
        raise SystemExit(1) from None


if __name__ == "__main__":
    sys.exit(main())
