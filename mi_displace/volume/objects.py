"""Object volumes O_j (§4): scalar fields on a voxel grid placed in a world-space box.

An :class:`ObjectVolume` holds the density normalised to [0, 1] as a float32 NumPy array of
shape ``(nz, ny, nx)`` (x varies fastest, as in the raw files) and the world box
``[bbox_min, bbox_max]`` it fills (voxel i spans ``[min + i h, min + (i+1) h]``).  Its Dr.Jit
textures are the object texture O_j (trilinear, zero outside the box) and the precomputed
gradient texture ∇O_j (central differences in world units, §4.3).

Sources: raw + JSON sidecar (:func:`load_raw`), Mitsuba ``.vol`` grids (:func:`load_vol`),
NumPy arrays (:meth:`ObjectVolume.from_array`) and a procedural field with hidden inner
structure (:func:`piggy_bank`: a hollow shell with coins inside, like the paper's Fig. 1).
"""
from __future__ import annotations

import json
import struct
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

#: Most voxels an object volume may have (refused before anything is allocated).
MAX_VOXELS = 512 ** 3
#: NumPy dtypes a raw file may hold (sidecar ``dtype`` names).
RAW_DTYPES = {"uint8": "u1", "uint16": "u2", "int16": "i2", "uint32": "u4", "float32": "f4"}


def check_resolution(shape, what: str, minimum: int = 1, limit: int = MAX_VOXELS) -> tuple[int, ...]:
    """Validate a 3-D grid resolution: three integers >= ``minimum``, at most ``limit`` voxels
    (default :data:`MAX_VOXELS`), else a ``ValueError`` starting with ``what``."""
    shape = tuple(int(s) for s in shape)
    if len(shape) != 3 or any(s < minimum for s in shape):
        sizes = "positive sizes" if minimum == 1 else f"integers >= {minimum}"
        raise ValueError(f"{what}: expected three {sizes}, got {shape}")
    if int(np.prod(shape, dtype=np.int64)) > limit:
        raise ValueError(f"{what}: {shape} is {np.prod(shape, dtype=np.int64):,} voxels, more than "
                         f"the limit of {limit:,}")
    return shape


