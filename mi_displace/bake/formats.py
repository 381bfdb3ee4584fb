"""Map formats of §1.2, each written with a JSON sidecar holding its scale/offset metadata.

Every quantised displacement channel stores ``q = round((d - offset) / scale)``; reading
gives back ``d = offset + scale * q`` [object units] exactly as written (the sidecar holds
``scale`` and ``offset`` as Python floats).  Offset and scale span the baked range
[d_min, d_max] over the texels that hold a value (covered or padded), so the full integer
range is used.  Normals and directions are unit vectors
in the low-poly's tangent frame (x = tangent, y = bitangent, z = normal;
:mod:`mi_displace.bake.meshdata`) encoded as ``(x + 1) / 2``; two-component encodings restore
``z = sqrt(1 - x^2 - y^2)`` (§1.2), valid because tangent-space z >= 0 on the outward side.
PNG maps are *linear data* (no sRGB curve).

========================  ======  =====================================================
format (file)             pixel   channels
========================  ======  =====================================================
``d8`` (.png)             Y 8     displacement (along the interpolated normal)
``d16`` (.png)            Y 16    displacement, 16 bit (the PNG-16 of Fig. 21's table)
``dir24_d8`` (.png)       RGBA 8  RGB direction, A displacement
``dir16_d16`` (.png)      RGBA 8  R,G direction x,y; B,A displacement high, low byte
``d8_n24`` (.png)         RGBA 8  RGB normal, A displacement (Fig. 20)
``dual_d8_n16`` (.png)    RGBA 8  R front depth, G back depth (dual-depth relief), B,A
                                  normal x,y
``d16_n16`` (.png)        RGBA 8  R,G displacement high, low byte; B,A normal x,y
``float`` (.exr)          Y 32    displacement; beside it ``float_normal.exr`` (RGB 32,
                                  MikkTSpace normal), ``float_direction.exr`` (RGB 32)
                                  and with the back depth ``float_back.exr`` (Y 32);
                                  float32, ZIP, channels named as Mitsuba's ``bitmap``
                                  reads them
``normal_tangent`` (.png) RGB 8   tangent-space normal map (MikkTSpace frame)
``normal_mitsuba`` (.png) RGB 8   tangent-space normal map in the frame of Mitsuba's
                                  stock ``normalmap`` BSDF (:mod:`mitsuba_frames`)
``normal_object`` (.png)  RGB 8   object-space normal map
``normal_tangent16``      RGB 16  ``normal_tangent`` at 16 bits
(.png)
``ao`` (.png)             Y 16    ambient occlusion in [0, 1] (:mod:`occlusion`)
``curvature`` (.png)      Y 16    signed mean curvature, 0.5 + 0.5 clip(H / H_ref, -1, 1)
                                  (:mod:`curvature`; H_ref in the sidecar)
``cavity`` (.png)         Y 16    clip(-H / H_ref, 0, 1)
``albedo`` (.png)         RGB 16  the high-poly's colour, sRGB-encoded (:mod:`albedo`)
``ao_float``,             Y 32    the same maps as float EXRs: AO, H [1 / object units],
``curvature_float``,              cavity, linear RGB albedo (RGB 32)
``cavity_float``,
``albedo_float`` (.exr)
========================  ======  =====================================================

Green channel: with ``green="-y"`` (DirectX) the tangent-space maps meant for other tools
(``normal_tangent``, ``normal_tangent16`` and ``float_normal.exr``) store G = 1 - G of the
OpenGL (``+y``, Blender, Mitsuba) encoding; the sidecar records ``green`` and
:func:`read_map` undoes it.  ``normal_mitsuba`` is always ``+y`` (Mitsuba's ``normalmap`` has
no switch) and so are the packed normals of the displacement formats (our own plugins read
them).

Every file opens as ``mi.load_dict({"type": "bitmap", "filename": ..., "raw": True})``.
Vectors in the float EXRs are encoded like the PNGs' (``(x + 1) / 2``, what Mitsuba's
``normalmap`` decodes).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

FORMATS = {
    "d8": ".png", "d16": ".png", "dir24_d8": ".png", "dir16_d16": ".png", "d8_n24": ".png",
    "dual_d8_n16": ".png", "d16_n16": ".png", "float": ".exr",
    "normal_tangent": ".png", "normal_mitsuba": ".png", "normal_object": ".png",
    "normal_tangent16": ".png", "ao": ".png", "curvature": ".png", "cavity": ".png",
    "albedo": ".png", "ao_float": ".exr", "curvature_float": ".exr", "cavity_float": ".exr",
    "albedo_float": ".exr",
}
#: surface-map formats -> the map the baker must evaluate for them (:mod:`surface_maps`)
SURFACE_FORMATS = {"ao": "ao", "ao_float": "ao", "curvature": "curvature",
                   "curvature_float": "curvature", "cavity": "curvature", "cavity_float": "curvature",
                   "albedo": "albedo", "albedo_float": "albedo"}
#: the green-channel conventions: OpenGL (Blender, Mitsuba, Unity) and DirectX (Unreal, 3ds Max)
GREEN = ("+y", "-y")
#: formats whose tangent-space normal follows ``green``
GREEN_FORMATS = ("normal_tangent", "normal_tangent16", "float")
#: the float format's companion EXRs: name -> (file suffix, map it holds)
FLOAT_COMPANIONS = {"normal": ("_normal", "normal_tangent"),
                    "direction": ("_direction", "direction_tangent"),
                    "back": ("_back", "back_depth")}
#: what a user asks for most: 16-bit displacement and the tangent-space normal map in
#: MikkTSpace and in Mitsuba's stock frame (the validity mask ``valid.png`` is always
#: written); ``--formats all`` writes every format
DEFAULT_FORMATS = ("d16", "normal_tangent", "normal_mitsuba")
UV_CONVENTION = "texel (c, r) centre at u = (c + 0.5) / W, v = 1 - (r + 0.5) / H (v up, row 0 on top)"
TANGENT_CONVENTION = ("MikkTSpace (genTangSpaceDefault) over the vertex normals written in low.obj; "
                      "bitangent = sign * cross(n, t) per pixel from the interpolated, unnormalised "
                      "n and t; normal = normalize(x t + y b + z n)")


def check_formats(formats) -> tuple[str, ...]:
    """Validate a list of format names (ValueError naming the unknown ones)."""
    formats = tuple(FORMATS) if formats == "all" or tuple(formats) == ("all",) else tuple(formats)
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise ValueError(f"formats: unknown {bad or 'empty list'}; choose from {', '.join(FORMATS)}")
    return formats


def _range(filled, *arrays) -> tuple[float, float]:
    """(offset, span) of the values at the ``filled`` texels ((H, W) bool, or None: all):
    empty texels beyond the padding do not widen the quantisation range."""
    if filled is not None and np.any(filled):
        arrays = tuple(a[filled] for a in arrays)
    lo = float(min(np.min(a) for a in arrays))
    hi = float(max(np.max(a) for a in arrays))
    return lo, (hi - lo if hi > lo else 1.0)


def _quantise(d: np.ndarray, offset: float, span: float, bits: int) -> tuple[np.ndarray, float]:
    levels = (1 << bits) - 1
    scale = span / levels
    q = np.clip(np.round((d.astype(np.float64) - offset) / scale), 0, levels)
    return q.astype(np.uint16 if bits > 8 else np.uint8), scale


def _unit8(v: np.ndarray) -> np.ndarray:
    return _fixed(np.asarray(v, np.float64) * 0.5 + 0.5, 8)


def _fixed(x: np.ndarray, bits: int) -> np.ndarray:
    """Values in [0, 1] as unsigned integers of ``bits`` (8 or 16), rounded."""
    levels = (1 << bits) - 1
    q = np.clip(np.round(np.asarray(x, np.float64) * levels), 0, levels)
    return q.astype(np.uint16 if bits > 8 else np.uint8)


def _flip_green(data: np.ndarray, levels: float) -> np.ndarray:
    """G -> levels - G of an (H, W, 3) encoded normal map (OpenGL <-> DirectX)."""
    data = data.copy()
    data[..., 1] = levels - data[..., 1]
    return data


def _from8(q: np.ndarray) -> np.ndarray:
    return q.astype(np.float32) / 255.0 * 2.0 - 1.0


def _complete_z(xy: np.ndarray) -> np.ndarray:
    z = np.sqrt(np.clip(1.0 - (xy ** 2).sum(-1, keepdims=True), 0.0, 1.0))
    return _normalise(np.concatenate([xy, z], -1))


def _normalise(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.maximum(n, 1e-30), [0.0, 0.0, 1.0]).astype(np.float32)


def write_png_raw(path: Path, data: np.ndarray, srgb: bool = False) -> None:
    """Write integer data (H, W) or (H, W, C in {3, 4}) as a PNG (uint8 or uint16): linear
    data, or (``srgb``) colours already sRGB-encoded."""
    import mitsuba as mi

    data = np.ascontiguousarray(data if data.ndim == 3 else data[:, :, None])
    fmt = {1: mi.Bitmap.PixelFormat.Y, 3: mi.Bitmap.PixelFormat.RGB, 4: mi.Bitmap.PixelFormat.RGBA}
    bitmap = mi.Bitmap(data, pixel_format=fmt[data.shape[2]])
    bitmap.set_srgb_gamma(srgb)
    bitmap.write(str(path))


def read_png_raw(path: Path) -> np.ndarray:
    """Integer data (H, W, C) of a PNG, exactly as stored; ``ValueError`` naming the file
    when it is not an image Mitsuba can read."""
    import mitsuba as mi

    try:
        data = np.asarray(mi.Bitmap(str(path)))
    except RuntimeError as error:   # mi.Bitmap: "Unknown file format", no file name
        raise ValueError(f"map file {str(path)!r} is not a readable PNG image ({error})") from None
    return data if data.ndim == 3 else data[:, :, None]


def write_exr_channels(path: Path, channels: dict) -> None:
    """Write float32 (H, W) planes under the given channel names (ZIP compression)."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: np.ascontiguousarray(v, np.float32) for k, v in channels.items()}) as f:
        f.write(str(path))


