"""Sub-commands ``bake``, ``restore`` and ``meshdiff`` of ``mi-displace`` (paper 003).

* ``bake --high H [--low L] --res N --out DIR [--aa A] [--max-distance D] [--padding K]
  [--formats f1,f2] [--diagnostics] [--cage C | --cage-offset D] [--target-faces F]
  [--smoothing S] [--ao-samples N] [--ao-distance D] [--ao-seed S] [--curvature-range H]
  [--high-texture IMG] [--green +y|-y] [--preview]`` -> maps + sidecars, ``low.obj``, ``valid.png``, Mitsuba
  scene fragments ``mitsuba_*.xml``, ``bake.json`` (and ``preview.png`` / ``.json``);
* ``restore --map DIR/MAP [--low L] [--levels K | --split N] --out M.(ply|obj)``;
* ``meshdiff A B [--samples N] [--json]`` -> RMS and Hausdorff, both ways.
"""
from __future__ import annotations

import argparse
import json
import warnings

from mi_displace.core.progress import stage


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def add_commands(sub) -> dict:
    """Add the baker's sub-parsers to ``sub``; returns {command: handler}."""
    p = sub.add_parser("bake", help="bake displacement/normal maps of a high-poly over a low-poly")
    p.add_argument("--high", required=True, help="high-poly mesh (OBJ/PLY/...)")
    p.add_argument("--low", default=None, help="low-poly mesh; omitted: simplified from the high-poly")
    p.add_argument("--res", type=_int, required=True, help="map size in texels")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--aa", type=_int, default=1, help="sub-samples per texel side (default 1)")
    p.add_argument("--max-distance", type=_positive_float, default=None,
                   help="largest |displacement| searched, object units (default: 1.5 x the one-sided "
                        "Hausdorff distance low -> high + 0.5%% of the diagonal)")
    p.add_argument("--padding", type=float, default=8, help="edge padding in texels (default 8)")
    p.add_argument("--formats", default=None,
                   help="comma-separated map formats, or 'all' (default: d16,normal_tangent,normal_mitsuba; "
                        "valid.png, the mask, is always written)")
    p.add_argument("--diagnostics", action="store_true", help="diagnostics mode: overhang rays and diagnostics.png")
    p.add_argument("--cage", default=None, help="cage mesh with the low-poly's topology (Fig. 8)")
    p.add_argument("--cage-offset", type=_positive_float, default=None,
                   help="cage = low-poly pushed out along its normals by this distance")
    p.add_argument("--target-faces", type=_int, default=5000, help="faces of a generated low-poly")
    p.add_argument("--smoothing", type=_int, default=10, help="Taubin passes before simplifying")
    p.add_argument("--ao-samples", type=_int, default=64,
                   help="ambient occlusion rays per texel sample (formats ao, ao_float; default 64)")
    p.add_argument("--ao-distance", type=_positive_float, default=None,
                   help="ambient occlusion ray length, object units (default 0.1 x the diagonal)")
    p.add_argument("--ao-seed", type=_int, default=0, help="ambient occlusion random seed")
    p.add_argument("--curvature-range", type=_positive_float, default=None,
                   help="|H| of full contrast in the curvature and cavity maps, 1/object units "
                        "(default the 99th percentile of |H|)")
    p.add_argument("--high-texture", default=None,
                   help="the high-poly's colour texture (looked up with its UVs): bakes albedo")
    p.add_argument("--green", choices=("+y", "-y"), default="+y",
                   help="tangent-space normal map convention: +y OpenGL (default), -y DirectX "
                        "(write --green=-y)")
    p.add_argument("--preview", action="store_true",
                   help="render the high-poly and every scene fragment side by side with FLIP "
                        "(preview.png, preview.json)")

    p = sub.add_parser("restore", help="restore a detailed mesh from a low-poly and a map (§5)")
    p.add_argument("--map", required=True, help="baked map (its .json sidecar must lie beside it)")
    p.add_argument("--low", default=None, help="low-poly with UVs (default: the one the map names)")
    p.add_argument("--levels", type=_int, default=2, help="rounds of 1->4 midpoint subdivision")
    p.add_argument("--split", type=_int, default=None, help="uniform 1->N^2 split instead of --levels")
    p.add_argument("--out", required=True, help="restored mesh, .ply or .obj")

    p = sub.add_parser("meshdiff", help="RMS and Hausdorff distance between two meshes")
    p.add_argument("a", help="reference mesh (relative values use its bounding-box diagonal)")
    p.add_argument("b", help="test mesh")
    p.add_argument("--samples", type=_int, default=100_000, help="surface samples per direction")
    p.add_argument("--json", action="store_true", help="print JSON")
    return {"bake": _cmd_bake, "restore": _cmd_restore, "meshdiff": _cmd_meshdiff}


