"""Blender's Cycles bakes: the peer of ``bench bake_blender``.

Cycles runs in a separate Python that has ``bpy`` (Blender as a module: ``pip install bpy``,
about 375 MB; Blender 5.0 wants Python 3.11), named by ``$MI_DISPLACE_BLENDER_PYTHON``
(default ``python3``); :mod:`.blender_side` is the script it runs.  :func:`bake` raises
:class:`~mi_displace.bench.peers.PeerUnavailable` when that Python cannot import ``bpy``.
"""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np

from mi_displace.bench.peers import PeerUnavailable

#: The maps :mod:`.blender_side` bakes, each (H, W, 4) float32, row 0 = top (v = 1).
MAPS = ("normal_tangent", "normal_object", "position_high", "position_low", "normal_low",
        "normal_tangent_directx")
#: the maps it bakes too when given AO settings
AO_MAPS = ("ao", "pointiness")


def python() -> str:
    """The Blender Python (``$MI_DISPLACE_BLENDER_PYTHON``, default ``python3``), checked to
    import ``bpy``."""
    name = os.environ.get("MI_DISPLACE_BLENDER_PYTHON", "python3")
    try:
        check = subprocess.run([name, "-c", "import bpy"], capture_output=True)
    except OSError as error:
        raise PeerUnavailable(f"MI_DISPLACE_BLENDER_PYTHON={name!r} does not run ({error})") from error
    if check.returncode != 0:
        raise PeerUnavailable(
            f"MI_DISPLACE_BLENDER_PYTHON={name!r} cannot import bpy; python3.11 -m venv /tmp/bpy "
            "&& /tmp/bpy/bin/pip install bpy, then MI_DISPLACE_BLENDER_PYTHON=/tmp/bpy/bin/python")
    return name


def bake(high_obj: Path, low_obj: Path, res: int, max_distance: float, out_dir: Path,
         ao_samples: int = 0, ao_distance: float = 1.0, texture: Path | None = None) -> dict:
    """Cycles' selected-to-active bakes of ``high_obj`` onto ``low_obj`` (OBJ files) at
    ``res`` x ``res`` texels with cage extrusion ``max_distance`` (object units); with
    ``ao_samples``, also AO (that many samples, rays of ``ao_distance``) and pointiness;
    with ``texture`` (an sRGB image for the high-poly's UVs), only ``albedo``.

    Returns:
        ``{"maps": {name: (res, res, 4) float32 for name in MAPS}, "version": Blender's,
        "seconds": {name: seconds of its bpy.ops.object.bake call}}``.
    """
    subprocess.run([python(), str(Path(__file__).with_name("blender_side.py")), str(high_obj),
                    str(low_obj), str(res), repr(max_distance), str(out_dir),
                    *(["albedo", str(texture)] if texture is not None else
                      [str(ao_samples), repr(ao_distance)] if ao_samples else [])],
                   check=True, capture_output=True)
    record = json.loads((out_dir / "blender.json").read_text())
    names = ("albedo",) if texture is not None else MAPS + (AO_MAPS if ao_samples else ())
    return {"maps": {name: np.load(out_dir / f"{name}.npy") for name in names},
            "version": record["version"], "seconds": record["seconds"]}