def read_exr_channels(path: Path) -> dict:
    """Float32 planes of an EXR by channel name; ``ValueError`` naming the file when it is
    not an EXR image."""
    import OpenEXR

    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            return {k: np.asarray(v.pixels, np.float32) for k, v in f.channels().items()}
    except RuntimeError as error:
        raise ValueError(f"map file {str(path)!r} is not a readable EXR image ({error})") from None


def write_map(out_dir: Path, fmt: str, maps: dict, meta: dict, green: str = "+y") -> Path:
    """Encode ``maps`` in format ``fmt`` under ``out_dir/fmt.<ext>`` plus ``fmt.<ext>.json``.

    Args:
        maps: ``displacement`` (H, W), ``normal_tangent``, ``normal_object``,
            ``direction_tangent`` (H, W, 3), optional ``back_depth`` (H, W); the surface
            maps a surface format needs: ``ao``, ``curvature`` [1 / object units],
            ``cavity`` (H, W), ``albedo`` (H, W, 3) linear; float32.
        meta: shared metadata copied into the sidecar (low-poly file, max_distance, ...;
            ``curvature_range`` H_ref for the curvature PNG).
        green: ``+y`` (OpenGL) or ``-y`` (DirectX) for :data:`GREEN_FORMATS`.
    """
    path = Path(out_dir) / f"{fmt}{FORMATS[fmt]}"
    d = maps["displacement"]
    nt, dirn = maps["normal_tangent"], maps["direction_tangent"]
    side = {**meta, "format": fmt, "file": path.name, "width": int(d.shape[1]),
            "height": int(d.shape[0]), "uv_convention": UV_CONVENTION}
    if fmt in GREEN_FORMATS:
        side["green"] = green
    flip = green == "-y"
    if fmt in SURFACE_FORMATS:
        _write_surface(path, fmt, maps, side)
    elif fmt in ("d8", "d16", "dir24_d8", "dir16_d16", "d8_n24", "d16_n16"):
        bits = 16 if fmt in ("d16", "dir16_d16", "d16_n16") else 8
        offset, span = _range(maps.get("filled"), d)
        q, scale = _quantise(d, offset, span, bits)
        side["displacement"] = {"offset": offset, "scale": scale, "bits": bits}
        hi, lo = (q >> 8).astype(np.uint8), (q & 255).astype(np.uint8)
        if fmt in ("d8", "d16"):
            data = q
        elif fmt == "dir24_d8":
            data = np.dstack([_unit8(dirn), q])
        elif fmt == "dir16_d16":
            data = np.dstack([_unit8(dirn[..., :2]), hi, lo])
        elif fmt == "d8_n24":
            data = np.dstack([_unit8(nt), q])
        else:  # d16_n16
            data = np.dstack([hi, lo, _unit8(nt[..., :2])])
        write_png_raw(path, data)
    elif fmt == "dual_d8_n16":
        back = maps.get("back_depth")
        if back is None:
            raise ValueError("format 'dual_d8_n16' needs the back depth (bake with it requested)")
        offset, span = _range(maps.get("filled"), d, back)
        qf, scale = _quantise(d, offset, span, 8)
        qb, _ = _quantise(back, offset, span, 8)
        side["displacement"] = {"offset": offset, "scale": scale, "bits": 8}
        write_png_raw(path, np.dstack([qf, qb, _unit8(nt[..., :2])]))
    elif fmt == "float":
        write_exr_channels(path, {"Y": d})
        side["companions"] = {}
        for key, (suffix, name) in FLOAT_COMPANIONS.items():
            value = maps.get(name)
            if value is None:
                continue
            file = path.with_name(f"{path.stem}{suffix}.exr")
            # vectors encoded (x + 1) / 2 like the PNGs (Mitsuba's normalmap decodes 2 c - 1)
            if value.ndim == 3:
                value = value * 0.5 + 0.5
                if flip and key == "normal":
                    value = _flip_green(value, 1.0)
            write_exr_channels(file, {"Y": value} if value.ndim == 2 else
                               {c: value[..., k] for k, c in enumerate("RGB")})
            side["companions"][key] = file.name
        side["displacement"] = {"offset": 0.0, "scale": 1.0, "bits": 32}
    elif fmt in NORMAL_FORMATS:
        name, bits = NORMAL_FORMATS[fmt]
        data = _fixed(maps[name] * 0.5 + 0.5, bits)
        write_png_raw(path, _flip_green(data, (1 << bits) - 1) if flip and fmt in GREEN_FORMATS else data)
        side["space"] = fmt.split("_")[1].rstrip("16")
        side["bits"] = bits
    side["tangent_convention"] = TANGENT_CONVENTION
    Path(str(path) + ".json").write_text(json.dumps(side, indent=2))
    return path


