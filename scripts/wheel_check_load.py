"""Load a packaged scene of every registered plugin with ``mi.load_file`` and render it at 16².

Run by ``scripts/wheel_check.sh`` with the Python of a virtualenv that has the wheel
installed, from a temporary directory: the scenes, their include files and assets must come
from the installed package.  Prints one line per plugin with its load and render seconds;
exits 1 if a registered plugin has no entry in :data:`SCENES` or a scene fails to load or
renders a non-finite or black frame.
"""
import sys
import time

import mitsuba as mi
import numpy as np

import mi_displace
from mi_displace.core.backend import resolve_variant
from mi_displace.core.resources import scene_path

SMALL = {"res": "16", "spp": "4"}
#: plugin name -> (packaged scene, defines) that instantiates it, each as cheap as it gets
SCENES = {
    "cells": ("displaced_sphere.xml", {"resolution": "32"}),
    "displaced": ("displaced_sphere.xml", {"resolution": "32"}),
    "raster": ("displaced_sphere.xml", {"resolution": "32", "integrator": "raster"}),
    "ripples": ("tradeoff/bumpy_sphere.xml", {"resolution": "8", "mode": "approximation",
                                              "integrator": "raster"}),
    "ddm": ("ddm_teapot_morph.xml", {"mode": "approximation", "map_resolution": "32"}),  # base="teapot"
    "vdm": ("vdm_torus.xml", {"mode": "approximation", "vdm_res": "16", "vdm_phi": "8",
                              "vdm_theta": "4", "vdm_curvatures": "4"}),
    "vdm_mesh": ("vdm_torus.xml", {"mode": "relief"}),
    "relief": ("vdm_torus.xml", {"mode": "relief"}),
    "horizon": ("vdm_torus.xml", {"mode": "horizon"}),
    "restored": ("bake_bunny.xml", {"mode": "approximation"}),
    "mikk_normalmap": ("bake_bunny.xml", {"mode": "normalmap"}),
    "bricks": ("slicing_plane_grazing.xml", {"mode": "approximation", "slices": "8"}),
    "slicing": ("slicing_plane_grazing.xml", {"mode": "approximation", "slices": "8"}),
    "depth_object": ("slicing_cup_depth.xml", {"mode": "approximation", "slices": "8"}),
    "visual_hull": ("slicing_cup_hull.xml", {"mode": "approximation", "slices": "8"}),
    "displaced_volume": ("volume_nucleon_pull.xml", {}),
    "volume_proxy": ("volume_nucleon_pull.xml", {}),
    "volume_slicer": ("volume_nucleon_pull.xml", {"mode": "approximation",
                                                   "integrator": "volume_slicer"}),
    "volume_isosurface": ("volume_piggy_surface.xml", {"iso_res": "32"}),
}


def registered_plugins() -> list[str]:
    """Names passed to ``mi.register_*`` while :func:`mi_displace.init` registers the plugins."""
    names = []
    mi.set_variant(resolve_variant())   # the variant's module holds the register_* functions
    kinds = [k for k in dir(mi) if k.startswith("register_")]
    originals = {k: getattr(mi, k) for k in kinds}

    def recorder(register):
        def record(name, constructor):
            names.append(name)
            return register(name, constructor)
        return record

    for kind, register in originals.items():
        setattr(mi, kind, recorder(register))
    try:
        mi_displace.init()
    finally:
        for kind, register in originals.items():
            setattr(mi, kind, register)
    return sorted(set(names))


def main() -> int:
    plugins = registered_plugins()
    failures = [f"{name}: no packaged scene listed in SCENES" for name in plugins
                if name not in SCENES]
    loaded = {}
    for name in plugins:
        if name not in SCENES:
            continue
        scene_file, defines = SCENES[name]
        key = (scene_file, tuple(sorted(defines.items())))
        start = time.perf_counter()
        try:
            if key not in loaded:
                scene = mi.load_file(str(scene_path(scene_file)), **SMALL, **defines)
                load_s = time.perf_counter() - start
                image = np.asarray(mi.render(scene, seed=0))
                loaded[key] = (image, load_s, time.perf_counter() - start - load_s)
            image, load_s, render_s = loaded[key]
        except Exception as e:  # every plugin is reported, not only the first failure
            failures.append(f"{name}: {scene_file} {defines}: {type(e).__name__}: {e}")
            continue
        ok = np.isfinite(image).all() and image.max() > 0
        print(f"  {name:18s} {scene_file:28s} load {load_s:6.2f} s  render {render_s:5.2f} s"
              f"{'' if ok else '  NON-FINITE OR BLACK'}", flush=True)
        if not ok:
            failures.append(f"{name}: {scene_file}: non-finite or black 16x16 frame")
    for line in failures:
        print(f"FAIL {line}", file=sys.stderr)
    print(f"{len(plugins) - len(failures)}/{len(plugins)} plugins loaded and rendered")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