def default_box(shape_zyx, spacing=(1.0, 1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """World box of a grid: centred at the origin, longest side 1, aspect from dims x spacing."""
    size = np.array(shape_zyx[::-1], float) * np.asarray(spacing, float)
    size = size / size.max()
    return -0.5 * size, 0.5 * size


class ObjectVolume:
    """A scalar object volume O_j with its gradient texture (module docstring).

    Args:
        data: density, shape ``(nz, ny, nx)``, finite; normalised to [0, 1] by ``value_range``.
        bbox_min, bbox_max: world box (3,) the grid fills.
        value_range: (lo, hi) mapped to (0, 1); default: the data's min and max.
        name: what the volume is (error messages).
    """

    def __init__(self, data, bbox_min=None, bbox_max=None, value_range=None, name="volume"):
        data = np.asarray(data)
        if data.ndim != 3:
            raise ValueError(f"{name}: expected a 3-D array (nz, ny, nx), got shape {data.shape}")
        check_resolution(data.shape, name)
        data = data.astype(np.float32)
        if not np.isfinite(data).all():
            bad = int((~np.isfinite(data)).sum())
            raise ValueError(f"{name}: {bad} voxels are NaN or infinite")
        lo, hi = (float(data.min()), float(data.max())) if value_range is None else map(float, value_range)
        if not hi > lo:
            raise ValueError(f"{name}: value range ({lo}, {hi}) is empty (constant volume?)")
        self.name = name
        self.data = np.clip((data - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)
        if bbox_min is None or bbox_max is None:
            bbox_min, bbox_max = default_box(data.shape)
        self.bbox_min = np.asarray(bbox_min, float).reshape(3)
        self.bbox_max = np.asarray(bbox_max, float).reshape(3)
        if not (np.isfinite(self.bbox_min).all() and np.isfinite(self.bbox_max).all()
                and (self.bbox_max > self.bbox_min).all()):
            raise ValueError(f"{name}: bbox_min {self.bbox_min} must be below bbox_max {self.bbox_max}")
        self._textures = None

    @classmethod
    def from_array(cls, array, **kwargs) -> "ObjectVolume":
        """An object volume from a NumPy array ``(nz, ny, nx)`` (see the constructor)."""
        return cls(array, **kwargs)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.data.shape

    @property
    def voxel_size(self) -> np.ndarray:
        """World size of one voxel along x, y, z."""
        return (self.bbox_max - self.bbox_min) / np.array(self.shape[::-1], float)

    def gradient_array(self) -> np.ndarray:
        """∇O by central differences (one-sided at the faces), world units, ``(nz, ny, nx, 3)``."""
        h = self.voxel_size
        gz, gy, gx = np.gradient(self.data, h[2], h[1], h[0])
        return np.stack([gx, gy, gz], axis=-1).astype(np.float32)

    def textures(self) -> tuple[mi.Texture3f, mi.Texture3f]:
        """(O_j, ∇O_j) as trilinear Dr.Jit textures, built on first use."""
        if self._textures is None:
            density = mi.Texture3f(mi.TensorXf(self.data[..., None]), use_accel=False,
                                   filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)
            grad = mi.Texture3f(mi.TensorXf(self.gradient_array()), use_accel=False,
                                filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)
            self._textures = (density, grad)
        return self._textures

    def texture_coords(self, p: mi.Point3f) -> tuple[mi.Point3f, mi.Bool]:
        """Normalised texture coordinates of world points and whether they lie in the box."""
        lo, hi = mi.ScalarPoint3f(self.bbox_min), mi.ScalarPoint3f(self.bbox_max)
        u = (p - lo) / (hi - lo)
        inside = dr.all((u >= 0) & (u <= 1))
        return mi.Point3f(u), inside

    def density(self, p: mi.Point3f, active=True) -> mi.Float:
        """O(p) in [0, 1] at world points (trilinear; 0 outside the box or ``active``)."""
        u, inside = self.texture_coords(p)
        return dr.select(inside & active, self.textures()[0].eval(u)[0], 0.0)

    def gradient(self, p: mi.Point3f, active=True) -> mi.Vector3f:
        """Precomputed ∇O(p) (world units; 0 outside the box or ``active``)."""
        u, inside = self.texture_coords(p)
        g = self.textures()[1].eval(u)
        return dr.select(inside & active, mi.Vector3f(g[0], g[1], g[2]), 0.0)

    def nbytes(self) -> int:
        """Bytes of the object and gradient textures (float32)."""
        return int(self.data.size * 4 * 4)


def load_raw(path, sidecar=None) -> ObjectVolume:
    """Load a headerless raw volume described by a JSON sidecar (``dims`` x,y,z, ``dtype``,
    ``byte_order``, optional ``header_bytes``, ``spacing``, ``value_range``).

    The sidecar defaults to ``path`` with a ``.json`` suffix.  Everything is checked before
    the voxels are read: missing sidecar, unknown dtype, absurd dims, file size.
    """
    path = Path(path)
    sidecar = Path(sidecar) if sidecar is not None else path.with_suffix(".json")
    if not path.is_file():
        raise FileNotFoundError(f"raw volume {str(path)!r} does not exist")
    if not sidecar.is_file():
        raise FileNotFoundError(f"raw volume {str(path)!r}: its JSON sidecar {str(sidecar)!r} "
                                "does not exist (it must give dims and dtype)")
    try:
        meta = json.loads(sidecar.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"sidecar {str(sidecar)!r} is not valid JSON: {e}") from None
    for key in ("dims", "dtype"):
        if key not in meta:
            raise ValueError(f"sidecar {str(sidecar)!r}: missing key {key!r}")
    dims = check_resolution(meta["dims"], f"sidecar {str(sidecar)!r} dims")
    if meta["dtype"] not in RAW_DTYPES:
        raise ValueError(f"sidecar {str(sidecar)!r}: dtype {meta['dtype']!r} is not one of "
                         f"{', '.join(RAW_DTYPES)}")
    order = {"little": "<", "big": ">"}.get(meta.get("byte_order", "little"))
    if order is None:
        raise ValueError(f"sidecar {str(sidecar)!r}: byte_order must be 'little' or 'big'")
    dtype = np.dtype(order + RAW_DTYPES[meta["dtype"]])
    header = int(meta.get("header_bytes", 0))
    expected = header + int(np.prod(dims)) * dtype.itemsize
    actual = path.stat().st_size
    if actual != expected:
        raise ValueError(f"raw volume {str(path)!r} has {actual:,} bytes but its sidecar says "
                         f"{dims[0]}x{dims[1]}x{dims[2]} {meta['dtype']} (+{header} header) = "
                         f"{expected:,} bytes")
    data = np.fromfile(path, dtype=dtype, offset=header).reshape(dims[2], dims[1], dims[0])
    spacing = meta.get("spacing", [1.0, 1.0, 1.0])
    lo, hi = default_box(data.shape, spacing)
    return ObjectVolume(data, lo, hi, value_range=meta.get("value_range"), name=str(path))


def load_vol(path) -> ObjectVolume:
    """Load a Mitsuba ``.vol`` grid (binary "VOL" v3, float32, first channel), keeping its box."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"volume grid {str(path)!r} does not exist")
    with open(path, "rb") as f:
        head = f.read(48)
        if len(head) < 48 or head[:3] != b"VOL" or head[3] != 3:
            raise ValueError(f"volume grid {str(path)!r} is not a Mitsuba VOL v3 file")
        encoding, nx, ny, nz, channels = struct.unpack("<iiiii", head[4:24])
        box = np.array(struct.unpack("<6f", head[24:48]))
        if encoding != 1:
            raise ValueError(f"volume grid {str(path)!r}: encoding {encoding} (only float32 = 1)")
        check_resolution((nx, ny, nz), f"volume grid {str(path)!r}")
        expected = 48 + nx * ny * nz * channels * 4
        size = path.stat().st_size
        if size != expected:
            raise ValueError(f"volume grid {str(path)!r} has {size:,} bytes, its header says {expected:,}")
        data = np.fromfile(f, dtype="<f4").reshape(nz, ny, nx, channels)[..., 0]
    if not (box[3:] > box[:3]).all():
        box = np.concatenate(default_box(data.shape))
    return ObjectVolume(data, box[:3], box[3:], name=str(path))


def write_vol(path, volume: ObjectVolume) -> Path:
    """Write ``volume`` as a Mitsuba ``.vol`` grid (float32, one channel, its box)."""
    path = Path(path)
    nz, ny, nx = volume.shape
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]) + struct.pack("<iiiii", 1, nx, ny, nz, 1))
        f.write(struct.pack("<6f", *volume.bbox_min, *volume.bbox_max))
        f.write(volume.data.astype("<f4").tobytes())
    return path


def piggy_bank(resolution: int = 96) -> ObjectVolume:
    """Procedural object with hidden inner structure: a hollow ellipsoidal shell (density 0.6)
    holding three dense coins (density 1) that only a cut or a peel reveals (paper, Fig. 1).

    The field is smooth (a 1.5-voxel ramp at every boundary) so that its gradient exists.
    Box: [-0.5, 0.5]^3.
    """
    if not isinstance(resolution, (int, np.integer)) or not 8 <= resolution <= 512:
        raise ValueError(f"piggy_bank: resolution must be an integer in [8, 512], got {resolution!r}")
    n = int(resolution)
    c = (np.arange(n) + 0.5) / n - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    ramp = 1.5 / n

    def inside(signed):  # signed distance-like value < 0 inside; soft step
        return np.clip(0.5 - signed / ramp, 0.0, 1.0)

    r = np.sqrt((x / 0.45) ** 2 + (y / 0.36) ** 2 + (z / 0.32) ** 2)
    outer, inner = inside((r - 1.0) * 0.36), inside((r - 0.82) * 0.36)
    shell = 0.6 * (outer - inner)
    coins = np.zeros_like(x)
    for cx, cz in ((-0.15, -0.12), (0.02, -0.08), (0.17, -0.14)):
        radial = np.sqrt((x - cx) ** 2 + (z - cz) ** 2) - 0.075
        thick = np.abs(y) - 0.03
        coins = np.maximum(coins, inside(np.maximum(radial, thick)))
    data = np.maximum(shell, coins).astype(np.float32)
    return ObjectVolume(data, [-0.5] * 3, [0.5] * 3, value_range=(0.0, 1.0), name="piggy_bank")
