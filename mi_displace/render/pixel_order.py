"""The order of a GPU-style frame's pixels among its lanes: 4 x 4 pixel tiles.

Every frame of :mod:`mi_displace.render.raster` (its rays, :func:`raster.pixel_rays`; its
z-buffer, :func:`mi_displace.render.zbuffer.sample_index`; the slicing shapes' rasterised
slices; the volume slicer) numbers its pixels tile by tile: bands of :data:`TILE` rows, each
cut into tiles of :data:`TILE` columns (the last band and the last tile of a band narrower
when the film's sides are not multiples of it), a tile's pixels row by row.  A SIMD packet
of 16 lanes is then 4 x 4 neighbouring pixels instead of 16 of one row, so the Embree
packet queries of its rays meet fewer acceleration-structure nodes: the same hits in less
time (the raster frame at 512², ``python scripts/constant_ab.py render.pixel_order.TILE 1 4
SCENE``, ``TILE`` 1 being row order: the sliced donut ``best`` 0.80-0.81x, ``a`` 0.86-0.87x,
the HDDM thorns 0.79x, the restored bunny 0.81x, VDM 0.96-0.97x; images identical).  Against
the frames before this module, 21 of 22 packaged scene / option / size cases at 96² and
101² are identical; the restored bunny differs in 145 of 9216 pixels by at most 6e-8
(absolute), with ``TILE`` 1 too: its frame's kernels compile to other float rounding, the
order changes nothing.  :func:`image` puts
the pixels back in rows.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Pixels per tile side (1: row order; 8 measured slower than 4 on the sliced donut, 0.83x
#: against 0.80x of row order).
TILE = 4


def _short(width: int, height: int) -> tuple[int, int]:
    """Columns of a band's last tile and rows of the last band (TILE unless the film's side
    is not a multiple of it)."""
    return width % TILE or TILE, height % TILE or TILE


def pixel_of(lane: mi.UInt32, width: int, height: int) -> tuple[mi.UInt32, mi.UInt32]:
    """Pixel (x, y) of each frame lane ``lane`` in [0, width x height).

    Every division is by a constant (a tile's side, a band's lanes, the short sides), each
    side chosen per lane: libLLVM 19.1 crashes compiling a division by a per-lane divisor
    here (``scripts/repro/llvm_division_crash.py``, docs/platform.md)."""
    cols_short, rows_short = _short(width, height)
    band = lane // (TILE * width)   # every band before the last holds TILE x width lanes
    rest = lane - band * (TILE * width)
    last_band = band == (height - 1) // TILE
    tile = dr.select(last_band, rest // (TILE * rows_short), rest // (TILE * TILE))
    inside = rest - tile * dr.select(last_band, TILE * rows_short, TILE * TILE)
    last_tile = tile == (width - 1) // TILE
    x = dr.select(last_tile, inside % cols_short, inside % TILE)
    y = dr.select(last_tile, inside // cols_short, inside // TILE)
    return tile * TILE + x, band * TILE + y


def lane_of(x: mi.UInt32, y: mi.UInt32, width: int, height: int) -> mi.UInt32:
    """Frame lane of pixel (x, y) (the inverse of :func:`pixel_of`)."""
    cols_short, rows_short = _short(width, height)
    band, tile = y // TILE, x // TILE
    rows = dr.select(band == (height - 1) // TILE, mi.UInt32(rows_short), TILE)
    cols = dr.select(tile == (width - 1) // TILE, mi.UInt32(cols_short), TILE)
    return band * (TILE * width) + tile * (TILE * rows) + (y % TILE) * cols + x % TILE


def rows(values, width: int, height: int):
    """``values`` (one entry per pixel in frame order, any Dr.Jit type) in row order."""
    dr.eval(values)   # one kernel for all components (each gather would evaluate its own)
    i = dr.arange(mi.UInt32, width * height)
    return dr.gather(type(values), values, lane_of(i % width, i // width, width, height))


def image(L: mi.Color3f, width: int, height: int) -> mi.TensorXf:
    """The (height, width, 3) image of per-pixel colours ``L`` in frame order."""
    return mi.TensorXf(dr.ravel(rows(L, width, height)), (height, width, 3))
