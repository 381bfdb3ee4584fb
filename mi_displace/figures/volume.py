"""Trade-off sweeps of the volume technique (docs/volume.md), ``mi-displace figures volume``.

Each sweep is :func:`mi_displace.evaluate.tradeoff.tradeoff` over one knob of one scene: the
approximation (``volume_slicer``) at every value, FLIP against the scene's path-traced
reference (two seeds; their FLIP is the noise floor), warm time (median of 3 load + render
rounds after a cold one) and the path tracer's own curve (4, 16, 64, 256 spp):

* ``bits`` (8 / 16 / 32 = float) and ``dk_res`` (D_k resolution) and ``spacing`` (slice
  distance, voxels) on ``volume_nucleon_pull.xml`` (Gaussian pull, eq. 8);
* ``composition`` (on the fly / precomputed, eq. 9) on ``volume_composite_wave_peel.xml``;
* ``normals`` (gradient / jacobian / blend / fd, §4.3) on ``volume_piggy_surface.xml``
  against its iso-surface reference, plus (:func:`normal_angles`, the sweep's ``inspect``)
  the angle between the point's normal and the finite-difference normal, and the exact mesh
  normal, at the reference mesh's vertices.

Outputs: ``volume_figures.json`` (per sweep: the table rows and the whole tradeoff result),
``volume_figures.md`` and ``volume_sweeps.png`` (one tradeoff plot per sweep).  ``--quick``:
24² images, 16-spp references.
"""
from __future__ import annotations

import json
from pathlib import Path

import mitsuba as mi
import numpy as np

from mi_displace.core.resources import scenes_dir
from mi_displace.evaluate import tradeoff as tr

SCENES = scenes_dir()
SWEEPS = [
    ("bits", "volume_nucleon_pull.xml", ["8", "16", "32"]),
    ("dk_res", "volume_nucleon_pull.xml", ["8", "16", "32", "64"]),
    ("spacing", "volume_nucleon_pull.xml", ["0.5", "1", "2", "4"]),
    ("composition", "volume_composite_wave_peel.xml", ["on_the_fly", "precomputed"]),
    ("normals", "volume_piggy_surface.xml", ["gradient", "jacobian", "blend", "fd"]),
]
#: spp of the path tracer's own curve beside each sweep
PATH_SPPS = (4, 16, 64, 256)


def normal_angles(scene) -> dict:
    """Median angle (deg) between the normals the scene's ``volume_slicer`` uses and the
    finite-difference / exact mesh normals, at the vertices of the volume's iso-surface
    (a :func:`tradeoff` ``inspect``: ``vs_fd_deg``, ``vs_mesh_deg``)."""
    from mi_displace.volume.isosurface import isosurface

    integrator = scene.integrator()
    vol, method = integrator.plugin.volume, integrator.settings.normals
    verts, faces = isosurface(vol, 0.5, 128)
    mesh = mi.Mesh("iso", len(verts), len(faces), mi.Properties(), True, False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(verts.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    params.update()
    mesh.recompute_vertex_normals()
    truth = np.array(mi.traverse(mesh)["vertex_normals"]).reshape(-1, 3)
    p = mi.Point3f(*(mi.Float(verts[:, i]) for i in range(3)))
    fallback = mi.Vector3f(0, 0, 1)
    n, fd = (np.stack([np.array(c) for c in vol.normal(p, m, fallback)], -1)
             for m in (method, "fd"))

    def angle(ref):
        return float(np.median(np.degrees(np.arccos(np.clip((n * ref).sum(1), -1, 1)))))
    return {"vs_fd_deg": angle(fd), "vs_mesh_deg": angle(truth)}


def sweep(knob: str, scene_file: str, values: list[str], res: int, max_spp: int,
          cache_dir=None) -> dict:
    """One knob of one scene through :func:`tradeoff` (module docstring)."""
    result = tr.tradeoff(SCENES / scene_file, [tr.parse_knob(f"{knob}={','.join(values)}")],
                         params={"res": str(res)}, max_spp=max_spp, cache_dir=cache_dir,
                         path_spps=[s for s in PATH_SPPS if s < max_spp],
                         inspect=normal_angles if knob == "normals" else None)
    return {"knob": knob, "scene": scene_file, "res": res, "rows": tr.table_rows(result),
            "tradeoff": result}


def markdown(record: list[dict]) -> str:
    """One table per sweep (value, FLIP, warm time, inspected angles) and its path curve."""
    lines = []
    for s in record:
        t = s["tradeoff"]
        columns = [(s["knob"], s["knob"], ""), ("FLIP", "flip", ".4f"),
                   ("warm time (s)", "time_warm_s", ".3g")]
        if any("vs_fd_deg" in r for r in s["rows"]):
            columns += [("vs FD (deg)", "vs_fd_deg", ".3g"), ("vs mesh (deg)", "vs_mesh_deg", ".3g")]
        lines.append(f"**{s['knob']}** on `{s['scene']}` ({s['res']}², reference "
                     f"{t['reference_spp']} spp, {t['reference_time_s']:.3g} s, noise floor "
                     f"{t['noise_floor_flip']:.4f})\n")
        lines.append(tr.markdown(s["rows"], columns))
        lines.append("path tracer: " + ", ".join(
            f"{c['spp']} spp FLIP {c['flip']:.4f} ({c['time_s']:.3g} s)" for c in t["path_curve"])
            + "\n")
    return "\n".join(lines)


def plot(record: list[dict], path) -> None:
    """One :func:`tradeoff.plot` panel per sweep."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.5 * len(record), 4.0))
    FigureCanvasAgg(fig)
    for i, s in enumerate(record):
        tr.plot(s["tradeoff"], ax=fig.add_subplot(1, len(record), i + 1),
                title=f"{s['knob']} ({s['scene'].replace('.xml', '')})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_figures(out_dir, quick: bool = False, cache_dir=None) -> list:
    """Every sweep of :data:`SWEEPS` (``quick``: 24², 16-spp references) and the outputs."""
    from mi_displace.evaluate.compare import _finite_or_none

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    res, max_spp = (24, 16) if quick else (64, 512)
    record = [sweep(knob, scene, values, res, max_spp, cache_dir) for knob, scene, values in SWEEPS]
    (out_dir / "volume_figures.json").write_text(json.dumps(_finite_or_none(record), indent=2))
    (out_dir / "volume_figures.md").write_text(markdown(record))
    plot(record, out_dir / "volume_sweeps.png")
    return record


def add_options(parser) -> None:
    """No options of its own."""


def run(args) -> int:
    """``mi-displace figures volume``: the files of the module docstring under ``args.out``."""
    record = write_figures(args.out, quick=args.quick)
    print(f"wrote {args.out}/volume_figures.json, volume_figures.md and volume_sweeps.png "
          f"({len(record)} tables)")
    return 0
