"""Experiment, in ONE process: a raster frame whose samples are ordered by T x T pixel tiles
instead of row by row, against the frame as drawn (rows).  The order is a contract of
``mi_displace.render.raster.pixel_rays`` (the lanes of every frame kernel) with
``mi_displace.render.zbuffer.sample_index`` / ``sample_xy`` (the z-buffer's sample order)
and ``raster.render``'s final reshape; this script swaps all of them in (monkeypatched; the
library is unchanged), un-permutes the tiled image, compares the two images bit for bit,
then prints ROUNDS x (median wall seconds of REPS frames drawn alternately, rows and tiles)
and their ratio.  Why: a SIMD packet of 16 lanes is 16 pixels of a row in row order, 4 x 4
pixels in tile order, so the Embree packet queries of the frame's rays (the slicing
self-shadow walk above all) meet fewer BVH nodes per packet.

    ./.venv/bin/python scripts/tiled_order_ab.py SCENE [name=value ...]

Environment: TILE (4), REPS (7), ROUNDS (3).  The film's sides must be multiples of TILE."""
import os
import statistics
import sys
import time

import numpy as np


def main(scene_file: str, *params: str) -> None:
    import drjit as dr
    import mitsuba as mi

    import mi_displace
    mi_displace.init()
    from mi_displace.core.resources import scene_path
    from mi_displace.render import raster, zbuffer
    from mi_displace.render.scene import load
    from mi_displace.slicing import rasterised

    T = int(os.environ.get("TILE", 4))
    values = {"integrator": "raster", "res": 512, "mode": "approximation"}
    values.update(p.split("=", 1) for p in params)
    scene, _ = load(scene_path(scene_file), **values)
    integrator = mi.load_dict({"type": "raster", "aa": 1})
    plain = {"pixel_rays": raster.pixel_rays, "render": raster.render,
             "sample_index": zbuffer.sample_index, "sample_xy": zbuffer.sample_xy}

    def tile_of(px, py, w):   # pixel (px, py) -> its place in tile order
        tiles_x = w // T
        return ((py // T) * tiles_x + px // T) * (T * T) + (py % T) * T + px % T

    def pixel_of(p, w):   # the inverse
        tiles_x = w // T
        tile, sub = p // (T * T), p % (T * T)
        return (tile % tiles_x) * T + sub % T, (tile // tiles_x) * T + sub // T

    def pixel_rays(sensor, aa):
        w, h = sensor.film().crop_size()
        assert w % T == 0 and h % T == 0, "film sides must be multiples of TILE"
        n = aa * aa
        idx = dr.arange(mi.UInt32, w * h * n)
        pixel, sub = idx // n, idx % n
        px, py = pixel_of(pixel, w)
        x = mi.Float(px) + (mi.Float(sub % aa) + 0.5) / aa
        y = mi.Float(py) + (mi.Float(sub // aa) + 0.5) / aa
        ray, weight = sensor.sample_ray(0.0, 0.5, mi.Point2f(x / w, y / h), mi.Point2f(0.5))
        return ray, mi.Color3f(weight), int(w), int(h)

    def sample_index(view, X, Y, aa):
        w = view.width // aa
        return tile_of(X // aa, Y // aa, w) * (aa * aa) + (Y % aa) * aa + X % aa

    def sample_xy(view, index, aa):
        n, w = aa * aa, view.width // aa
        px, py = pixel_of(index // n, w)
        sub = index % n
        return px * aa + sub % aa, py * aa + sub // aa

    def render(scene, sensor, *args, **kwargs):
        image = plain["render"](scene, sensor, *args, **kwargs)   # pixels in tile order
        h, w = image.shape[0], image.shape[1]
        i = dr.arange(mi.UInt32, w * h)
        src = tile_of(i % w, i // w, w)
        out = dr.gather(mi.Float, image.array, dr.repeat(src, 3) * 3 + dr.tile(dr.arange(mi.UInt32, 3), w * h))
        return mi.TensorXf(out, (h, w, 3))

    tiled = {"pixel_rays": pixel_rays, "render": render, "sample_index": sample_index,
             "sample_xy": sample_xy}

    def use(which):
        table = plain if which == "rows" else tiled
        raster.pixel_rays, raster.render = table["pixel_rays"], table["render"]
        rasterised.pixel_rays = table["pixel_rays"]
        zbuffer.sample_index, zbuffer.sample_xy = table["sample_index"], table["sample_xy"]

    def frame(which):
        use(which)
        try:
            return np.asarray(mi.render(scene, integrator=integrator, spp=1), np.float32)
        finally:
            use("rows")

    a, b = frame("rows"), frame("tiles")
    print(f"{scene_file} {' '.join(params)}: {T}x{T} tiles: identical {np.array_equal(a, b)}, "
          f"max |difference| {float(np.abs(a - b).max()):.3g}, finite {bool(np.isfinite(b).all())}, "
          f"mean {float(b.mean()):.4f}")
    reps, rounds = int(os.environ.get("REPS", 7)), int(os.environ.get("ROUNDS", 3))
    for _ in range(rounds):
        times = {"rows": [], "tiles": []}
        for _ in range(reps):
            for which in times:
                dr.sync_thread()
                start = time.perf_counter()
                frame(which)
                dr.sync_thread()
                times[which].append(time.perf_counter() - start)
        old, new = statistics.median(times["rows"]), statistics.median(times["tiles"])
        print(f"rows {old:.4f} s  tiles {new:.4f} s  tiles/rows {new / old:.3f}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(*sys.argv[1:])
