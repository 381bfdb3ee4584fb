"""A height bitmap read as sRGB colour (no raw="true") is named at load, with the fix."""
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.core.texture_height import bitmap_decodes_srgb


def _png(tmp_path, bits):
    ramp = np.linspace(0, 1, 16).reshape(4, 4, 1)
    data = (ramp * (2 ** bits - 1)).astype(np.uint8 if bits == 8 else np.uint16)
    path = tmp_path / f"h{bits}.png"
    mi.Bitmap(data).write(str(path))
    return str(path)


@pytest.mark.parametrize("bits", [8, 16])
def test_the_decode_is_detected_and_is_real(variant, tmp_path, bits):
    """Property: without raw the texture's mean is the sRGB decode of the stored ramp's
    (0.32 for a 0..1 ramp), with raw it is the ramp's own (0.5); the check says which."""
    path = _png(tmp_path, bits)
    decoded = mi.load_dict({"type": "bitmap", "filename": path})
    raw = mi.load_dict({"type": "bitmap", "filename": path, "raw": True})
    assert abs(raw.mean()[0] - 0.5) < 1e-3 and decoded.mean()[0] < 0.4
    assert bitmap_decodes_srgb(decoded) and not bitmap_decodes_srgb(raw)
    linear = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.full((2, 2, 1), 0.5, np.float32))})
    assert not bitmap_decodes_srgb(linear) and not bitmap_decodes_srgb(mi.load_dict({"type": "cells"}))


@pytest.mark.parametrize("shape", [
    {"type": "displaced", "base": "plane", "resolution": 4, "scale": 0.1},
    {"type": "slicing", "base": "plane", "slices": 4, "scale": 0.1},
    {"type": "sphere", "bsdf": {"type": "relief", "tile_size": 0.5}},
])
def test_every_height_consumer_warns_naming_raw(variant, tmp_path, shape):
    height = {"type": "bitmap", "filename": _png(tmp_path, 8)}
    target = shape["bsdf"] if "bsdf" in shape else shape
    target["height"] = height
    with pytest.warns(UserWarning, match="parameter 'height' is a bitmap read as sRGB.*raw"):
        mi.load_dict(shape)
    height["raw"] = True
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        mi.load_dict(shape)


def test_a_python_texture_is_no_bitmap(variant):
    """A texture written in Python (no ``to_string``) is not a bitmap, and ``displaced``
    builds over it (``bench dicing``'s procedural sphere)."""
    class Flat(mi.Texture):
        def __init__(self, props):
            super().__init__(props)

        def eval_1(self, si, active=True):
            return mi.Float(0.5)

    mi.register_texture("flat_python", lambda props: Flat(props))
    texture = mi.load_dict({"type": "flat_python"})
    assert not bitmap_decodes_srgb(texture)
    shape = mi.load_dict({"type": "displaced", "base": "plane", "resolution": 4, "scale": 0.1,
                          "height": {"type": "flat_python"}})
    assert shape.face_count() == 32
