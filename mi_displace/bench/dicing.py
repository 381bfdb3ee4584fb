"""`mi-displace bench dicing`: screen-adaptive dicing against uniform tessellation (issue 13).

1. **Cycles' sphere** re-made: h = 0.05 sin 8x sin 8y sin 8z on a radius-1 sphere, camera 3.2
   units away, 50 mm lens (36 mm film width: 39.6 degrees), 256^2, dicing rate 1 px: our
   triangle count beside Cycles' quoted 821,760 (an external figure, not measured here), our
   tessellation + acceleration-structure time, and FLIP against a uniform tessellation with
   4x shorter edges (0.25 px at the front) next to the noise floor of that path reference
   (FLIP between two seeds).
2. **Sweeps** on ``displaced_sphere``, ``bump_vs_displaced`` (its true-displacement side)
   and ``displaced_horizon``: triangles, bytes, build time (plugin + Mitsuba's acceleration
   structure: ``mi.load_file`` end to end) and FLIP for uniform ``resolution`` and for
   ``dicing_rate`` 0.5 / 1 / 2 / 4 px.  The reference of each scene is dicing at 0.5 px with
   ``offscreen_dicing_scale`` 1 (nothing coarsened off screen; the only tessellation of the
   horizon plane fine enough near the camera that fits in memory), and the finest uniform
   point's FLIP against it is reported too.  Every render: Mitsuba ``path`` (max_depth 2),
   same seed for every geometry (correlated samples, so FLIP measures geometry), noise floor
   = FLIP between two seeds of the reference.
3. The summary (``--json``): on the horizon plane, dicing at 1 px against the cheapest
   uniform resolution of the sweep whose FLIP is no larger (``uniform_faces``), with both
   build times measured in this process, and ``cycles_faces`` = 821760 (quoted).

``--quick`` runs every part with :data:`QUICK` sizes (64^2 films, 4 spp, two uniform
resolutions and two rates per scene): the same code paths in seconds, numbers not comparable.

Writes ``dicing_bench.json`` and ``dicing_flip_vs_faces.png`` under ``--out`` (default: a
folder ``mi_displace_bench/dicing`` in the system's temporary directory); the documentation's
figures are refreshed by naming them: ``mi-displace bench dicing --out docs/figures``.
"""
from __future__ import annotations

import gc
import json as _json
import math
import time
from pathlib import Path
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from mi_displace.bench._timing import output_dir, print_record
from mi_displace.core.resources import scene_path
from mi_displace.evaluate import metrics
from mi_displace.render import scene as scenes

CYCLES_FACES = 821_760       # Cycles' count for its 5,120-triangle sphere (issue 13, quoted)
SWEEPS = {  # scene -> extra -D parameters
    "displaced_sphere": {}, "bump_vs_displaced": {"mode": "reference"},
    "displaced_horizon": {"mode": "uniform"},
}
REFERENCE_RATE = 0.5


class Sizes(NamedTuple):
    """What a run renders: ``spp`` per render, films of ``res`` x ``res`` pixels, the Cycles
    sphere's uniform reference at ``cycles_reference`` cells per side, dicing ``rates`` (px)
    and each sweep scene's uniform ``resolutions`` (cells per side)."""
    spp: int
    res: int
    cycles_reference: int
    rates: tuple
    resolutions: dict


FULL = Sizes(32, 256, 4096, (0.5, 1.0, 2.0, 4.0),
             {"displaced_sphere": (128, 256, 512, 1024, 2048),
              "bump_vs_displaced": (128, 256, 512, 1024, 2048),
              "displaced_horizon": (256, 512, 1024, 2048)})
QUICK = Sizes(4, 64, 512, (1.0, 4.0), {name: (32, 128) for name in SWEEPS})


def _solid_sines_texture():
    """h = sin 8x sin 8y sin 8z of the unit-sphere point at (u, v) (Mitsuba's sphere uv)."""

    class SolidSines(mi.Texture):
        def __init__(self, props):
            super().__init__(props)

        def _eval(self, si):
            phi, theta = dr.two_pi * si.uv.x, dr.pi * si.uv.y
            sp, cp = dr.sincos(phi)
            st, ct = dr.sincos(theta)
            p = mi.Vector3f(st * cp, st * sp, ct)
            s = [dr.sin(8 * c) for c in p]
            c = [8 * dr.cos(8 * x) for x in p]
            grad_p = mi.Vector3f(c[0] * s[1] * s[2], s[0] * c[1] * s[2], s[0] * s[1] * c[2])
            dp_du = dr.two_pi * mi.Vector3f(-st * sp, st * cp, 0)
            dp_dv = dr.pi * mi.Vector3f(ct * cp, ct * sp, -st)
            return s[0] * s[1] * s[2], mi.Vector2f(dr.dot(grad_p, dp_du), dr.dot(grad_p, dp_dv))

        def eval_1(self, si, active=True):
            return self._eval(si)[0]

        def eval_1_grad(self, si, active=True):
            return self._eval(si)[1]

        def max(self):
            return mi.Float(1.0)

        def is_spatially_varying(self):
            return True

    mi.register_texture("solid_sines", lambda props: SolidSines(props))


