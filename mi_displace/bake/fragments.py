"""Mitsuba scene fragments written beside a bake's maps: one ``<scene>`` file per way to use them.

Each fragment holds one ``<shape>`` (object units of the low-poly, no ``to_world``) and
names its files by absolute path (Mitsuba resolves the names in an included file against
the *including* scene's folder, so relative names would break); include it from a scene
with ``<include filename="bake_out/mitsuba_displaced.xml"/>``.  Moving the bake folder
means baking again or editing the paths.

===============================  ===========================================================
fragment                         shape
===============================  ===========================================================
``mitsuba_displaced.xml``        ``displaced`` over ``low.obj`` with the displacement map
                                 (d16, else float, else d8) as a raw ``bitmap``: ``scale``
                                 = (2^bits - 1) * s and ``midlevel`` = -offset / scale from
                                 the sidecar (d = offset + s q, q = (2^bits - 1) h);
                                 ``edge_length`` = one texel's mean object size
``mitsuba_restored.xml``         ``restored`` from the same map, ``levels="auto"``
``mitsuba_normalmap.xml``        ``low.obj`` under ``mikk_normalmap`` (normal_tangent.png,
                                 ``green`` as baked)
``mitsuba_normalmap_stock.xml``  ``low.obj`` under Mitsuba's ``normalmap`` (normal_mitsuba.png)
===============================  ===========================================================

A fragment is written when its map is among the bake's formats.
"""
from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from mi_displace.bake import formats
from mi_displace.bake.meshdata import MeshData

#: displacement maps a ``displaced`` shape reads (one channel), in order of preference
DISPLACEMENT_MAPS = ("d16", "float", "d8")

_BITMAP = ('<texture name="{name}" type="bitmap"><string name="filename" value={file}/>'
           '<boolean name="raw" value="true"/></texture>')


def _path(path) -> str:
    """An absolute path as a quoted, escaped XML attribute value."""
    return quoteattr(str(path))


def texel_size(low: MeshData, width: int, height: int) -> float:
    """Mean object-space side of one texel over the low-poly [object units]:
    sqrt(surface area / (UV area * width * height))."""
    p, uv, f = low.positions.astype(np.float64), low.uvs.astype(np.float64), low.faces
    area = np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1).sum() / 2
    a, b = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
    uv_area = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum() / 2
    return float(np.sqrt(area / max(uv_area * width * height, 1e-30)))


def _scene(shape: str) -> str:
    return f'<scene version="3.0.0">\n    {shape}\n</scene>\n'


def _low_with(out_dir: Path, bsdf: str, map_file: str, extra: str = "") -> str:
    texture = _BITMAP.format(name="normalmap", file=_path(out_dir / map_file))
    return (f'<shape type="obj"><string name="filename" value={_path(out_dir / "low.obj")}/>'
            f'<bsdf type="{bsdf}">{extra}{texture}<bsdf type="diffuse"/></bsdf></shape>')


def write_fragments(out_dir: Path, map_formats, low: MeshData, green: str = "+y") -> list[str]:
    """Write the fragments the bake's ``map_formats`` allow (see the module docstring);
    returns their file names.  The maps and their sidecars must already be in ``out_dir``;
    ``green``: the convention of ``normal_tangent.png``, passed on to ``mikk_normalmap``."""
    out_dir = Path(out_dir).resolve()
    written = {}
    disp = next((f for f in DISPLACEMENT_MAPS if f in map_formats), None)
    if disp is not None:
        meta = formats.read_metadata(out_dir / f"{disp}{formats.FORMATS[disp]}")
        q = meta["displacement"]
        steps = 1.0 if q["bits"] == 32 else float((1 << q["bits"]) - 1)
        scale = steps * q["scale"]
        edge = texel_size(low, meta["width"], meta["height"])
        written["mitsuba_displaced.xml"] = _scene(
            f'<shape type="displaced"><string name="base" value="mesh"/>'
            f'<string name="filename" value={_path(out_dir / "low.obj")}/>'
            f'{_BITMAP.format(name="height", file=_path(meta["_path"]))}'
            f'<float name="scale" value="{scale!r}"/><float name="midlevel" value="{-q["offset"] / scale!r}"/>'
            f'<float name="edge_length" value="{edge!r}"/></shape>')
        written["mitsuba_restored.xml"] = _scene(
            f'<shape type="restored"><string name="map" value={_path(meta["_path"])}/>'
            f'<string name="levels" value="auto"/></shape>')
    if "normal_tangent" in map_formats:
        written["mitsuba_normalmap.xml"] = _scene(_low_with(
            out_dir, "mikk_normalmap", "normal_tangent.png", f'<string name="green" value="{green}"/>'))
    if "normal_mitsuba" in map_formats:
        written["mitsuba_normalmap_stock.xml"] = _scene(_low_with(out_dir, "normalmap", "normal_mitsuba.png"))
    for name, text in written.items():
        (out_dir / name).write_text(text)
    return list(written)
