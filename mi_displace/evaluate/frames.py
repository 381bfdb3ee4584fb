"""Animation frames as independent jobs: ``mi.traverse`` edits stepped over a frame range.

``mi-displace animate SCENE.xml --edit ID.PARAM=A:B [--edit ...] --frames N --out DIR``
renders frame ``i`` with every edited parameter at ``A + (B - A) * i / N`` (the end is
excluded, so a periodic animation loops without a repeated frame; ``--endpoint``:
``A + (B - A) * i / (N - 1)``, first and last frame at A and B, for a progressing cut).  Frames are split into
chunks; each chunk is one job (:func:`mi_displace.evaluate.jobs.run_jobs`) that loads the
scene once and renders its frames through ``mi.traverse`` edits (no rebuild of what the
edit does not change), so ``--cluster`` spreads chunks over workers.  The PNG bytes come back
to the caller, who writes ``DIR/frame_NNNN.png`` and ``DIR/frames.json`` (per frame: the
edited values, the edit's ``params.update()`` time, the render time and the host); the result
is the same image for image whichever machine rendered it (same seeds per frame).

``ddm-animate`` (``ID.time`` over ``[0, duration)``) and ``volume-animate`` (one map
parameter, end included) are this command with their own option names.
"""
from __future__ import annotations

import json
import re
import tempfile
from pathlib import Path

import numpy as np

from mi_displace.evaluate.jobs import run_jobs
from mi_displace.render import scene as scenes


def parse_edit(text: str) -> tuple[str, float, float]:
    """``ID.PARAM=A:B`` as ``(key, A, B)``.

    Raises:
        ValueError: malformed, or ``A``/``B`` not finite numbers.
    """
    match = re.fullmatch(r"\s*([\w\-]+(?:\.[\w\-]+)+)\s*=\s*([^:]+):([^:]+)\s*", text)
    if not match:
        raise ValueError(f"--edit: expected ID.PARAM=START:STOP, got {text!r}")
    try:
        start, stop = float(match.group(2)), float(match.group(3))
    except ValueError:
        raise ValueError(f"--edit: START and STOP must be numbers, got {text!r}") from None
    if not (np.isfinite(start) and np.isfinite(stop)):
        raise ValueError(f"--edit: START and STOP must be finite, got {text!r}")
    return match.group(1), start, stop


def frame_edits(edits: list[tuple[str, float, float]], frames: int,
                endpoint: bool = False) -> list[dict]:
    """The ``{key: value}`` of every frame (module docstring; ``endpoint``: B included)."""
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise ValueError(f"--frames: must be a positive integer, got {frames!r}")
    steps = frames - 1 if endpoint and frames > 1 else frames
    return [{key: start + (stop - start) * i / steps for key, start, stop in edits}
            for i in range(frames)]


def render_chunk(scene_path: str, params: dict, frames: list[tuple[int, dict]],
                 spp: int | None, seed: int) -> list[dict]:
    """One job: load the scene once, render each ``(index, edits)`` frame.

    Returns:
        ``[{"index", "png" (bytes, 8-bit sRGB), "render_s", "edit_s"}]``.
    """
    import time

    from mi_displace.core.io import write_png
    from mi_displace.evaluate.metrics import assert_finite

    scene, _ = scenes.load(scene_path, **params)
    out = []
    with tempfile.TemporaryDirectory(prefix="mi_displace_frames_") as tmp:
        for index, edits in frames:
            start = time.perf_counter()
            scenes.apply_edits(scene, edits)
            edit_s = time.perf_counter() - start
            image, seconds = scenes.render(scene, spp=spp, seed=seed + index)
            assert_finite(image, f"frame {index} ({edits})")
            path = write_png(Path(tmp) / f"{index}.png", image)
            out.append({"index": index, "png": path.read_bytes(), "render_s": seconds,
                        "edit_s": edit_s})
    return out


def animate(scene_path, edits: list[tuple[str, float, float]], frames: int, out_dir,
            params: dict | None = None, spp: int | None = None, seed: int = 0,
            chunk: int = 8, cluster: str | None = None, progress: bool | None = False,
            endpoint: bool = False) -> dict:
    """Render the frames (module docstring) and write ``out_dir/frame_NNNN.png``.

    Args:
        scene_path: any scene XML.
        edits: ``(key, start, stop)`` triples (:func:`parse_edit`).
        frames: number of frames.
        out_dir: output folder.
        params: XML parameters.
        spp: samples per pixel (``None``: the scene's); frame ``i`` uses seed ``seed + i``.
        chunk: frames per job.
        cluster: ``None``, ``"local:N"`` or a Dask scheduler address.
        progress: a progress bar over the chunks.
        endpoint: the last frame at the edits' end values (module docstring).

    Returns:
        ``{"frames": [paths], "edits": [values per frame], "render_s", "edit_s", "hosts"
        (per frame), "failed": {chunk: message}}``, also written to ``out_dir/frames.json``.

    Raises:
        ValueError: bad arguments or a key the scene does not have (checked by loading the
            scene once before any job starts).
    """
    if not edits:
        raise ValueError("--edit: give at least one ID.PARAM=START:STOP")
    per_frame = frame_edits(edits, frames, endpoint)
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk: must be a positive integer, got {chunk!r}")
    params = scenes.check_params(params)
    scene, _ = scenes.load(scene_path, **params)
    scenes.apply_edits(scene, per_frame[0])  # refuses unknown keys before any job runs
    del scene
    indexed = list(enumerate(per_frame))
    jobs = [{"scene_path": str(scene_path), "params": params, "frames": indexed[i:i + chunk],
             "spp": spp, "seed": seed} for i in range(0, frames, chunk)]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths, render_s, edit_s, hosts = ([None] * frames for _ in range(4))
    failed = {}

    def done(job_index, outcome):
        if not outcome["ok"]:
            failed[job_index] = outcome["error"]
            return
        for frame in outcome["value"]:
            path = out_dir / f"frame_{frame['index']:04d}.png"
            path.write_bytes(frame["png"])
            paths[frame["index"]] = path
            render_s[frame["index"]] = frame["render_s"]
            edit_s[frame["index"]] = frame["edit_s"]
            hosts[frame["index"]] = outcome["host"]

    run_jobs(render_chunk, jobs, cluster=cluster, on_result=done, progress=progress,
             desc="frames")
    records = [{"index": i, "file": None if p is None else p.name, "edits": per_frame[i],
                "edit_s": edit_s[i], "render_s": render_s[i], "host": hosts[i]}
               for i, p in enumerate(paths)]
    (out_dir / "frames.json").write_text(json.dumps({"frames": records, "failed": failed},
                                                    indent=2))
    return {"frames": paths, "edits": per_frame, "render_s": render_s, "edit_s": edit_s,
            "hosts": hosts, "failed": failed}
