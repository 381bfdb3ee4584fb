"""Detail tiles D in canonical tile coordinates (HDDM §3.1): x, y in [0, 1] across the tile,
z = w above the base surface (in units of the plugin's ``height``).

A :class:`Tile` is an indexed triangle mesh (NumPy, one-off preprocessing) with unit vertex
normals and the two precomputed tangent directions T1, T2 of §3.2 (T1 x T2 = N).  Tiles
need not be height fields: the built-in procedural tiles are

* ``thorn``   — a horn that curls over past the horizontal on a square ground plate
  (not a function of (x, y)); ``flower`` has the *same topology* (metamorphosis, §4.2);
* ``chain``   — two interlinked stadium rings (genus 2 in all, not homeomorphic to the base);
* ``hair``    — 8 open, thin threads (non-covering, 384 triangles as the paper's hair tile);
* ``hexagon`` — a bevelled hexagonal plateau that tiles the plane in the ``hex`` layout;
* ``stone``   — a rounded, seeded-irregular stone filling its cell (``stone:SEED``).

Mesh files (OBJ / PLY) are read as they are, already in tile coordinates.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Tile:
    """One detail tile D.

    Attributes:
        name: what it is (built-in name or file path).
        positions: (V, 3) float32 canonical coordinates (x, y across the tile, z = w).
        normals: (V, 3) float32 unit normals.
        faces: (F, 3) uint32 triangles (counter-clockwise seen from the normal side).
        tangents: (V, 2, 3) float32 unit T1, T2 with T1 x T2 = N (HDDM §3.2).
    """

    name: str
    positions: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    tangents: np.ndarray

    @property
    def vertex_count(self) -> int:
        return len(self.positions)

    @property
    def face_count(self) -> int:
        return len(self.faces)

    @property
    def nbytes(self) -> int:
        """Bytes HDDM stores for this tile: positions, normals, 2 tangents (float32), faces."""
        return self.vertex_count * 12 * 4 + self.face_count * 12

    def compatible_with(self, other: "Tile") -> bool:
        """Same vertex count and identical faces (eq. 3 interpolates vertex by vertex)."""
        return (self.vertex_count == other.vertex_count
                and np.array_equal(self.faces, other.faces))


def tangent_frames(normals: np.ndarray) -> np.ndarray:
    """(V, 2, 3) unit T1, T2 orthogonal to each unit normal, T1 x T2 = N."""
    n = np.asarray(normals, np.float64)
    axis = np.where((np.abs(n[:, 0]) < 0.6)[:, None], [[1.0, 0, 0]], [[0, 1.0, 0]])
    t1 = np.cross(axis, n)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return np.stack([t1, t2], 1).astype(np.float32)


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals; isolated / zero-area vertices get +z."""
    p = np.asarray(positions, np.float64)
    f = np.asarray(faces, np.int64)
    fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    acc = np.zeros_like(p)
    for k in range(3):
        np.add.at(acc, f[:, k], fn)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    return np.where(length > 1e-20, acc / np.maximum(length, 1e-30), [[0, 0, 1.0]]).astype(np.float32)


def make_tile(name: str, positions, faces, normals=None) -> Tile:
    """Validate and complete a tile (normals from faces when not given).

    Raises:
        ValueError: empty tile, non-finite values, bad face indices, or zero size
            (all vertices coincide in x and y).
    """
    p = np.asarray(positions, np.float32).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    if len(p) == 0 or len(f) == 0:
        raise ValueError(f"tile {name!r} is empty ({len(p)} vertices, {len(f)} faces)")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"tile {name!r} has NaN/Inf vertex positions")
    if f.min() < 0 or f.max() >= len(p):
        raise ValueError(f"tile {name!r}: face indices outside 0..{len(p) - 1}")
    span = p.max(0) - p.min(0)
    if not (span[0] > 1e-6 or span[1] > 1e-6):
        raise ValueError(f"tile {name!r} has zero size: all vertices share one (x, y) "
                         f"(extent {span.tolist()}); tiles live in x, y in [0, 1]")
    n = vertex_normals(p, f) if normals is None else np.asarray(normals, np.float32).reshape(-1, 3)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 1e-12, n / np.maximum(length, 1e-30), [[0, 0, 1.0]]).astype(np.float32)
    return Tile(name, p, n, f.astype(np.uint32), tangent_frames(n))


