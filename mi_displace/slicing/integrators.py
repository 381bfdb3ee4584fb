"""What the slicing family's proxy costs under each Mitsuba integrator (docs/slicing.md,
"Under Mitsuba's integrators"): ``python -m mi_displace.slicing.integrators [--quick]``.

Two cases against their true geometry rendered by the same integrator: a bricks torus
sliced in direction ``best`` (true geometry: ``displaced``) and the cup as a depth object
(true geometry: the cup mesh), under a sun and a dim constant sky.  Per integrator: the
mean over the pixels the true geometry covers, as a ratio, and the pixels exactly black
where the true geometry is lit; for ``aov``, the depth coverage and the mean depth and
normal errors where both see a surface; ``ptracer`` against ``path`` of the same shape
(their flux ratio, sun only and sky only; the true geometry's own ratio is the control).
"""
from __future__ import annotations

import argparse
import json

import mitsuba as mi
import numpy as np

SKY = 0.3
INTEGRATORS = {
    "path max_depth 2": {"type": "path", "max_depth": 2},
    "path max_depth 3": {"type": "path", "max_depth": 3},
    "volpath max_depth 2": {"type": "volpath", "max_depth": 2},
    "direct": {"type": "direct"},
    "prb max_depth 2": {"type": "prb", "max_depth": 2},
    "aov depth, sh_normal": {"type": "aov", "aovs": "dd:depth,nn:sh_normal"},
}


def cases() -> dict:
    """name -> (slicing-family shape, true geometry, camera origin, camera target)."""
    from mi_displace.slicing import assets

    material = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.4]}}
    bricks = {"type": "bricks", "rows": 4, "columns": 2, "mortar": 0.15, "bevel": 0.2,
              "to_uv": mi.ScalarTransform4f().scale([4, 2, 1])}
    torus = {"base": "torus", "major_radius": 1.0, "minor_radius": 0.4, "scale": 0.1,
             "height": bricks, "bsdf": material}
    cup = assets.source_shape("cup", [0.7, 0.5, 0.4])
    return {
        "torus (best)": ({"type": "slicing", **torus, "resolution": 16, "slices": 8,
                          "draw_base": True}, {"type": "displaced", **torus, "resolution": 256},
                         (0.3, -3.0, 2.4), (0, 0, 0)),
        "cup (depth object)": ({"type": "depth_object", "slices": 64, "resolution": 64,
                                "source": cup}, cup, (0.2, -1.6, 1.6), (0, 0, 0.3)),
    }


def render(shape: dict, integrator: dict, eye, target, spp: int, res: int,
           lights=("sun", "sky")) -> np.ndarray:
    """(res, res, C) image of ``shape`` (C: 3 colour channels, or the AOVs)."""
    emitters = {}
    if "sun" in lights:
        emitters["sun"] = {"type": "directional", "direction": [-0.4, 0.5, -0.75], "irradiance": 2.0}
    if "sky" in lights:
        emitters["sky"] = {"type": "constant", "radiance": SKY}
    scene = mi.load_dict({
        "type": "scene", "integrator": integrator, "obj": shape, **emitters,
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(eye), target=list(target),
                                                              up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}}})
    img = np.asarray(mi.render(scene, spp=spp))
    if not np.all(np.isfinite(img)):
        raise RuntimeError(f"non-finite pixels under {integrator['type']}")
    return img if integrator["type"] == "aov" else img[..., :3]


def compare(img: np.ndarray, truth: np.ndarray, aov: bool) -> dict:
    """The numbers of one integrator (module docstring)."""
    if aov:
        depth, ref_depth = img[..., 0], truth[..., 0]
        both = (depth > 0) & (ref_depth > 0)
        cos = np.clip(np.sum(img[..., 1:4] * truth[..., 1:4], -1)[both], -1, 1)
        return {"coverage": float(np.mean(depth > 0)), "coverage_truth": float(np.mean(ref_depth > 0)),
                "depth_error": float(np.abs(depth - ref_depth)[both].mean()),
                "normal_error_deg": float(np.degrees(np.arccos(cos)).mean())}
    value, ref = img.mean(-1), truth.mean(-1)
    covered = np.abs(ref - SKY) > 1e-3
    return {"mean_ratio": float(value[covered].mean() / ref[covered].mean()),
            "black_where_truth_lit": int(((value == 0) & (ref > 0)).sum()),
            "covered": int(covered.sum())}


def flux_ratio(shape: dict, eye, target, light: str, spp: int, res: int) -> float:
    """ptracer / path flux of ``shape`` alone under ``light`` (max_depth 2 for the sun, 3 for
    the sky), over the pixels path sees the shape in (the sky seen directly is path's only)."""
    depth = 2 if light == "sun" else 3
    path = render(shape, {"type": "path", "max_depth": depth}, eye, target, spp, res, (light,))
    particles = render(shape, {"type": "ptracer", "max_depth": depth}, eye, target, spp, res, (light,))
    seen = np.abs(path - (SKY if light == "sky" else 0.0)).max(-1) > 1e-3
    return float(particles[seen].sum() / path[seen].sum())


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="32^2, 4 spp (a smoke run)")
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args(argv)
    from mi_displace.core import backend

    backend.init(mi.variant() or "llvm_ad_rgb")

    res, spp, pt_spp = (32, 4, 4) if args.quick else (64, 16, 64)
    out = {}
    for name, (shape, truth, eye, target) in cases().items():
        rows = {}
        for label, integrator in INTEGRATORS.items():
            aov = integrator["type"] == "aov"
            rows[label] = compare(render(shape, integrator, eye, target, spp, res),
                                  render(truth, integrator, eye, target, spp, res), aov)
            print(f"{name:20s} {label:22s} {json.dumps(rows[label])}", flush=True)
        for light in ("sun", "sky"):
            label = f"ptracer / path ({light})"
            rows[label] = {"shape": flux_ratio(shape, eye, target, light, pt_spp, res),
                           "truth": flux_ratio(truth, eye, target, light, pt_spp, res)}
            print(f"{name:20s} {label:22s} {json.dumps(rows[label])}", flush=True)
        out[name] = rows
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"res": res, "spp": spp, "ptracer_spp": pt_spp, "cases": out}, f, indent=1)
    return out


if __name__ == "__main__":
    main()
