"""Where the bench volume frame's displacement overhead goes, in ONE process (a shared
machine's load falls on every case alike): the undisplaced frame, the displaced one (the
bench's Gaussian pull) with the renderer's two read savings switched off and on one by one,
and a pull of amount 1e-4, which reads every D_k / J that the pull reads but leaves the
walnut where it is (its time over the undisplaced one is the cost of the reads, the rest of
the displaced frame's is the cost of the bigger displaced object).  Prints JSON: medians (s)
over REPS interleaved warm renders, their ratios to the median undisplaced frame (wall and
CPU), and whether each image equals the first case's.

    [REPS=60] ./.venv/bin/python scripts/volume_overhead_ab.py

Switches: ``reuse`` = SliceSettings.reuse_lookup (shade with the density step's lookup),
``box`` = the D_k's read_box (skip reads outside its non-zero nodes)."""
import json, os, statistics, time
import numpy as np
from mi_displace.core import backend
backend.init()
import drjit as dr
from mi_displace.bench import volume as B
from mi_displace.volume import displacement as ad, field as af, slicer as s

obj, sensor, scene = B.walnut_256(), B._sensor(), B.sun_scene()
st = s.SliceSettings(model="surface", normals="jacobian", spacing=1.0, shadows=False, iso=B.ISO)


def pulled(amount):
    m = ad.PlacedMap(B.PULL[0], {**B.PULL[1], "amount": amount}, resolution=B.PULL_RESOLUTION,
                     to_world=B.PULL_TO_WORLD)
    v = af.DisplacedVolume(obj, ad.DisplacementChain([m], bits=16), **B.VOLUME_KW)
    v.prepare()
    return v


und = af.DisplacedVolume(obj, ad.DisplacementChain([]), **B.VOLUME_KW)
dis, tiny = pulled(B.PULL[1]["amount"]), pulled(1e-4)
boxes = {v: v.chain.sampled_maps()[0].read_box for v in (dis, tiny)}
cases = {"undisplaced": (und, True, True), "displaced/neither": (dis, False, False),
         "displaced/reuse": (dis, True, False), "displaced/box": (dis, False, True),
         "displaced/both": (dis, True, True), "tiny_pull/both": (tiny, True, True)}
times = {k: [] for k in cases}
cpu = {k: [] for k in cases}
imgs = {}
load = os.getloadavg()
for _ in range(int(os.environ.get("REPS", 60)) + 1):
    for k, (v, reuse, box) in cases.items():
        st.reuse_lookup = reuse
        if v in boxes:
            v.chain.sampled_maps()[0].read_box = boxes[v] if box else None
        dr.sync_thread()
        t, c = time.perf_counter(), time.process_time()
        imgs[k] = np.array(s.render(scene, sensor, v, st))
        times[k].append(time.perf_counter() - t)
        cpu[k].append(time.process_time() - c)
wall = {k: statistics.median(t[1:]) for k, t in times.items()}
proc = {k: statistics.median(t[1:]) for k, t in cpu.items()}
first = "displaced/neither"
out = {"load_average_start": load, "load_average_end": os.getloadavg(), "reps": len(times[first]) - 1}
for k in cases:
    out[k] = {"wall_s": wall[k], "cpu_s": proc[k], "vs_undisplaced_wall": wall[k] / wall["undisplaced"],
              "vs_undisplaced_cpu": proc[k] / proc["undisplaced"]}
    if k.startswith("displaced"):
        out[k]["image_equals_" + first] = bool(np.array_equal(imgs[k], imgs[first]))
print(json.dumps(out, indent=1))