def _cmd_bake(args) -> int:
    from mi_displace.bake.baker import bake
    from mi_displace.bake.formats import DEFAULT_FORMATS

    fmts = DEFAULT_FORMATS if args.formats is None else [f.strip() for f in args.formats.split(",")]
    with stage(f"baking {args.high} at {args.res}^2"), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = bake(args.high, args.low, res=args.res, out_dir=args.out, aa=args.aa,
                      max_distance=args.max_distance, pad=args.padding, map_formats=fmts,
                      diagnostics=args.diagnostics, cage=args.cage,
                      cage_offset=args.cage_offset, target_faces=args.target_faces,
                      smoothing_iterations=args.smoothing, ao_samples=args.ao_samples,
                      ao_distance=args.ao_distance, ao_seed=args.ao_seed,
                      curvature_range=args.curvature_range, high_texture=args.high_texture,
                      green=args.green, progress=lambda line: print(f"bake: {line}", flush=True))
    for w in caught:
        print(f"mi-displace: warning: {w.message}")
    r = result.record
    c, t, lo = r["counts"], r["timings"], r["low"]
    for note in lo["notes"]:
        print(f"low-poly: {note}")
    print(f"low-poly: {lo['boundary_edges']} boundary edges, {lo['non_manifold_edges']} "
          f"non-manifold edge{'' if lo['non_manifold_edges'] == 1 else 's'}")
    print(f"baked {r['settings']['width']}x{r['settings']['height']} (aa {r['settings']['aa']}, "
          f"search distance {r['settings']['max_distance']:.4g}): "
          f"{c['covered']} texels covered, ok {c['ok']}, ambiguous {c['ambiguous']}, "
          f"backface {c['backface']}, missed {c['miss'] + c['beyond']} (beyond the search "
          f"distance {c['beyond']}, nothing {c['miss']}); "
          f"bake {t['bake_s']:.3f} s (acceleration {t['accel_s']:.3f} s)\n"
          f"wrote {args.out}/bake.json and {len(r['files'])} files")
    if args.preview:
        _preview(args.high, args.out, result)
    return 0


def _preview(high_path: str, out: str, bake_result) -> None:
    from mi_displace.bake.meshdata import load_mesh
    from mi_displace.bake.preview import compare_bake, decode_errors, write_preview
    from mi_displace.bake.trace import AMBIGUOUS, OK

    with stage("rendering the preview"):
        result = compare_bake(load_mesh(high_path, "high-poly"), out, res=256, spp=16)
        status = bake_result.status
        decodes = decode_errors(out, bake_result.low, bake_result.maps["normal_object"],
                                (status == OK) | (status == AMBIGUOUS))
    png, _ = write_preview(result, out, decodes)
    print("preview (FLIP against the high-poly: all / UV chart borders / chart interiors):")
    for way, r in result.items():
        if way != "reference":
            print(f"  {way:14s} {r['flip']:.4f} / {r['flip_border']:.4f} / {r['flip_interior']:.4f}")
    print("normals Mitsuba decodes at texel centres against the object-space bake "
          "(degrees: mean / p99 / max, texels over 1 degree):")
    for way, d in decodes.items():
        print(f"  {way:14s} {d['mean_deg']:.3f} / {d['p99_deg']:.3f} / {d['max_deg']:.3f}, "
              f"{d['over_1deg']} of {d['texels']}")
    print(f"wrote {png}")


def _cmd_restore(args) -> int:
    from mi_displace.bake.restore import low_for_map, restore

    if not str(args.out).lower().endswith((".ply", ".obj")):   # before any work
        raise ValueError(f"out: restored mesh must be .ply or .obj, got {str(args.out)!r}")
    low = args.low or low_for_map(args.map)
    with stage(f"restoring {args.map}"):
        out = restore(low, args.map, levels=args.levels, split=args.split)
    out.save(args.out)
    r = out.report
    print(f"restored {len(out.faces)} triangles, {len(out.positions)} vertices in "
          f"{out.seconds:.3f} s; wrote {args.out}\n"
          f"low-poly {'closed' if r['closed'] else 'open'} ({r['boundary_edges']} boundary, "
          f"{r['non_manifold_edges']} non-manifold edges); {r['void_vertices']} vertices over "
          f"texels without high-poly, {r['dropped_faces']} faces dropped; holes {r['holes']}")
    return 0


def _cmd_meshdiff(args) -> int:
    from mi_displace.bake.meshdata import load_mesh
    from mi_displace.evaluate.metrics import mesh_distance

    if args.samples < 1:
        raise ValueError(f"--samples: must be positive, got {args.samples}")
    with stage(f"meshdiff: loading {args.a} and {args.b}") as s:
        a, b = load_mesh(args.a, "mesh A"), load_mesh(args.b, "mesh B")
        s.note = f"{len(a.faces):,} and {len(b.faces):,} faces"
    with stage(f"meshdiff: {args.samples:,} surface samples each way"):
        d = mesh_distance((a.positions, a.faces), (b.positions, b.faces), samples=args.samples)
    if args.json:
        print(json.dumps({"a": args.a, "b": args.b, **d}, indent=2))
    else:
        print(f"RMS {d['rms']:.6g} ({d['rms_rel']:.4%} of the diagonal), Hausdorff "
              f"{d['hausdorff']:.6g} ({d['hausdorff_rel']:.4%}); A->B {d['hausdorff_ab']:.6g}, "
              f"B->A {d['hausdorff_ba']:.6g}")
    return 0
