"""Animation (§6, Figs. 1 and 6): a map parameter stepped through ``mi.traverse`` — only that
map's D_k is re-sampled, the object textures stay — one frame per value, in one call."""
from __future__ import annotations

import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np


def frame_values(start: float, stop: float, frames: int) -> np.ndarray:
    """``frames`` values from start to stop inclusive (a progressing cut or peel)."""
    if not isinstance(frames, (int, np.integer)) or frames < 1:
        raise ValueError(f"frames: must be a positive integer, got {frames!r}")
    if not (np.isfinite(start) and np.isfinite(stop)):
        raise ValueError(f"start/stop must be finite, got {start}, {stop}")
    return np.linspace(start, stop, frames) if frames > 1 else np.array([float(start)])


def render_frames(scene: mi.Scene, key: str, values, out_dir, spp: int | None = None) -> list[dict]:
    """Set ``params[key]`` to each value, update, render, write ``out_dir/frame_NNNN.png``.

    Args:
        key: a scene parameter, e.g. ``volume.map0_angle`` (``mi.traverse`` name).
    Returns:
        One record per frame: value, file, update_s (re-sampling the edited D_k), render_s.
    """
    from mi_displace.core.io import write_image
    from mi_displace.evaluate.metrics import assert_finite

    params = mi.traverse(scene)
    if key not in params:
        editable = [k for k in params.keys() if "_map" in k or ".map" in k]
        raise ValueError(f"parameter {key!r} is not in the scene; editable map parameters: "
                         f"{', '.join(editable) or 'none'}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    records = []
    for i, value in enumerate(values):
        start = time.perf_counter()
        params[key] = float(value)
        params.update()
        dr.sync_thread()
        update_s = time.perf_counter() - start
        start = time.perf_counter()
        image = np.array(mi.render(scene, spp=spp or 1, seed=i))[..., :3]
        render_s = time.perf_counter() - start
        assert_finite(image, f"frame {i} ({key} = {value})")
        path = write_image(out_dir / f"frame_{i:04d}.png", image)
        records.append({"value": float(value), "file": str(path), "update_s": update_s, "render_s": render_s})
    return records