def merge(name: str, parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (positions, faces) parts into one indexed mesh."""
    ps, fs, base = [], [], 0
    for p, f in parts:
        ps.append(p)
        fs.append(f + base)
        base += len(p)
    return np.concatenate(ps), np.concatenate(fs)


def grid_faces(rows: int, cols: int, wrap_cols: bool = False) -> np.ndarray:
    """Two triangles per quad of a rows x cols vertex grid (row-major), optionally wrapping
    the columns (tubes).  Winding: (r, c), (r, c+1), (r+1, c+1) — i.e. d/dc x d/dr."""
    cq = cols if wrap_cols else cols - 1
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cq), indexing="ij")
    r, c = r.ravel(), c.ravel()
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    d, e = a + cols, b + cols
    return np.concatenate([np.stack([a, b, e], 1), np.stack([a, e, d], 1)])


def plate(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n quad grid covering [0, 1]^2 at w = 0, facing +z."""
    g = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(g, g)            # rows along y
    p = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    return p, grid_faces(n + 1, n + 1)


def tube(spine: np.ndarray, radius: np.ndarray, sides: int, frame_up=(0.0, 1.0, 0.0),
         tip: bool = False, petals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A tube along ``spine`` (S, 3) with ``radius`` (S,), ``sides`` around, normals outward.

    With ``tip`` the last spine point becomes one apex vertex (a cone tip).  ``petals``
    (S,) scales a cos(5 phi) modulation of the radius (the flower tile).
    """
    spine = np.asarray(spine, np.float64)
    tangent = np.gradient(spine, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    up = np.asarray(frame_up, np.float64)
    side = np.cross(tangent, up)
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    other = np.cross(side, tangent)
    phi = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    rings = spine if not tip else spine[:-1]
    rr = radius[: len(rings), None] * (1 + (0 if petals is None else petals[: len(rings), None])
                                      * np.cos(5 * phi)[None])
    p = (rings[:, None] + rr[..., None] * (np.cos(phi)[None, :, None] * side[: len(rings), None]
                                          + np.sin(phi)[None, :, None] * other[: len(rings), None]))
    p = p.reshape(-1, 3)
    f = grid_faces(len(rings), sides, wrap_cols=True)
    if tip:
        apex = len(p)
        p = np.concatenate([p, spine[-1:]])
        last = (len(rings) - 1) * sides + np.arange(sides)
        f = np.concatenate([f, np.stack([last, (last + 1 - (len(rings) - 1) * sides) % sides
                                         + (len(rings) - 1) * sides, np.full(sides, apex)], 1)])
    # orient outward: the first ring's face normals must point away from the spine
    pf = p[f]
    fn = np.cross(pf[:, 1] - pf[:, 0], pf[:, 2] - pf[:, 0])
    out = pf.mean(1) - spine[np.minimum(f[:, 0] // sides, len(spine) - 1)]
    if np.sum(np.einsum("ij,ij->i", fn, out)) < 0:
        f = f[:, ::-1]
    return p, f


def thorn(rings: int = 8, sides: int = 14, curl: float = 2.4) -> Tile:
    """A horn on a ground plate: it rises and curls over past horizontal (tip below its
    highest point), so it is *not* a height field.  ``curl`` in radians."""
    s = np.linspace(0.0, 1.0, rings + 1)
    ang = curl * s
    arc = 0.55 / curl * 1.6
    spine = np.stack([0.3 + arc * (1 - np.cos(ang)), np.full_like(s, 0.5), arc * np.sin(ang)], 1)
    radius = 0.2 * (1 - s) ** 0.9
    horn = tube(spine, radius, sides, tip=True)
    return make_tile("thorn", *merge("thorn", [plate(), horn]))


def flower(rings: int = 8, sides: int = 14) -> Tile:
    """Metamorphosis partner of :func:`thorn` (same vertices and faces): a straight stem
    opening into five petals."""
    s = np.linspace(0.0, 1.0, rings + 1)
    spine = np.stack([np.full_like(s, 0.5), np.full_like(s, 0.5), 0.8 * s], 1)
    radius = 0.06 + 0.3 * s ** 3
    petals = 0.6 * s ** 2
    bloom = tube(spine, radius, sides, tip=True, petals=petals)
    bloom[0][-1] = [0.5, 0.5, 0.55]   # apex sinks into the cup
    return make_tile("flower", *merge("flower", [plate(), bloom]))


def _stadium(center, half_length: float, radius: float, normal_axis: int, long_axis: int,
             n_path: int) -> np.ndarray:
    """Closed stadium curve (two half circles joined by straight runs), (n_path, 3)."""
    t = np.linspace(0, 1, n_path, endpoint=False)
    perim = 4 * half_length + 2 * np.pi * radius
    d = t * perim
    pts = np.zeros((n_path, 2))
    seg = [2 * half_length, np.pi * radius, 2 * half_length, np.pi * radius]
    edges = np.cumsum([0] + seg)
    k = np.searchsorted(edges, d, side="right") - 1
    loc = d - edges[k]
    a = loc / radius
    pts[k == 0] = np.stack([-half_length + loc[k == 0], np.full((k == 0).sum(), -radius)], 1)
    pts[k == 1] = np.stack([half_length + radius * np.sin(a[k == 1]), -radius * np.cos(a[k == 1])], 1)
    pts[k == 2] = np.stack([half_length - loc[k == 2], np.full((k == 2).sum(), radius)], 1)
    pts[k == 3] = np.stack([-half_length - radius * np.sin(a[k == 3]), radius * np.cos(a[k == 3])], 1)
    out = np.tile(np.asarray(center, np.float64), (n_path, 1))
    other = [a for a in range(3) if a not in (normal_axis, long_axis)][0]
    out[:, long_axis] += pts[:, 0]
    out[:, other] += pts[:, 1]
    return out


def _ring(curve: np.ndarray, thickness: float, sides: int, plane_normal) -> tuple[np.ndarray, np.ndarray]:
    """A closed tube of radius ``thickness`` around a closed planar ``curve``."""
    n_path = len(curve)
    tangent = np.roll(curve, -1, 0) - np.roll(curve, 1, 0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    b = np.broadcast_to(np.asarray(plane_normal, np.float64), tangent.shape)
    side = np.cross(tangent, b)
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    phi = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    p = curve[:, None] + thickness * (np.cos(phi)[None, :, None] * side[:, None]
                                      + np.sin(phi)[None, :, None] * b[:, None])
    # rows = path (wrapping), columns = around the tube (wrapping)
    rows = np.arange(n_path)
    r, c = np.meshgrid(rows, np.arange(sides), indexing="ij")
    a = r * sides + c
    bb = r * sides + (c + 1) % sides
    d = ((r + 1) % n_path) * sides + c
    e = ((r + 1) % n_path) * sides + (c + 1) % sides
    f = np.concatenate([np.stack([a.ravel(), d.ravel(), e.ravel()], 1),
                        np.stack([a.ravel(), e.ravel(), bb.ravel()], 1)])
    pts = p.reshape(-1, 3)
    pf = pts[f]
    fn = np.cross(pf[:, 1] - pf[:, 0], pf[:, 2] - pf[:, 0])
    out = pf.mean(1) - curve[f[:, 0] // sides]
    if np.sum(np.einsum("ij,ij->i", fn, out)) < 0:
        f = f[:, ::-1]
    return pts, f


def chain(n_path: int = 16, sides: int = 8) -> Tile:
    """Two interlinked links: one lying flat across the tile (along x), one standing in the
    x-z plane at the tile's right edge, through which the next tile's flat link passes."""
    flat = _ring(_stadium((0.5, 0.5, 0.12), 0.22, 0.12, 2, 0, n_path), 0.04, sides, (0, 0, 1))
    stand = _ring(_stadium((1.0, 0.5, 0.12), 0.1, 0.1, 1, 0, n_path), 0.04, sides, (0, 1, 0))
    return make_tile("chain", *merge("chain", [flat, stand]))


def hair(threads: int = 8, segments: int = 8, seed: int = 7) -> Tile:
    """``threads`` open, thin (3-sided) strands rising and bending from seeded roots;
    non-covering: the base shows between them.  8 x 8 x 3 x 2 = 384 triangles."""
    rng = np.random.default_rng(seed)
    roots = rng.uniform(0.1, 0.9, (threads, 2))
    dirs = rng.uniform(0, 2 * np.pi, threads)
    parts = []
    s = np.linspace(0, 1, segments + 1)
    for k in range(threads):          # a handful of threads: per-thread NumPy, no per-vertex loop
        lean = 0.45 * s ** 2
        spine = np.stack([roots[k, 0] + lean * np.cos(dirs[k]), roots[k, 1] + lean * np.sin(dirs[k]),
                          0.9 * s - 0.25 * s ** 2], 1)
        parts.append(tube(spine, np.full(segments + 1, 0.012), 3, frame_up=(0.3, 0.2, 1.0)))
    return make_tile("hair", *merge("hair", parts))


HEX_ASPECT = 2 / np.sqrt(3)   # height / width of a pointy-top regular hexagon


def hexagon(rings: int = 6, per_side: int = 6, bevel: float = 0.25) -> Tile:
    """A pointy-top hexagon inscribed in [0, 1]^2 (x spans the width, y the height; in a
    layout the tile's v extent is HEX_ASPECT times its u extent): a plateau at w = 1 with a
    bevel of width ``bevel`` (fraction of the radius) down to w = 0 at the outline."""
    corners = np.array([[np.cos(a), np.sin(a)] for a in np.pi / 2 + np.arange(6) * np.pi / 3])
    t = np.arange(per_side) / per_side
    outline = np.concatenate([corners[k] + t[:, None] * (corners[(k + 1) % 6] - corners[k])
                              for k in range(6)])                   # (6 * per_side, 2), radius 1
    m = len(outline)
    radii = np.linspace(1.0, 0.0, rings + 1)[:-1]
    height = np.clip((1 - radii) / bevel, 0, 1)
    height = 0.5 - 0.5 * np.cos(np.pi * height)                     # smooth bevel
    ring_pts = radii[:, None, None] * outline[None]
    xy = np.concatenate([ring_pts.reshape(-1, 2), [[0.0, 0.0]]])
    z = np.concatenate([np.repeat(height, m), [1.0]])
    f = grid_faces(rings, m, wrap_cols=True)
    centre = len(xy) - 1
    last = (rings - 1) * m + np.arange(m)
    f = np.concatenate([f, np.stack([last, (rings - 1) * m + (np.arange(m) + 1) % m,
                                     np.full(m, centre)], 1)])
    # map radius-1 hexagon (width sqrt(3), height 2) onto [0, 1]^2
    pos = np.stack([0.5 + xy[:, 0] / np.sqrt(3), 0.5 + xy[:, 1] / 2, z], 1)
    pf = pos[f]
    fn = np.cross(pf[:, 1] - pf[:, 0], pf[:, 2] - pf[:, 0])
    if fn[:, 2].sum() < 0:
        f = f[:, ::-1]
    return make_tile("hexagon", pos, f)


def stone(seed: int = 0, n: int = 12) -> Tile:
    """A rounded stone filling its cell: a superellipse dome with seeded lumps, closed by
    a skirt down to w = 0 at the cell border.  All seeds share one topology."""
    rng = np.random.default_rng(seed)
    g = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(g, g)
    cx, cy = 2 * x - 1, 2 * y - 1
    e = rng.uniform(2.5, 5.0)
    r = (np.abs(cx) ** e + np.abs(cy) ** e) ** (1 / e)
    dome = np.sqrt(np.clip(1 - r ** 2, 0, 1))
    lumps = sum(rng.uniform(0.05, 0.12) * np.cos(rng.uniform(1, 3) * np.pi * cx + rng.uniform(0, 6))
                * np.cos(rng.uniform(1, 3) * np.pi * cy + rng.uniform(0, 6)) for _ in range(3))
    z = np.clip(rng.uniform(0.6, 1.0) * dome * (1 + lumps), 0, None)
    p = np.stack([0.04 + 0.92 * x.ravel(), 0.04 + 0.92 * y.ravel(), z.ravel()], 1)
    return make_tile(f"stone:{seed}", p, grid_faces(n + 1, n + 1))


BUILTIN = {"thorn": thorn, "flower": flower, "chain": chain, "hair": hair,
           "hexagon": hexagon, "stone": stone}


def load_tile_file(path: str | os.PathLike) -> Tile:
    """A tile from an OBJ / PLY file, taken as it is (canonical tile coordinates).

    Raises:
        FileNotFoundError: no such file.  ValueError: wrong suffix, unreadable, empty.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"ddm: tile file {str(path)!r} does not exist")
    if path.suffix.lower() not in (".obj", ".ply"):
        raise ValueError(f"ddm: tile file {str(path)!r} must be .obj or .ply")
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many types for broken files
        raise ValueError(f"ddm: tile file {str(path)!r} could not be read: {e}") from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64)
    return make_tile(str(path), np.asarray(getattr(mesh, "vertices", np.zeros((0, 3)))), faces)


def get_tile(spec: str) -> Tile:
    """A built-in tile by name (``stone:SEED`` for a seeded stone) or a mesh file path."""
    spec = str(spec).strip()
    name, _, arg = spec.partition(":")
    if name in BUILTIN:
        if arg:
            if name != "stone" or not arg.isdigit():
                raise ValueError(f"ddm: tile {spec!r}: only 'stone:SEED' takes an argument")
            return stone(int(arg))
        return BUILTIN[name]()
    if spec.lower().endswith((".obj", ".ply")) or os.sep in spec:
        return load_tile_file(spec)
    raise ValueError(f"ddm: unknown tile {spec!r}; expected one of {', '.join(sorted(BUILTIN))}, "
                     "'stone:SEED' or an .obj/.ply file")
