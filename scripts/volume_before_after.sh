#!/usr/bin/env bash
# The bench volume frames (walnut 256^3, 512^2, one-voxel slices, Gaussian pull, Jacobian
# normals) rendered by the slicer of an older commit and by the working tree, interleaved in
# ONE process (a shared machine's load falls on both alike), plus VTK's frame; prints JSON.
#
#   scripts/volume_before_after.sh [COMMIT (default 5bc139b)] [REPEATS (default 8)]
#
# The old commit's mi_displace/volume/{displacement,field,slicing}.py are copied into
# out/before/ (imports renamed) and drive the same ObjectVolume; docs/volume.md quotes it.
set -euo pipefail
cd "$(dirname "$0")/.."
commit=${1:-5bc139b}
reps=${2:-8}
mkdir -p out/before
for f in displacement field slicing; do
  git show "$commit:mi_displace/volume/$f.py" \
    | sed 's/from mi_displace.volume.displacement import/from before_displacement import/; s/from mi_displace.volume.field import/from before_field import/' \
    > "out/before/before_$f.py"
done
REPS=$reps ./.venv/bin/python - <<'PY'
import json, os, statistics, sys, time
sys.path.insert(0, "out/before")
import numpy as np
from mi_displace.core import backend
backend.init()
import drjit as dr, mitsuba as mi
import before_displacement as bd, before_field as bf, before_slicing as bs
from mi_displace.bench import volume as B
from mi_displace.volume import displacement as ad, field as af, slicer as as_

obj, sensor, scene = B.walnut_256(), B._sensor(), B.sun_scene()
kw = B.VOLUME_KW
cases = {}
for side, (d, f, s) in {"before": (bd, bf, bs), "after": (ad, af, as_)}.items():
    st = s.SliceSettings(model="surface", normals="jacobian", spacing=1.0, shadows=False, iso=B.ISO)
    pull = d.PlacedMap(*B.PULL, resolution=B.PULL_RESOLUTION, to_world=B.PULL_TO_WORLD)
    cases[side + "/undisplaced"] = (s, f.DisplacedVolume(obj, d.DisplacementChain([]), **kw), st)
    cases[side + "/displaced"] = (s, f.DisplacedVolume(obj, d.DisplacementChain([pull], bits=16), **kw), st)
times = {k: [] for k in cases}
cpu = {k: [] for k in cases}
imgs = {}
load_start = os.getloadavg()
for _ in range(int(os.environ["REPS"]) + 1):
    for k, (s, vol, st) in cases.items():
        dr.sync_thread()
        t, c = time.perf_counter(), time.process_time()
        imgs[k] = np.array(s.render(scene, sensor, vol, st))
        times[k].append(time.perf_counter() - t)
        cpu[k].append(time.process_time() - c)
vtk_s, reason = B.vtk_time(obj)
out = {"load_average_start": load_start, "load_average_end": os.getloadavg(), "vtk_s": vtk_s, "vtk_reason": reason}
for k in cases:
    out[k] = {"warm_median_s": statistics.median(times[k][1:]), "cold_s": times[k][0],
              "cpu_median_s": statistics.median(cpu[k][1:])}
for side in ("before", "after"):
    d, u = out[side + "/displaced"], out[side + "/undisplaced"]
    out[side + "/displacement_overhead"] = d["warm_median_s"] / u["warm_median_s"]
    out[side + "/displacement_overhead_cpu"] = d["cpu_median_s"] / u["cpu_median_s"]
    out[side + "/undisplaced_vs_vtk"] = u["warm_median_s"] / vtk_s if vtk_s else None
diff = np.abs(imgs["before/displaced"] - imgs["after/displaced"]).max(-1)
out.update(undisplaced_identical=bool(np.array_equal(imgs["before/undisplaced"], imgs["after/undisplaced"])),
           displaced_pixels_differing_by_over_0_01=int((diff > 0.01).sum()),
           displaced_mean_abs_diff=float(diff.mean()),
           finite=bool(all(np.isfinite(i).all() for i in imgs.values())))
print(json.dumps(out, indent=1))
PY
