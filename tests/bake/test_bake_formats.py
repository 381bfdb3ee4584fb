"""Every §1.2 format round-trips through its file and sidecar within its quantisation step."""
import json

import numpy as np
import pytest

from mi_displace.bake import formats


def _maps(h=16, w=24, seed=0):
    rng = np.random.default_rng(seed)
    d = rng.uniform(-0.3, 0.7, (h, w)).astype(np.float32)
    def unit(z_min):
        v = rng.normal(size=(h, w, 3))
        v[..., 2] = np.abs(v[..., 2]) + z_min
        return (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)
    curvature = rng.uniform(-3.0, 3.0, (h, w)).astype(np.float32)
    return {"displacement": d, "normal_tangent": unit(0.5), "normal_object": unit(-1.0),
            "normal_mitsuba": unit(0.5), "direction_tangent": unit(0.5), "back_depth": (d - 0.2).astype(np.float32),
            "ao": rng.uniform(0, 1, (h, w)).astype(np.float32), "curvature": curvature,
            "cavity": np.clip(-curvature / 3.0, 0, 1), "albedo": rng.uniform(0, 1, (h, w, 3)).astype(np.float32)}


#: displacement bits of each quantised format (the §1.2 table), independent of the sidecar
BITS = {"d8": 8, "d16": 16, "dir24_d8": 8, "dir16_d16": 16, "d8_n24": 8, "dual_d8_n16": 8,
        "d16_n16": 16}


def check_round_trip(tmp_path, fmt):
    """Write and read ``fmt``; displacement within half of the step the format's bit depth
    gives over the input's own range (not the step the sidecar claims)."""
    maps = _maps()
    path = formats.write_map(tmp_path, fmt, maps, {"low": "low.obj", "curvature_range": 3.0})
    meta = json.loads((tmp_path / (path.name + ".json")).read_text())
    assert meta["format"] == fmt and meta["width"] == 24 and meta["height"] == 16
    out = formats.read_map(path)
    if out["displacement"] is not None:
        d = maps["displacement"]
        lo = min(d.min(), maps["back_depth"].min()) if fmt == "dual_d8_n16" else d.min()
        step = (d.max() - lo) / ((1 << BITS[fmt]) - 1) if fmt in BITS else 0.0
        err = np.abs(out["displacement"] - d).max()
        assert err <= 0.5 * step + 1e-6, (fmt, err, step)
        assert np.all(np.isfinite(out["displacement"]))
    # surface maps: 16-bit PNGs within half a step of their encoding (curvature over its
    # range 3, the sidecar's H_ref: |H| <= 3 here), floats exact; sRGB albedo within 1e-4
    name = fmt.removesuffix("_float")
    if out.get(name) is not None and name in ("ao", "curvature", "cavity", "albedo"):
        step = 0.0 if fmt.endswith("_float") else 0.5 / 65535 * (6.0 if name == "curvature" else 1.0)
        tol = 1e-4 if name == "albedo" and step else step + 1e-6
        assert np.abs(out[name] - maps[name]).max() <= tol, (fmt, np.abs(out[name] - maps[name]).max())
    one_byte = 2.0 / 255  # one 8-bit step of a [-1, 1] component
    for key in ("normal_tangent", "direction_tangent", "back_depth", "normal_object", "normal_mitsuba"):
        if out.get(key) is not None:
            tol = 1e-6 if fmt == "float" else (3 * one_byte if key != "back_depth" else 0.5 * step + 1e-6)
            assert np.abs(out[key] - maps[key]).max() <= tol, (fmt, key)


@pytest.mark.parametrize("fmt", sorted(formats.FORMATS))
def test_round_trip(tmp_path, variant, fmt):
    check_round_trip(tmp_path, fmt)


def png_header(path):
    """(bit depth, colour type) from a PNG's IHDR chunk, read from the bytes."""
    data = open(path, "rb").read(32)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR"
    return data[24], data[25]


