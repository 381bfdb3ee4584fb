"""Where the sliced donut's raster frame goes (one process; ratios hold on a shared machine).

    ./.venv/bin/python scripts/slicing_frame_profile.py [DIRECTION] [RES]

DIRECTION a or best (default best), RES the film side (512), on ``slicing_donut.xml`` as
``mi-displace bench frames`` draws it (``raster``, aa=1, one sample a pixel).  Prints

* the median wall seconds, over frames drawn alternately, of the whole frame, of the
  z-buffer passes alone (``mi_displace.slicing.rasterised.draw``) and of the frame with the
  slicing BSDF's self-shadows off: frame - (no self-shadows) is the self-shadow walk, the
  rest of the no-self-shadow frame beyond the passes is visibility and shading;
* per slice family, the polygons the self-shadow walk meets per walking sample (the sun's
  direction from every fragment the passes found and the light faces; mean, median, 95th
  percentile, maximum: its iterations, each a BVH query without the step tables), the BVH
  queries among them (the rest are closed-form steps, ``mi_displace.slicing.geometry.LayerStack``),
  and the iterations a SIMD packet of 16 neighbouring samples makes (the most of its
  lanes) over those of the lanes;
* the frame's kernels by execution time (``dr.JitFlag.KernelHistory``) with the labels of
  the symbolic loops and ifs they hold;
* the lever of the shape's ``rasterise=false`` (the slices walked by ray queries, as under
  ``path``, instead of rasterised before the frame): the frame walked at RES, and on the
  bench's fixed-cost film (``FIXED_RES``²) the frame drawn and walked, plain and with
  ``raster``'s ``freeze`` (a walked frame is recorded whole; a drawn one rasterises outside
  the recording), with the walked image's pixels that differ from the drawn one, and of a
  frozen frame the time of Dr.Jit's call itself (the recording's inputs traversed, its
  kernels replayed, the inputs assigned back)."""
import re
import statistics
import sys
import time
import types

import numpy as np

ROUNDS, REPS, KERNELS = 3, 5, 10


