"""Tile layouts (HDDM §3.2, §5): where each instance D_ij of a tile lies in the (u, v)
domain of the base surface.

A layout gives, per placed tile, the offset (u0, v0) of its canonical origin and which
tile of the tile set it uses; all tiles share one uv ``size`` (su, sv): canonical x maps to
u = u0 + su x, y to v = v0 + sv y.  Gaps in u and v shrink each tile inside its cell
(fractions of the cell), a gap in w lifts every tile off the surface (``w_offset``, in
object units, applied by the mapping).  A global offset (u0, v0) shifts the whole layout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LAYOUTS = ("rect", "hex", "alternate", "random")


@dataclass
class Layout:
    """Placed tiles.

    Attributes:
        offsets: (I, 2) float64 (u0, v0) of each tile [uv units].
        tile_index: (I,) int64 index into the tile set.
        size: (su, sv) uv extent of the canonical unit square.
        cells: (n, m) tiles along u and v (before pruning).
        chart: (I,) int64 UV chart each tile belongs to (mesh bases,
            :func:`mi_displace.ddm.charts.assign_charts`), else None.
    """

    offsets: np.ndarray
    tile_index: np.ndarray
    size: tuple[float, float]
    cells: tuple[int, int]
    chart: np.ndarray | None = None

    @property
    def count(self) -> int:
        return len(self.offsets)

    def subset(self, keep: np.ndarray) -> "Layout":
        """The layout restricted to the tiles where ``keep`` (bool (I,)) is True."""
        return Layout(self.offsets[keep], self.tile_index[keep], self.size, self.cells,
                      None if self.chart is None else self.chart[keep])


def _check_int(name: str, value, low: int = 1) -> int:
    if int(value) != value or value < low:
        raise ValueError(f"ddm: '{name}' must be an integer >= {low}, got {value!r}")
    return int(value)


def _check_gap(name: str, value) -> float:
    if not (math.isfinite(value) and 0 <= value < 1):
        raise ValueError(f"ddm: '{name}' must lie in [0, 1) (fraction of a cell), got {value!r}")
    return float(value)


def make_layout(kind: str, tiles_u: int, tiles_v: int, n_tiles: int = 1, gap_u: float = 0.0,
                gap_v: float = 0.0, u0: float = 0.0, v0: float = 0.0, seed: int = 0,
                pattern: list[list[int]] | None = None) -> Layout:
    """Build a layout.

    Args:
        kind: ``rect`` (n x m cells, tile k = 0), ``hex`` (rows of pointy-top hexagons
            at pitch 1/m, odd rows shifted by half a cell; a tile's v extent is 4/3 of the
            row pitch so that the hexagons interlock; they are regular on the surface when
            m = (2 / sqrt 3) n extent_v / extent_u), ``alternate`` (semi-regular: tile (i + j) mod
            ``n_tiles``, or ``pattern[j % rows][i % cols]``), ``random`` (seeded uniform
            choice among ``n_tiles``).
        tiles_u, tiles_v: cells along u and v (n, m).
        n_tiles: size of the tile set.
        gap_u, gap_v: empty fraction of each cell in u / v (tile shrunk, centred).
        u0, v0: offset of the whole layout [uv units].
        seed: seed of ``random``.
        pattern: optional rows of tile indices for ``alternate``.
    """
    if kind not in LAYOUTS:
        raise ValueError(f"ddm: unknown 'layout' {kind!r}; expected one of {', '.join(LAYOUTS)}")
    n, m = _check_int("tiles_u", tiles_u), _check_int("tiles_v", tiles_v)
    gu, gv = _check_gap("gap_u", gap_u), _check_gap("gap_v", gap_v)
    for name, val in (("u0", u0), ("v0", v0)):
        if not math.isfinite(val):
            raise ValueError(f"ddm: '{name}' must be finite, got {val!r}")
    j, i = np.meshgrid(np.arange(m), np.arange(n), indexing="ij")   # row-major over v, u
    i, j = i.ravel(), j.ravel()
    cu, cv = 1.0 / n, 1.0 / m
    if kind == "hex":
        # rows at pitch cv; a hexagon of height h interlocks with rows 3/4 h apart
        su = cu * (1 - gu)
        sv = cv * 4 / 3 * (1 - gv)
        ou = i * cu + (j % 2) * 0.5 * cu + 0.5 * gu * cu
        ov = j * cv + 0.5 * (cv - sv)
    else:
        su, sv = cu * (1 - gu), cv * (1 - gv)
        ou = i * cu + 0.5 * gu * cu
        ov = j * cv + 0.5 * gv * cv
    if kind == "alternate":
        if pattern is not None:
            pat = np.asarray(pattern, np.int64)
            if pat.ndim != 2 or pat.size == 0 or pat.min() < 0 or pat.max() >= n_tiles:
                raise ValueError(f"ddm: 'pattern' must be rows of tile indices in 0..{n_tiles - 1}")
            index = pat[j % pat.shape[0], i % pat.shape[1]]
        else:
            index = (i + j) % n_tiles
    elif kind == "random":
        index = np.random.default_rng(seed).integers(0, n_tiles, len(i))
    else:
        index = np.zeros(len(i), np.int64)
    offsets = np.stack([ou + u0, ov + v0], 1)
    return Layout(offsets, index.astype(np.int64), (su, sv), (n, m))