def _cycles_scene(shape: dict, sizes: Sizes) -> dict:
    return {
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "camera": {"type": "perspective", "fov": math.degrees(2 * math.atan(18 / 50)),
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, -3.2, 0], target=[0, 0, 0],
                                                              up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": sizes.res, "height": sizes.res,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": sizes.spp}},
        "key": {"type": "point", "position": [3, -3, 3], "intensity": {"type": "rgb", "value": 30}},
        "ambient": {"type": "constant", "radiance": {"type": "rgb", "value": 0.05}},
        "ball": {"type": "displaced", "base": "sphere", "scale": 0.05, "midlevel": 0.0,
                 "height": {"type": "solid_sines"},
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.6, 0.5]}},
                 **shape},
    }


def _timed_load(loader) -> tuple[mi.Scene, float]:
    gc.collect()
    dr.sync_thread()
    start = time.perf_counter()
    scene = loader()
    dr.sync_thread()
    return scene, time.perf_counter() - start


def _measure(loader, spp: int, reference=None, seeds=(0,)) -> dict:
    """Load (timed), render ``seeds`` at ``spp``; FLIP of seed 0 against ``reference`` if given."""
    scene, build_s = _timed_load(loader)
    shape = next(s for s in scene.shapes() if hasattr(s, "build_stats"))
    stats = dict(shape.build_stats)
    images = []
    for seed in seeds:
        img, render_s = scenes.render(scene, spp=spp, seed=seed)
        metrics.assert_finite(img, "dicing bench image")
        images.append(img)
    del scene, shape
    gc.collect()
    row = {"faces": stats["faces"], "vertices": stats["vertices"], "bytes": stats["bytes"],
           "build_s": build_s, "tessellate_s": stats["tessellate_s"], "render_s": render_s,
           "edge_segments_max": stats.get("edge_segments_max")}
    if reference is not None:
        row["flip"] = metrics.flip(reference, images[0])[0]
    return row, images


def cycles_sphere(sizes: Sizes) -> dict:
    """Part 1 (see the module docstring)."""
    _solid_sines_texture()
    ref_loader = lambda: mi.load_dict(_cycles_scene({"resolution": sizes.cycles_reference}, sizes))
    fine, (ref0, ref1) = _measure(ref_loader, sizes.spp, seeds=(0, 1))
    noise = metrics.flip(ref0, ref1)[0]
    ours, _ = _measure(lambda: mi.load_dict(_cycles_scene(
        {"dicing_rate": 1.0, "cam": {"type": "ref", "id": "camera"}}, sizes)), sizes.spp,
        reference=ref0)
    return {"cycles_faces": CYCLES_FACES, "faces": ours["faces"], "bytes": ours["bytes"],
            "tessellate_s": ours["tessellate_s"], "build_s": ours["build_s"],
            "flip_vs_uniform_4x": ours["flip"], "noise_floor_flip": noise,
            "uniform_4x_faces": fine["faces"], "uniform_4x_build_s": fine["build_s"],
            "spp": sizes.spp}


def sweep(name: str, sizes: Sizes) -> dict:
    """Part 2 for one scene."""
    path = scene_path(f"{name}.xml")
    extra = {**SWEEPS[name], "res": sizes.res}
    dicing_params = ({"mode": "approximation", "res": sizes.res} if name == "displaced_horizon"
                     else {**extra, "tessellation": "dicing"})

    def load(**params):
        return lambda: scenes.load(path, **{**dicing_params, **params})[0]

    if name == "displaced_horizon":
        reference = load(mode="reference", reference_rate=REFERENCE_RATE)
    else:
        reference = _with_offscreen(path, dicing_params, REFERENCE_RATE)
    ref, (ref0, ref1) = _measure(reference, sizes.spp, seeds=(0, 1))
    out = {"reference": {**ref, "dicing_rate": REFERENCE_RATE, "offscreen_dicing_scale": 1},
           "noise_floor_flip": metrics.flip(ref0, ref1)[0], "uniform": [], "dicing": []}
    for rate in sizes.rates:
        row, _ = _measure(load(dicing_rate=rate), sizes.spp, reference=ref0)
        out["dicing"].append({"dicing_rate": rate, **row})
    for res in sizes.resolutions[name]:
        row, _ = _measure(lambda: scenes.load(path, **{**extra, "resolution": res})[0],
                          sizes.spp, reference=ref0)
        out["uniform"].append({"resolution": res, **row})
    return out