def check_d16_is_16_bit(tmp_path):
    path = formats.write_map(tmp_path, "d16", _maps(64, 64), {})
    assert png_header(path) == (16, 0)                       # 16-bit greyscale
    q = formats.read_png_raw(path)
    assert q.dtype == np.uint16 and len(np.unique(q)) > 1000  # more levels than 8 bits hold


def test_d16_png_is_16_bit(tmp_path, variant):
    check_d16_is_16_bit(tmp_path)


def test_formats_carry_what_they_promise(tmp_path, variant):
    maps = _maps()
    carried = {f: formats.read_map(formats.write_map(tmp_path, f, maps, {})) for f in formats.FORMATS}
    assert carried["dir24_d8"]["direction_tangent"] is not None
    assert carried["dir16_d16"]["direction_tangent"] is not None
    assert carried["d8_n24"]["normal_tangent"] is not None
    assert carried["dual_d8_n16"]["back_depth"] is not None
    assert carried["d8"]["normal_tangent"] is None and carried["d8"]["direction_tangent"] is None
    # 16-bit displacement is 257x finer than 8-bit
    s8 = json.loads((tmp_path / "d8.png.json").read_text())["displacement"]["scale"]
    s16 = json.loads((tmp_path / "d16_n16.png.json").read_text())["displacement"]["scale"]
    assert s8 / s16 == pytest.approx(65535 / 255)


def test_bad_input(tmp_path, variant):
    with pytest.raises(ValueError, match="formats"):
        formats.check_formats(["d8", "d12"])
    with pytest.raises(FileNotFoundError, match="does not exist"):
        formats.read_map(tmp_path / "none.png")
    path = formats.write_map(tmp_path, "d8", _maps(), {})
    (tmp_path / "d8.png.json").unlink()
    with pytest.raises(FileNotFoundError, match="metadata"):
        formats.read_map(path)
    (tmp_path / "d8.png.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        formats.read_map(path)


def test_every_file_the_baker_writes_opens_in_mitsuba(sphere_pair, tmp_path):
    """Issue 29: each map (every format, the mask, the diagnostics image) is a texture
    Mitsuba's ``bitmap`` loads, and it returns the stored values: a displacement texel of
    the float map reads back as the bake's displacement."""
    import mitsuba as mi

    from mi_displace.bake.baker import bake

    high, low = sphere_pair
    r = bake(high, low, res=32, out_dir=tmp_path, map_formats="all", diagnostics=True,
             max_distance=0.2, pad=2)
    images = sorted(p for p in tmp_path.iterdir() if p.suffix in (".png", ".exr"))
    assert {p.name for p in images} == {f for f in r.record["files"] if f.endswith((".png", ".exr"))}
    assert len(images) >= len(formats.FORMATS) + 2
    row, col = np.unravel_index(np.argmax(np.abs(r.maps["displacement"])), (32, 32))
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(float(col + 0.5) / 32, float(row + 0.5) / 32)   # that texel's centre (v down)
    for path in images:
        texture = mi.load_dict({"type": "bitmap", "filename": str(path), "raw": True,
                                "filter_type": "nearest"})
        value = np.asarray(texture.eval(si)).ravel()
        assert np.all(np.isfinite(value)), path.name
    texture = mi.load_dict({"type": "bitmap", "filename": str(tmp_path / "float.exr"), "raw": True,
                            "filter_type": "nearest"})
    d = r.maps["displacement"][row, col]
    assert abs(d) > 0.01 and np.asarray(texture.eval_1(si))[0] == pytest.approx(d, abs=1e-6)


def test_a_float_map_without_a_y_channel_is_named(tmp_path):
    path = formats.write_map(tmp_path, "float", _maps(), {"low": "low.obj"})
    formats.write_exr_channels(path, {"D": _maps()["displacement"]})   # channels Mitsuba cannot read
    with pytest.raises(ValueError, match=r"float\.exr' has no 'Y' channel"):
        formats.read_map(path)
