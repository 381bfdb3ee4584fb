"""Albedo transfer: the colour of a textured high-poly where each texel's ray hit it.

Two sources, evaluated on the device at the hit's triangle and barycentrics:

* **texture**: the high-poly's own UVs (per face corner) and an image (a file Mitsuba's
  ``Bitmap`` reads, or an (H, W, 3) float array of linear RGB), looked up bilinearly with
  repeat wrapping, v up (image row 0 at v = 1, as OBJ and Mitsuba's ``bitmap``);
* **vertex colours**: an (V, 3) array of linear RGB per high-poly vertex, interpolated.

Values are linear RGB; 8-bit sRGB images (PNG, JPEG) are linearised on loading like
Mitsuba's ``bitmap`` does, and the albedo PNG is written sRGB-encoded (16 bit) so a ``bitmap``
without ``raw`` reads the same linear values back.
"""
from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.meshdata import MeshData


def load_texture(texture) -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an image file or array (ValueError / FileNotFoundError
    naming ``high_texture``)."""
    if isinstance(texture, (str, Path)):
        path = Path(texture)
        if not path.is_file():
            raise FileNotFoundError(f"high_texture: file {str(path)!r} does not exist")
        try:
            bitmap = mi.Bitmap(str(path))
        except RuntimeError as error:
            raise ValueError(f"high_texture: {str(path)!r} is not an image Mitsuba reads ({error})") from None
        bitmap = bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
        data = np.array(bitmap, np.float32)
    else:
        data = np.asarray(texture, np.float32)
    if data.ndim != 3 or data.shape[2] != 3 or min(data.shape[:2]) < 1 or not np.all(np.isfinite(data)):
        raise ValueError(f"high_texture: must be a finite (H, W, 3) RGB image, got shape {data.shape}")
    return data


class HighPolyColour:
    """The high-poly's colour source on the device (see the module docstring)."""

    def __init__(self, high: MeshData, texture=None, vertex_colors=None):
        if (texture is None) == (vertex_colors is None):
            raise ValueError("albedo: give exactly one of high_texture and high_colors")
        faces = np.asarray(high.faces)
        if texture is not None:
            if high.uvs is None:
                raise ValueError("high_texture: the high-poly has no UVs to look the texture up with")
            uv = high.uvs[faces].astype(np.float32)                              # (F, 3, 2)
            self.corner = [mi.Point2f(*(mi.Float(np.ascontiguousarray(uv[:, k, c])) for c in range(2)))
                           for k in range(3)]
            self.texture = mi.Texture2f(mi.TensorXf(load_texture(texture)),
                                        filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Repeat)
        else:
            colors = np.asarray(vertex_colors, np.float32)
            if colors.shape != (len(high.positions), 3) or not np.all(np.isfinite(colors)):
                raise ValueError(f"high_colors: must be finite with shape ({len(high.positions)}, 3), "
                                 f"got {colors.shape}")
            c = colors[faces]                                                     # (F, 3, 3)
            self.corner = [mi.Color3f(*(mi.Float(np.ascontiguousarray(c[:, k, j])) for j in range(3)))
                           for k in range(3)]
            self.texture = None

    def evaluate(self, prim: mi.UInt32, bary: mi.Point2f, active: mi.Bool) -> mi.Color3f:
        """Linear RGB at the hits (triangle ``prim``, barycentrics of vertices 1 and 2)."""
        w = (1.0 - bary.x - bary.y, bary.x, bary.y)
        cls = type(self.corner[0])
        value = sum((dr.gather(cls, self.corner[k], prim, active) * w[k] for k in (1, 2)),
                    dr.gather(cls, self.corner[0], prim, active) * w[0])
        if self.texture is None:
            return mi.Color3f(value)
        return mi.Color3f(self.texture.eval(mi.Point2f(value.x, 1.0 - value.y), active))