def main(direction: str = "best", res: str = "512") -> None:
    import drjit as dr
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load
    from mi_displace.slicing import rasterised, trace
    from mi_displace.slicing.sliced import FAMILIES

    scene, _ = load(scene_path("slicing_donut.xml"), mode="approximation", integrator="raster",
                    direction=direction, res=int(res))
    integrator = mi.load_dict({"type": "raster", "aa": 1})
    shape = next(s for s in scene.shapes() if hasattr(s, "raster_begin"))
    bsdf, volume, sensor = shape.bsdf(), shape.volume, scene.sensors()[0]

    def frame():
        dr.eval(mi.render(scene, integrator=integrator, spp=1))

    def passes():
        drawn = rasterised.draw(volume, sensor, 1)
        dr.eval(drawn.packed, drawn.found)

    def unshadowed():
        bsdf.self_shadows = False
        try:
            frame()
        finally:
            bsdf.self_shadows = True

    def walked():
        shape.rasterise = False
        try:
            frame()
        finally:
            shape.rasterise = True

    cases = {"frame": frame, "z-buffer passes": passes, "frame without self-shadows": unshadowed,
             "frame walked": walked}
    for step in cases.values():
        step()
    used = {fam: volume.counts[fam] for fam in FAMILIES[direction]}
    print(f"slicing_donut.xml direction={direction} at {res}^2, slices {used}")
    for _ in range(ROUNDS):
        times = {name: [] for name in cases}
        for _ in range(REPS):
            for name, step in cases.items():
                dr.sync_thread()
                start = time.perf_counter()
                step()
                dr.sync_thread()
                times[name].append(time.perf_counter() - start)
        med = {name: statistics.median(t) for name, t in times.items()}
        walk = med["frame"] - med["frame without self-shadows"]
        rest = med["frame without self-shadows"] - med["z-buffer passes"]
        print("  ".join(f"{name} {1e3 * t:.0f} ms" for name, t in med.items())
              + f"  | shares: self-shadow walk {walk / med['frame']:.2f}, passes "
              f"{med['z-buffer passes'] / med['frame']:.2f}, rest {rest / med['frame']:.2f}"
              f"; walked / drawn {med['frame walked'] / med['frame']:.2f}")

    # the self-shadow walk's iterations (polygons met) and BVH queries: the walk's loops
    # counted (trace's while_loop wrapped; its BVH query runs under the if labelled
    # "slicing_query", whose mask is the lanes that ask)
    drawn = rasterised.draw(volume, sensor, 1)
    hit = drawn.hit
    sun = next(e for e in scene.emitters() if e.class_name() == "DirectionalEmitter")
    wl = dr.normalize(-mi.Vector3f(sun.world_transform() @ mi.ScalarVector3f(0, 0, 1)))
    wl = wl + dr.zeros(mi.Vector3f, dr.width(hit.found))
    normal = volume.normal(hit)
    walking = drawn.covered & hit.found & (dr.dot(normal, wl) > 0)
    counts, asked = [], []

    def if_stmt(args, cond, true_fn, false_fn, **kwargs):
        if kwargs.get("label") == "slicing_query":
            asked.append(cond)
        return dr.if_stmt(args, cond, true_fn, false_fn, **kwargs)

    def counted(state, cond, body, **kwargs):
        kwargs.pop("labels", None)

        def step(*s):
            asked.clear()
            out = body(*s[:-2])
            queried = asked[-1] if asked else s[3]   # s[3]: the lanes still walking
            return (*out, s[-2] + 1, s[-1] + dr.select(queried, 1, 0))

        zero = dr.zeros(mi.UInt32, dr.width(state[3]))
        out = dr.while_loop((*state, zero, zero), lambda *s: cond(*s[:-2]), step, **kwargs)
        counts.append((out[-2], out[-1], state[3]))
        return out[:-2]

    trace.dr = types.SimpleNamespace(**{**{k: getattr(dr, k) for k in dir(dr) if not k.startswith("__")},
                                        "while_loop": counted, "if_stmt": if_stmt})
    try:
        dr.eval(volume.occluded(hit, normal, wl, walking))
    finally:
        trace.dr = dr
    for fam, (met, queries, lanes) in zip(FAMILIES[direction], counts):
        q, b, on = np.array(met), np.array(queries), np.array(lanes)
        packets = q[: len(q) // 16 * 16].reshape(-1, 16).max(1).sum() * 16
        print(f"family {fam}: {on.sum()} walking samples, polygons met mean {q[on].mean():.1f} median "
              f"{np.median(q[on]):.0f} p95 {np.percentile(q[on], 95):.0f} max {q.max()}, of them BVH "
              f"queries mean {b[on].mean():.1f}; packets of 16 / lanes {packets / q.sum():.2f}")

    dr.kernel_history()
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        dr.sync_thread()
        start = time.perf_counter()
        frame()
        dr.sync_thread()
        wall = time.perf_counter() - start
    history = dr.kernel_history()
    print(f"profiled frame {1e3 * wall:.0f} ms, {len(history)} launches, kernels "
          f"{sum(h['execution_time'] for h in history) / 1e3 / wall:.2f} of it; the largest:")
    for h in sorted(history, key=lambda h: -h["execution_time"])[:KERNELS]:
        ir = h.get("ir")
        text = ir.getvalue() if hasattr(ir, "getvalue") else str(ir or "")
        labels = sorted(set(re.findall(r"(?:raster|slicing)_[a-z_]+", text)))
        print(f"  {h['execution_time']:8.1f} ms  size {h['size']:>8}  {', '.join(labels) or h['type'].name}")
    fixed_cost(direction)


def fixed_cost(direction: str) -> None:
    """The frame drawn and walked (the shape's ``rasterise``), plain and frozen, on the
    bench's fixed-cost film: median wall ms of frames drawn alternately."""
    import drjit as dr
    import mitsuba as mi

    from mi_displace.bench.frames import FIXED_RES
    from mi_displace.core.resources import scene_path
    from mi_displace.render.scene import load

    scene, _ = load(scene_path("slicing_donut.xml"), mode="approximation", integrator="raster",
                    direction=direction, res=FIXED_RES)
    shape = next(s for s in scene.shapes() if hasattr(s, "raster_begin"))
    integrators = {freeze: mi.load_dict({"type": "raster", "aa": 1, "freeze": freeze})
                   for freeze in (False, True)}
    cases = [(freeze, drawn) for freeze in (False, True) for drawn in (True, False)]
    name = lambda case: f"{'frozen' if case[0] else 'plain'} {'drawn' if case[1] else 'walked'}"

    def frame(case):
        shape.rasterise = case[1]
        try:
            return mi.render(scene, integrator=integrators[case[0]], spp=1)
        finally:
            shape.rasterise = True

    frozen = integrators[True].frozen   # mi_displace.render.raster.FrozenFrames
    replay, calls = frozen.function, []

    def timed(*args):   # Dr.Jit's own call: the inputs traversed, the kernels replayed, the
        dr.sync_thread()   # inputs assigned back
        start = time.perf_counter()
        result = replay(*args)
        dr.sync_thread()
        calls.append(time.perf_counter() - start)
        return result

    frozen.function = timed
    images = {case: np.array(frame(case)) for case in cases * 2}   # the second: replays
    assert all(np.isfinite(image).all() for image in images.values())
    differ = np.abs(images[(False, False)] - images[(False, True)]).max(-1)
    print(f"fixed cost at {FIXED_RES}^2: walked vs drawn: {int((differ > 0).sum())} of "
          f"{differ.size} pixels differ (max {differ.max():.2g}); frozen = plain: walked "
          f"{np.array_equal(images[(True, False)], images[(False, False)])}, drawn "
          f"{np.array_equal(images[(True, True)], images[(False, True)])}")
    for _ in range(ROUNDS):
        times = {case: [] for case in cases}
        replays = {case: [] for case in cases if case[0]}
        for _ in range(3 * REPS):
            for case in cases:
                calls.clear()
                dr.sync_thread()
                start = time.perf_counter()
                dr.eval(frame(case))
                dr.sync_thread()
                times[case].append(time.perf_counter() - start)
                if case[0]:
                    replays[case] += calls
        print("  ".join(f"{name(case)} {1e3 * statistics.median(t):.1f} ms" for case, t in times.items())
              + "  | of a frozen frame, Dr.Jit's call: " + "  ".join(
                  f"{name(case).split()[1]} {1e3 * statistics.median(t):.1f} ms" for case, t in replays.items()))


if __name__ == "__main__":
    main(*sys.argv[1:])
