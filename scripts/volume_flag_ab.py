"""A/B of the D_k zero-cell skip branch (displacement.nonzero_cells) on the bench volume frame:
the same displaced volume rendered with the flag grid and without it (every lookup reads the
D_k), interleaved in ONE process with the undisplaced frame; prints JSON (medians, s).

    [MAP=peel] [REPS=10] ./.venv/bin/python scripts/volume_flag_ab.py

MAP=peel swaps the Gaussian pull (a one-channel D_k) for a peel (three channels).  The flag is
forced on for the A side even where SampledMap leaves it off (one-channel D/α reads)."""
import json, os, statistics, time
import numpy as np
from mi_displace.core import backend
backend.init()
import drjit as dr, mitsuba as mi
from mi_displace.bench import volume as B
from mi_displace.volume import displacement as ad, field as af, slicer as s
obj, sensor, scene = B.walnut_256(), B._sensor(), B.sun_scene()
M, kw = B.PULL_TO_WORLD, B.VOLUME_KW
st = s.SliceSettings(model="surface", normals="jacobian", spacing=1.0, shadows=False, iso=B.ISO)
if os.environ.get("MAP") == "peel":
    pull = ad.PlacedMap("peel", {"angle": 40.0, "hinge": 0.8, "height": 0.6, "radius": 0.5}, to_world=M)
else:
    pull = ad.PlacedMap(*B.PULL, resolution=B.PULL_RESOLUTION, to_world=M)
und = af.DisplacedVolume(obj, ad.DisplacementChain([]), **kw)
dis = af.DisplacedVolume(obj, ad.DisplacementChain([pull], bits=16), **kw)
dis.prepare()
dk = dis.chain.sampled_maps()[0]
flag = mi.Float(dk.flags.astype(np.float32).ravel())
print("stored", dk.disp.stored, dk.jac.stored, dk.galpha.stored, "flag frac", np.array(flag).mean())
cases = {"undisplaced": (und, None), "flag": (dis, flag), "noflag": (dis, None)}
times = {k: [] for k in cases}; imgs = {}
for _ in range(int(os.environ.get("REPS", 10)) + 1):
    for k, (v, f) in cases.items():
        dk.nonzero = f
        dr.sync_thread(); t = time.perf_counter()
        imgs[k] = np.array(s.render(scene, sensor, v, st))
        times[k].append(time.perf_counter() - t)
out = {k: statistics.median(t[1:]) for k, t in times.items()}
out["load"] = os.getloadavg()
out["flag_vs_noflag"] = out["flag"] / out["noflag"]
out["identical"] = bool(np.array_equal(imgs["flag"], imgs["noflag"]))
print(json.dumps(out))
