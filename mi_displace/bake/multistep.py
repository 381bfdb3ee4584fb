"""Multistep displacement (§4, Fig. 9): high -> intermediate -> low with two maps.

A feature that is not a height field over the low-poly (an overhang: the low-poly's normal
line crosses it twice) cannot be stored in one map.  With an intermediate model that is a
height field over the low-poly *and* over which the original is a height field, two maps do:

* stage 1: bake the intermediate over the low-poly (map 1);
* restore R1 = restore(low, map 1, levels_1) — it inherits the low-poly's UV layout;
* stage 2: bake the original over R1 (map 2, same UV layout).

Restoration needs only the low-poly and the two maps: R1 is rebuilt from low + map 1 (the
same deterministic code), then restored with map 2.  "None of [the intermediate models] are
needed for surface restoration" (§4).

:func:`leaning_horn_sphere` builds the measured example: a unit sphere with a Gaussian horn
displaced along a direction tilted by ``tilt`` from the normal (a vector displacement); with
a large tilt its tip hangs over the sphere.  The intermediate is the same horn tilted half
as far.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData
from mi_displace.bake.restore import Restored, restore


@dataclass
class MultistepResult:
    """Counts of both stages' bakes and the stage-1 restoration."""

    stage1: dict
    stage2: dict
    intermediate_faces: int


def _as_mesh(r: Restored, name: str) -> MeshData:
    return MeshData(r.positions, r.faces.astype(np.int64), r.uvs, name=name)


def multistep_bake(high: MeshData, intermediate: MeshData, low: MeshData, out_dir, res: int,
                   levels1: int = 2, max_distance1: float | None = None,
                   max_distance2: float | None = None, **bake_args) -> MultistepResult:
    """Bake ``out_dir/stage1`` (intermediate over low) and ``out_dir/stage2`` (high over R1).

    ``low`` must have UVs (stage 2 reuses its layout through R1); maps are written in the
    ``float`` format (plus whatever ``map_formats`` adds).  Each stage has its own
    ``max_distance`` [object units]: stage 2 measures only the small residual.
    """
    if low.uvs is None:
        raise ValueError("low: multistep baking needs a low-poly with UVs (both maps share them)")
    out_dir = Path(out_dir)
    fmts = bake_args.pop("map_formats", ["float"])
    b1 = bake(intermediate, low, res=res, out_dir=out_dir / "stage1", map_formats=fmts,
              max_distance=max_distance1, **bake_args)
    r1 = restore(out_dir / "stage1" / "low.obj", out_dir / "stage1" / "float.exr", levels=levels1,
                 keep_holes=False)
    b2 = bake(high, _as_mesh(r1, "stage1_restored"), res=res, out_dir=out_dir / "stage2",
              map_formats=fmts, max_distance=max_distance2, **bake_args)
    return MultistepResult(b1.record, b2.record, len(r1.faces))


def multistep_restore(low, map1, map2, levels1: int = 2, levels2: int = 1) -> Restored:
    """Restore from the low-poly and both maps (R1 = low + map 1, then R1 + map 2)."""
    r1 = restore(low, map1, levels=levels1, keep_holes=False)
    return restore(_as_mesh(r1, "stage1_restored"), map2, levels=levels2)


def leaning_horn_sphere(nu: int, nv: int, height: float = 0.5, width: float = 0.25,
                        tilt_deg: float = 60.0) -> MeshData:
    """Unit sphere (nu x nv grid with UVs) + a Gaussian horn at +x leaning towards +y.

    P = S + height * exp(-|S - c|^2 / width^2) * normalize(n cos(tilt) + t sin(tilt)),
    c = (1, 0, 0), t the unit tangent towards +y.  Units: object units (sphere radius 1).
    """
    from mi_displace.core import surfaces, tessellate

    base = surfaces.make_base("sphere", radius=1.0)
    t = tessellate.displace_parametric(base, None, 0.0, 0.0, nu, nv)
    p = np.stack([np.asarray(c) for c in t.positions], 1).astype(np.float64)
    uv = np.stack([np.asarray(c) for c in t.texcoords], 1).astype(np.float32)
    faces = np.stack([np.asarray(c) for c in t.faces], 1).astype(np.int64)
    n = p / np.linalg.norm(p, axis=1, keepdims=True)
    g = np.exp(-np.sum((p - [1.0, 0.0, 0.0]) ** 2, axis=1) / width ** 2)
    ey = np.array([0.0, 1.0, 0.0])
    tan = ey - n * (n @ ey)[:, None]
    tan /= np.maximum(np.linalg.norm(tan, axis=1, keepdims=True), 1e-12)
    a = np.radians(tilt_deg)
    w = n * np.cos(a) + tan * np.sin(a)
    return MeshData((p + height * g[:, None] * w).astype(np.float32), faces, uv,
                    name=f"horn_{tilt_deg:g}")