#: the normal-map formats -> (map, bits)
NORMAL_FORMATS = {"normal_tangent": ("normal_tangent", 8), "normal_mitsuba": ("normal_mitsuba", 8),
                  "normal_object": ("normal_object", 8), "normal_tangent16": ("normal_tangent", 16)}


def _write_surface(path: Path, fmt: str, maps: dict, side: dict) -> None:
    """A surface map (:data:`SURFACE_FORMATS`): 16-bit PNG or float EXR."""
    from mi_displace.bake.curvature import curvature_range, encode_signed

    name = fmt.removesuffix("_float")
    value = maps[name]
    if fmt.endswith("_float"):
        write_exr_channels(path, {"Y": value} if value.ndim == 2 else
                           {c: value[..., k] for k, c in enumerate("RGB")})
        side["encoding"] = "linear RGB" if name == "albedo" else (
            "H [1 / object units]" if name == "curvature" else "value in [0, 1]")
        return
    if name == "albedo":
        x = np.clip(np.asarray(value, np.float64), 0.0, 1.0)     # the sRGB curve (IEC 61966-2-1)
        encoded = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
        write_png_raw(path, _fixed(encoded, 16), srgb=True)
        side["encoding"] = "sRGB, 16 bit (a bitmap without raw reads linear RGB)"
        return
    if name == "curvature":
        if "curvature_range" not in side:   # the map's own range (the baker passes its H_ref)
            side["curvature_range"] = curvature_range(value, np.ones(value.shape, bool), None)
        value = encode_signed(value, side["curvature_range"])
        side["encoding"] = "0.5 + 0.5 clip(H / curvature_range, -1, 1), q / 65535, raw"
    else:
        side["encoding"] = "value = q / 65535, raw"
    write_png_raw(path, _fixed(value, 16))