def _with_offscreen(path, params, rate):
    """Loader of a sphere scene diced at ``rate`` with offscreen_dicing_scale 1: the XML has
    no such parameter, so the shape's value is set through mi.traverse before re-dicing."""
    def loader():
        scene = scenes.load(path, **{**params, "dicing_rate": rate})[0]
        p = mi.traverse(scene)
        for key in [k for k in p.keys() if k.endswith("offscreen_dicing_scale")]:
            p[key] = 1.0
        p.update()
        return scene
    return loader


def summary(cycles: dict, sweeps: dict) -> dict:
    """Part 3: the headline record."""
    hz = sweeps["displaced_horizon"]
    adaptive = next(r for r in hz["dicing"] if r["dicing_rate"] == 1.0)
    reaching = [r for r in hz["uniform"] if r["flip"] <= adaptive["flip"]]
    uniform = min(reaching, key=lambda r: r["faces"]) if reaching else max(
        hz["uniform"], key=lambda r: r["faces"])
    return {
        "adaptive_faces": adaptive["faces"], "uniform_faces": uniform["faces"],
        "uniform_resolution": uniform["resolution"],
        "uniform_reaches_adaptive_flip": bool(reaching),
        "adaptive_build_s": adaptive["build_s"], "uniform_build_s": uniform["build_s"],
        "flip_adaptive": adaptive["flip"], "flip_uniform": uniform["flip"],
        "noise_floor_flip": hz["noise_floor_flip"],
        "face_ratio": uniform["faces"] / adaptive["faces"],
        "cycles_faces": CYCLES_FACES, "cycles_sphere_faces": cycles["faces"],
        "cycles_sphere_flip_vs_uniform_4x": cycles["flip_vs_uniform_4x"],
        "cycles_sphere_noise_floor_flip": cycles["noise_floor_flip"],
        "cycles_sphere_build_s": cycles["build_s"],
    }


def plot(sweeps: dict, path: Path) -> None:
    """FLIP against triangles, uniform and adaptive on one chart per scene."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * len(sweeps), 3.6))
    FigureCanvasAgg(fig)
    for i, (name, data) in enumerate(sweeps.items()):
        ax = fig.add_subplot(1, len(sweeps), i + 1)
        for key, label, marker in (("uniform", "uniform resolution", "o-"),
                                   ("dicing", "dicing_rate (px)", "s-")):
            # a point at FLIP 0 is the reference itself (log axes): left out
            rows = sorted((r for r in data[key] if r["flip"] > 0), key=lambda r: r["faces"])
            ax.plot([r["faces"] for r in rows], [r["flip"] for r in rows], marker, label=label)
            for r in rows:
                ax.annotate(str(r.get("resolution", r.get("dicing_rate"))), (r["faces"], r["flip"]),
                            fontsize=7, textcoords="offset points", xytext=(3, 3))
        ax.axhline(data["noise_floor_flip"], color="gray", ls="--", lw=1, label="noise floor")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("triangles")
        ax.set_ylabel("FLIP vs reference")
        ax.set_title(f"{name} (reference: {data['reference']['faces']:,} faces)", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def run(sizes: Sizes = FULL) -> dict:
    cycles = cycles_sphere(sizes)
    sweeps = {name: sweep(name, sizes) for name in SWEEPS}
    return {"summary": summary(cycles, sweeps), "cycles_sphere": cycles, "sweeps": sweeps,
            "spp": sizes.spp, "res": sizes.res, "variant": mi.variant()}


def main(json: bool = False, quick: bool = False, out=None, replot: bool = False) -> int:
    """Run the benchmark (:data:`QUICK` sizes with ``quick``) and write its JSON and figure
    under ``out``; with ``replot``, only redraw the figure from the JSON saved there."""
    figures = output_dir("dicing", out)
    if replot:
        result = _json.loads((figures / "dicing_bench.json").read_text())
        plot(result["sweeps"], figures / "dicing_flip_vs_faces.png")
        return 0
    result = run(QUICK if quick else FULL)
    (figures / "dicing_bench.json").write_text(_json.dumps(result, indent=2))
    plot(result["sweeps"], figures / "dicing_flip_vs_faces.png")
    print_record(result["summary"], json, width=0)
    return 0
