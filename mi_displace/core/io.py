"""Image input/output: OpenEXR (linear HDR) and PNG (sRGB-encoded LDR, 8 or 16 bit).

Every function works on NumPy arrays of shape ``(H, W, 3)`` holding *linear* RGB radiance
(``float32``, arbitrary non-negative range).  The file format is chosen from the suffix:

* ``.exr`` — 32-bit float RGB, written with the ``OpenEXR`` package, ZIP compressed.
  Values are stored exactly as given (HDR, NaN/Inf preserved).
* ``.png`` — the linear values are clipped to ``[0, 1]``, encoded with the sRGB transfer
  function (:func:`to_srgb`) and quantised to 8 bits (default) or 16 bits per channel.
  PNG encoding and decoding use Mitsuba's ``mi.Bitmap`` (libpng), which needs no variant.

Reading returns linear float32 ``(H, W, 3)`` for both formats (PNG data is decoded with
:func:`from_srgb`).  A grey image is replicated to three channels; an alpha channel is dropped.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

EXR_SUFFIXES = (".exr",)
PNG_SUFFIXES = (".png",)
SUFFIXES = EXR_SUFFIXES + PNG_SUFFIXES


def to_srgb(linear) -> np.ndarray:
    """Clip linear RGB to ``[0, 1]`` and apply the sRGB transfer function (IEC 61966-2-1).

    Args:
        linear: array-like of any shape, linear values (NaN maps to 0).

    Returns:
        float32 array of the same shape with sRGB-encoded values in ``[0, 1]``.
    """
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float32), nan=0.0), 0.0, 1.0)
    return np.where(
        x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055
    ).astype(np.float32)


def from_srgb(encoded) -> np.ndarray:
    """Inverse of :func:`to_srgb`: sRGB-encoded values in ``[0, 1]`` to linear float32."""
    x = np.clip(np.asarray(encoded, dtype=np.float32), 0.0, 1.0)
    return np.where(
        x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4)
    ).astype(np.float32)


def as_rgb(image, name: str = "image") -> np.ndarray:
    """Convert an image to a float32 ``(H, W, 3)`` NumPy array, or raise ``ValueError``.

    Accepts anything ``np.asarray`` understands (NumPy, ``mi.TensorXf``, ``mi.Bitmap``) of
    shape ``(H, W)`` or ``(H, W, 1)`` (grey, replicated), ``(H, W, 3)`` or ``(H, W, 4)``
    (alpha dropped).  ``name`` is used in the error message.
    """
    try:
        a = np.asarray(image, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: expected an (H, W, 3) image array, got {type(image).__name__}") from e
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 3, 4) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name}: expected an image of shape (H, W, 3), got shape {a.shape}")
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return np.ascontiguousarray(a[..., :3])


def image_format(path: str | os.PathLike, what: str = "image") -> str:
    """The format of an image path from its suffix: ``".exr"`` or ``".png"``.

    Raises:
        ValueError: any other suffix (the message names ``what`` and the path).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(
            f"{what} {str(path)!r}: unknown image format {path.suffix!r}; "
            f"expected one of {', '.join(SUFFIXES)}"
        )
    return suffix


def write_exr(path: str | os.PathLike, image) -> Path:
    """Write linear RGB ``(H, W, 3)`` as a 32-bit float, ZIP-compressed OpenEXR file.

    Returns:
        The path written.  Parent folders are created.
    """
    import OpenEXR

    path = Path(path)
    rgb = as_rgb(image, f"image for {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": rgb}) as f:
        f.write(str(path))
    return path


def _existing(path: str | os.PathLike, kind: str) -> Path:
    """``Path(path)``, or FileNotFoundError naming the ``kind`` of file and the path."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{kind} file {str(path)!r} does not exist")
    return path


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file's R, G, B (or Y) channels as linear float32 ``(H, W, 3)``."""
    import OpenEXR

    path = _existing(path, "EXR")
    with OpenEXR.File(str(path), separate_channels=True) as f:
        channels = {k: v.pixels for k, v in f.channels().items()}
    if all(c in channels for c in "RGB"):
        planes = [channels[c] for c in "RGB"]
    elif "Y" in channels:
        planes = [channels["Y"]] * 3
    else:
        raise ValueError(
            f"EXR file {str(path)!r} has no R, G, B or Y channels (found {sorted(channels)})"
        )
    return np.stack([np.asarray(p, dtype=np.float32) for p in planes], axis=-1)


def write_png(path: str | os.PathLike, image, bits: int = 8) -> Path:
    """Write linear RGB ``(H, W, 3)`` as an sRGB PNG with 8 or 16 bits per channel.

    Values are clipped to ``[0, 1]`` before encoding; NaN is refused (``ValueError``)
    because a PNG cannot show it.
    """
    import mitsuba as mi

    path = Path(path)
    if bits not in (8, 16):
        raise ValueError(f"bits: PNG supports 8 or 16 bits per channel, got {bits!r}")
    rgb = as_rgb(image, f"image for {path}")
    if np.isnan(rgb).any():
        raise ValueError(f"image for {path}: {int(np.isnan(rgb).sum())} NaN values; a PNG cannot store NaN")
    dtype, scale = (np.uint8, 255.0) if bits == 8 else (np.uint16, 65535.0)
    quantised = np.round(to_srgb(rgb) * scale).astype(dtype)
    bitmap = mi.Bitmap(quantised, pixel_format=mi.Bitmap.PixelFormat.RGB)
    bitmap.set_srgb_gamma(True)
    path.parent.mkdir(parents=True, exist_ok=True)
    bitmap.write(str(path))
    return path


def read_png(path: str | os.PathLike) -> np.ndarray:
    """Read an 8- or 16-bit PNG and decode it from sRGB to linear float32 ``(H, W, 3)``."""
    import mitsuba as mi

    path = _existing(path, "PNG")
    bitmap = mi.Bitmap(str(path))
    data = np.asarray(bitmap)
    scale = float(np.iinfo(data.dtype).max) if np.issubdtype(data.dtype, np.integer) else 1.0
    encoded = as_rgb(data.astype(np.float32) / scale, f"PNG file {str(path)!r}")
    return from_srgb(encoded) if bitmap.srgb_gamma() else encoded


def write_image(path: str | os.PathLike, image, bits: int = 8) -> Path:
    """Write linear RGB ``(H, W, 3)`` to ``.exr`` (float32) or ``.png`` (``bits`` = 8 or 16).

    Raises:
        ValueError: unknown suffix, bad shape, or NaN in a PNG.
    """
    path = Path(path)
    if image_format(path, "output image") in EXR_SUFFIXES:
        return write_exr(path, image)
    return write_png(path, image, bits=bits)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read ``.exr`` or ``.png`` as linear float32 ``(H, W, 3)``.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: unknown suffix.
    """
    path = Path(path)
    if image_format(path, "input image") in EXR_SUFFIXES:
        return read_exr(path)
    return read_png(path)