def read_metadata(path: str | os.PathLike) -> dict:
    """The sidecar of a map (``path`` may be the map or its ``.json``)."""
    path = Path(path)
    side = path if path.suffix == ".json" else Path(str(path) + ".json")
    if not path.exists():
        raise FileNotFoundError(f"map file {str(path)!r} does not exist")
    if not side.is_file():
        raise FileNotFoundError(f"map {str(path)!r}: metadata {str(side)!r} (scale/offset) is missing")
    try:
        meta = json.loads(side.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"map metadata {str(side)!r} is not valid JSON: {e}") from None
    if meta.get("format") not in FORMATS:
        raise ValueError(f"map metadata {str(side)!r}: unknown format {meta.get('format')!r}")
    meta["_path"] = str(side.parent / meta["file"])
    return meta


def read_map(path: str | os.PathLike) -> dict:
    """Decode a map written by :func:`write_map`.

    Returns:
        dict with ``displacement`` (H, W) float32 [object units] (``None`` for pure normal
        maps), ``direction_tangent`` (H, W, 3) unit or ``None`` (along the normal),
        ``normal_tangent`` (H, W, 3) or ``None``, ``back_depth`` or ``None``, ``meta``;
        the normal-map formats give their own key (``normal_mitsuba``, ``normal_object``).
    """
    meta = read_metadata(path)
    fmt, file = meta["format"], Path(meta["_path"])
    if not file.is_file():
        raise FileNotFoundError(f"map file {str(file)!r} (named by its metadata) does not exist")
    out = {"displacement": None, "direction_tangent": None, "normal_tangent": None,
           "back_depth": None, "meta": meta}
    if fmt == "float":
        channels = read_exr_channels(file)
        if "Y" not in channels:
            raise ValueError(f"map file {str(file)!r} has no 'Y' channel (channels "
                             f"{sorted(channels)}); bake it again")
        out["displacement"] = channels["Y"]
        for key, file_name in meta.get("companions", {}).items():
            companion = file.parent / file_name
            if not companion.is_file():
                raise FileNotFoundError(f"map file {str(companion)!r} (named by the metadata of "
                                        f"{str(file)!r}) does not exist")
            ch = read_exr_channels(companion)
            name = FLOAT_COMPANIONS[key][1]
            if "Y" in ch:
                out[name] = ch["Y"]
                continue
            value = np.dstack([ch[c] for c in "RGB"])
            if key == "normal" and meta.get("green") == "-y":
                value = _flip_green(value, 1.0)
            out[name] = _normalise(value * 2.0 - 1.0)
        return _with_valid(out, meta)
    if fmt in SURFACE_FORMATS:
        name = fmt.removesuffix("_float")
        if fmt.endswith("_float"):
            ch = read_exr_channels(file)
            out[name] = ch["Y"] if "Y" in ch else np.dstack([ch[c] for c in "RGB"])
        elif name == "albedo":   # sRGB-encoded: linearised like Mitsuba's bitmap does
            import mitsuba as mi

            bitmap = mi.Bitmap(str(file)).convert(component_format=mi.Struct.Type.Float32,
                                                  srgb_gamma=False)
            out[name] = np.array(bitmap, np.float32)
        else:
            value = read_png_raw(file)[..., 0].astype(np.float32) / 65535
            out[name] = ((value - 0.5) * 2 * meta["curvature_range"] if name == "curvature"
                         else value)
        return out
    data = read_png_raw(file)
    if fmt in NORMAL_FORMATS:
        name, bits = NORMAL_FORMATS[fmt]
        levels = (1 << bits) - 1
        if meta.get("green") == "-y":
            data = _flip_green(data[..., :3].astype(np.int64), levels)
        out[name] = _normalise(data[..., :3].astype(np.float32) / levels * 2.0 - 1.0)
        return out
    q = meta["displacement"]

    def dec(values):
        return (q["offset"] + q["scale"] * values.astype(np.float64)).astype(np.float32)

    if fmt in ("d8", "d16"):
        out["displacement"] = dec(data[..., 0])
    elif fmt == "dir24_d8":
        out["direction_tangent"] = _normalise(_from8(data[..., :3]))
        out["displacement"] = dec(data[..., 3])
    elif fmt == "dir16_d16":
        out["direction_tangent"] = _complete_z(_from8(data[..., :2]))
        out["displacement"] = dec(data[..., 2].astype(np.uint32) * 256 + data[..., 3])
    elif fmt == "d8_n24":
        out["normal_tangent"] = _normalise(_from8(data[..., :3]))
        out["displacement"] = dec(data[..., 3])
    elif fmt == "dual_d8_n16":
        out["displacement"] = dec(data[..., 0])
        out["back_depth"] = dec(data[..., 1])
        out["normal_tangent"] = _complete_z(_from8(data[..., 2:4]))
    elif fmt == "d16_n16":
        out["displacement"] = dec(data[..., 0].astype(np.uint32) * 256 + data[..., 1])
        out["normal_tangent"] = _complete_z(_from8(data[..., 2:4]))
    return _with_valid(out, meta)


def _with_valid(out: dict, meta: dict) -> dict:
    """Add ``valid`` (H, W) float32 in {0, 1} from the mask the sidecar names, if any."""
    out["valid"] = None
    if meta.get("valid"):
        path = Path(meta["_path"]).parent / meta["valid"]
        if not path.is_file():
            raise FileNotFoundError(f"validity mask {str(path)!r} named by the map metadata is missing")
        out["valid"] = (read_png_raw(path)[..., 0] > 127).astype(np.float32)
    return out
