"""Trade-off sweeps of the volume technique (docs/volume.md), ``mi-displace volume-figures``.

Each sweep renders one scene's approximation (``volume_slicer``) at every value of one knob
and measures FLIP against that scene's path-traced reference (two seeds averaged; their FLIP
is the noise floor), with warm wall times in the same process; the path tracer's own curve
(FLIP of a k-spp render against the reference, and its time) sits beside each sweep:

* ``bits`` (8 / 16 / 32 = float) and ``dk_res`` (D_k resolution) and ``spacing`` (slice
  distance, voxels) on ``volume_nucleon_pull.xml`` (Gaussian pull, eq. 8);
* ``composition`` (on the fly / precomputed, eq. 9) on ``volume_composite_wave_peel.xml``;
* ``normals`` (gradient / jacobian / blend / fd, §4.3) on ``volume_piggy_surface.xml``
  against its iso-surface reference, plus the angle between each method's normal and the
  finite-difference normal, and the exact mesh normal, at the reference mesh's vertices.
"""
from __future__ import annotations

import json
import statistics
from pathlib import Path

import mitsuba as mi
import numpy as np

from mi_displace.evaluate import metrics
from mi_displace.evaluate.compare import scene_defaults
from mi_displace.render import scene as scenes

SCENES = Path(__file__).resolve().parents[2] / "scenes"
SWEEPS = [
    ("bits", "volume_nucleon_pull.xml", ["8", "16", "32"]),
    ("dk_res", "volume_nucleon_pull.xml", ["8", "16", "32", "64"]),
    ("spacing", "volume_nucleon_pull.xml", ["0.5", "1", "2", "4"]),
    ("composition", "volume_composite_wave_peel.xml", ["on_the_fly", "precomputed"]),
    ("normals", "volume_piggy_surface.xml", ["gradient", "jacobian", "blend", "fd"]),
]


def _reference(path, res, spp):
    """(reference image, noise floor FLIP, seconds, per-spp curve) of a scene."""
    ref_int = scene_defaults(path).get("reference_integrator", "path")
    scene, t = scenes.load(path, mode="reference", integrator=ref_int, res=res)
    images, seconds = [], t["build_s"]
    for seed in (0, 1):
        img, s = scenes.render(scene, spp=spp, seed=seed)
        images.append(img)
        seconds += s
    reference = 0.5 * (images[0] + images[1])
    noise, _ = metrics.flip(images[0], images[1])
    curve = []
    k = 4
    while k < 2 * spp:
        img, s = scenes.render(scene, spp=k, seed=100 + k)
        curve.append({"spp": k, "flip": metrics.flip(reference, img)[0], "time_s": s})
        k *= 4
    return reference, noise, seconds, curve


def _approx(path, res, **params):
    """(image, warm seconds: median of 2 after one cold) of the slicing renderer."""
    times = []
    for _ in range(3):
        scene, t = scenes.load(path, mode="approximation", integrator="volume_slicer", res=res, **params)
        img, s = scenes.render(scene, spp=1)
        times.append(t["build_s"] + s)
    metrics.assert_finite(img, f"approximation of {path.name}")
    return img, statistics.median(times[1:]), scene


def normal_angles(scene) -> dict:
    """Median angle (deg) of each normal method against FD and against the exact mesh normals,
    at the vertices of the scene's iso-surface reference mesh."""
    from mi_displace.volume.isosurface import isosurface

    vol = scene.integrator().plugin.volume
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
    out = {}
    normals = {m: np.stack([np.array(c) for c in vol.normal(p, m, fallback)], -1)
               for m in ("gradient", "jacobian", "blend", "fd")}
    for m, n in normals.items():
        def angle(ref):
            return float(np.median(np.degrees(np.arccos(np.clip((n * ref).sum(1), -1, 1)))))
        out[m] = {"vs_fd_deg": angle(normals["fd"]), "vs_mesh_deg": angle(truth)}
    return out


def sweep(knob, scene_file, values, res, spp) -> dict:
    path = SCENES / scene_file
    reference, noise, ref_s, curve = _reference(path, res, spp)
    rows = []
    last_scene = None
    for value in values:
        img, seconds, last_scene = _approx(path, res, **{knob: value})
        rows.append({knob: value, "flip": metrics.flip(reference, img)[0], "time_s": seconds})
        if knob == "normals":
            rows[-1].update(normal_angles(last_scene)[value])
    return {"knob": knob, "scene": scene_file, "res": res, "reference_spp": 2 * spp,
            "reference_time_s": ref_s, "noise_floor_flip": noise, "rows": rows, "path_curve": curve}


def markdown(record) -> str:
    lines = []
    for s in record:
        cols = [k for k in s["rows"][0] if k != s["knob"]]
        lines.append(f"**{s['knob']}** on `{s['scene']}` ({s['res']}², reference {s['reference_spp']} spp, "
                     f"{s['reference_time_s']:.3g} s, noise floor {s['noise_floor_flip']:.4f})\n")
        lines.append("| " + " | ".join([s["knob"], *cols]) + " |")
        lines.append("|" + "---|" * (len(cols) + 1))
        for r in s["rows"]:
            lines.append("| " + " | ".join([str(r[s["knob"]]), *(f"{r[c]:.4g}" for c in cols)]) + " |")
        lines.append("\npath tracer: " + ", ".join(f"{c['spp']} spp FLIP {c['flip']:.4f} ({c['time_s']:.3g} s)"
                                                   for c in s["path_curve"]) + "\n")
    return "\n".join(lines)


def plot(record, path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4 * len(record), 3.4))
    FigureCanvasAgg(fig)
    for i, s in enumerate(record):
        ax = fig.add_subplot(1, len(record), i + 1)
        ax.plot([c["time_s"] for c in s["path_curve"]], [c["flip"] for c in s["path_curve"]], "o-",
                color="gray", label="volpath/path (spp)")
        for r in s["rows"]:
            ax.plot(r["time_s"], r["flip"], "s")
            ax.annotate(str(r[s["knob"]]), (r["time_s"], r["flip"]), fontsize=7)
        ax.axhline(s["noise_floor_flip"], ls=":", color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("seconds")
        ax.set_ylabel("FLIP")
        ax.set_title(f"{s['knob']} ({s['scene'].replace('.xml', '')})", fontsize=8)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def write_figures(out_dir, quick: bool = False) -> list:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    res, spp = (48, 64) if quick else (64, 256)
    record = [sweep(knob, scene, values, res, spp) for knob, scene, values in SWEEPS]
    (out_dir / "volume_figures.json").write_text(json.dumps(record, indent=2))
    (out_dir / "volume_figures.md").write_text(markdown(record))
    plot(record, out_dir / "volume_sweeps.png")
    return record
