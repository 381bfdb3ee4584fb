"""Load and render Mitsuba scenes with wall-clock timings and per-shape build statistics.

:func:`load` times ``mi.load_file`` end to end (``build_s``: XML parsing, plugin
construction — including our plugins' tessellation kernels — and Mitsuba's acceleration
structure build).  Our shape plugins expose what they built as a ``build_stats`` dict
attribute (e.g. ``{"tessellate_s": 0.12, "vertices": 66049, "faces": 131072,
"bytes": 3_000_000}``); ``scene.shapes()`` returns the Python objects of Python-defined
shapes, so :func:`shape_stats` can collect them.

:func:`render` times ``mi.render`` *including* the evaluation of the image to NumPy (the
JIT's queued work is synchronised before the clock starts and the image is fetched before
it stops), so warm and cold timings are wall seconds of complete renders.

A scene that Mitsuba refuses (XML error, unknown plugin, unused ``-D`` parameter, a plugin's
``ValueError``) raises ``ValueError`` naming the file; a plugin's ``FileNotFoundError``
stays a ``FileNotFoundError``.  Other plugin failures (bugs) stay ``RuntimeError``.
"""
from __future__ import annotations

import os
import re
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mi_displace.bake.mitsuba_frames import prepare_scene
from mi_displace.core.backend import ensure_registered
from mi_displace.core.dicing import fit_to_sensors
from mi_displace.core.progress import bar as progress_bar

#: Largest number of samples (pixels x spp) rendered in one ``mi.render`` call; larger
#: requests are split into passes with distinct seeds and averaged.
MAX_SAMPLES_PER_PASS = 1 << 24

_PY_ERROR = re.compile(r"\n(ValueError|FileNotFoundError): (.*)\Z", re.S)
_PY_TRACEBACK = "Traceback (most recent call last):"
_XML_POSITION = re.compile(r"Error while loading (.+?) \(line (\d+), col (\d+)\):")


def _name_xml_property(where: str) -> str:
    """Add the property name to Mitsuba's XML value errors, which give only line and column
    (``... (line 8, col 66): could not parse floating point value "big"``)."""
    match = _XML_POSITION.search(where)
    if not match:
        return where
    try:
        line = Path(match.group(1)).read_text(errors="replace").splitlines()[int(match.group(2)) - 1]
    except (OSError, IndexError):
        return where
    start = line.rfind("<", 0, int(match.group(3)))  # the column is the element's "<"
    tag = line[start:line.find(">", start) + 1] if start >= 0 else ""
    name = re.search(r'\bname\s*=\s*"([^"]*)"', tag)
    if not name:
        return where
    return f"{where[:match.end()]} {tag.split()[0][1:]} {name.group(1)!r}:{where[match.end():]}"


def _translate_load_error(path: Path, error: RuntimeError) -> Exception:
    """Map Mitsuba's wrapped loading errors to the exception a user should see."""
    message = str(error)
    where = re.sub(r"^\[[\w.]+:\d+\]\s*", "", message.split(_PY_TRACEBACK)[0])
    where = " ".join(where.split())
    where = _name_xml_property(where)
    match = _PY_ERROR.search(message)
    if match:  # a Python plugin raised ValueError / FileNotFoundError: keep its type
        kind = FileNotFoundError if match.group(1) == "FileNotFoundError" else ValueError
        return kind(f"scene {str(path)!r}: {where} {match.group(2).strip()}")
    if _PY_TRACEBACK in message:  # any other Python exception in a plugin is a bug
        return error
    return ValueError(f"scene {str(path)!r}: {where}")


def _user_error_inside(error: RuntimeError) -> Exception:
    """The ``ValueError`` / ``FileNotFoundError`` that a plugin raised while ``mi.render``
    traced it (Dr.Jit wraps it in a ``RuntimeError``), else ``error`` itself (a bug)."""
    cause = error
    while cause is not None:
        if isinstance(cause, (ValueError, FileNotFoundError)):
            return cause
        cause = cause.__cause__ or cause.__context__
    return error


def check_params(params: dict | None, what: str = "params") -> dict[str, str]:
    """Validate XML parameters: identifier names, values converted to ``str``."""
    params = dict(params or {})
    for name in params:
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_]\w*", name):
            raise ValueError(f"{what}: parameter name {name!r} is not an identifier")
    return {name: str(value) for name, value in params.items()}


def shape_stats(scene) -> list[dict]:
    """Build statistics of every shape that reports them.

    Returns:
        One dict per shape with a ``build_stats`` attribute: ``{"id", "type", **build_stats}``
        (``type`` is the Python class name), in ``scene.shapes()`` order.
    """
    stats = []
    for index, shape in enumerate(scene.shapes()):
        build_stats = getattr(shape, "build_stats", None)
        if isinstance(build_stats, dict):
            stats.append(
                {"id": shape.id() or f"shape_{index}", "type": type(shape).__name__, **build_stats}
            )
    return stats


def explain(scene) -> list[dict]:
    """What every plugin of ``scene`` built and why (``mi-displace render --explain``).

    The protocol: any shape, or BSDF attached to a shape, with a ``build_stats`` dict
    attribute is reported, as ``{"id", "kind" ("shape"/"bsdf"), "type", **build_stats}``
    (a BSDF shared by several shapes once).  A plugin opts in by setting the attribute.
    """
    rows, seen = [], set()
    for index, shape in enumerate(scene.shapes()):
        objects = [("shape", shape, shape.id() or f"shape_{index}")]
        bsdf = shape.bsdf()
        if bsdf is not None:
            objects.append(("bsdf", bsdf, bsdf.id() or f"bsdf_of_{objects[0][2]}"))
        for kind, obj, name in objects:
            stats = getattr(obj, "build_stats", None)
            if isinstance(stats, dict) and id(obj) not in seen:
                seen.add(id(obj))
                rows.append({"id": name, "kind": kind, "type": type(obj).__name__, **stats})
    return rows


def load(path: str | os.PathLike, **params) -> tuple[mi.Scene, dict]:
    """Load a scene XML file with ``$name`` parameters and time it.

    Args:
        path: the scene file.
        **params: XML parameters (``<default name=...>`` overrides), values turned to str.

    Returns:
        ``(scene, timings)`` where ``timings = {"build_s": seconds, "spp": the sampler's
        sample count as loaded, "shapes": shape_stats}`` (``mi.render(spp=...)`` changes the
        sampler's count afterwards, so read it here).

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: Mitsuba rejects the scene or a parameter (message names the file), or
            the scene has no integrator or no sensor, or a shape's BSDF is not set up
            (its ``setup_problem()``: a ``vdm`` without ``tile_size`` outside a ``vdm_mesh``),
            or the integrator cannot render the scene (its ``setup_problem(scene)``: an
            emitter ``raster`` does not model).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
    params = check_params(params)
    if mi.variant() is None:
        raise RuntimeError("no Mitsuba variant is set: call mi_displace.init() first")
    ensure_registered()            # the plugins of the variant set now (after mi.set_variant)
    dr.sync_thread()
    start = time.perf_counter()
    try:
        scene = mi.load_file(str(path), **params)
        # shapes sized for the scene's sensors but referencing none of their own
        fit_to_sensors(scene)
    except RuntimeError as e:
        raise _translate_load_error(path, e) from None
    prepare_scene(scene)           # BSDFs decoding in a frame of their own (mikk_normalmap)
    for shape in scene.shapes():   # a BSDF that cannot render what it models (vdm without a tile size)
        problem = getattr(shape.bsdf(), "setup_problem", lambda: None)()
        if problem:
            raise ValueError(f"scene {str(path)!r}: {problem}")
    # an integrator that cannot render the scene (raster: an emitter it does not model)
    problem = getattr(scene.integrator(), "setup_problem", lambda scene: None)(scene)
    if problem:
        raise ValueError(f"scene {str(path)!r}: {problem}")
    dr.sync_thread()
    build_s = time.perf_counter() - start
    for what, found in (("integrator", scene.integrator()), ("sensor", scene.sensors())):
        if not found:
            raise ValueError(f"scene {str(path)!r} has no <{what}>: add one (e.g. "
                             f"<{what} type=\"{'path' if what == 'integrator' else 'perspective'}\"/>)")
    return scene, {"build_s": build_s, "spp": scene_spp(scene), "shapes": shape_stats(scene)}


def scene_spp(scene, sensor: int = 0) -> int:
    """The current sample count of the scene's sensor's sampler.

    Note that ``mi.render(scene, spp=n)`` sets it to ``n`` for later renders.
    """
    return int(scene.sensors()[sensor].sampler().sample_count())


def _pass_seed(seed: int, index: int) -> int:
    """Seed of pass ``index`` of a render seeded ``seed`` (pass 0 keeps ``seed``)."""
    if index == 0:
        return seed
    h = (seed * 0x9E3779B1 + index * 0x85EBCA77 + 0x632BE5AB) & 0xFFFFFFFF
    h ^= h >> 16
    h = (h * 0x7FEB352D) & 0xFFFFFFFF
    return h ^ (h >> 15)


def render(scene, spp: int | None = None, seed: int = 0, sensor: int = 0,
           progress: bool | None = False, integrator=None) -> tuple[np.ndarray, float]:
    """Render a scene to a linear float32 ``(H, W, 3)`` NumPy image and time it.

    Requests of more than :data:`MAX_SAMPLES_PER_PASS` samples are split into passes of
    equal spp (distinct seeds derived from ``seed``) averaged with weights proportional to
    their spp; ``progress`` shows a bar over the passes (:func:`mi_displace.core.progress.bar`).

    Args:
        scene: a loaded ``mi.Scene``.
        spp: samples per pixel; ``None`` uses the sensor's current sampler count (what the
            scene declared, unless an earlier render passed another ``spp``).
        seed: seed of the sampler (pass 0 uses it unchanged: one pass equals
            ``mi.render(scene, spp=spp, seed=seed)``).
        sensor: sensor index.
        progress: show a progress bar when there are several passes (``None``: on a
            terminal, see :mod:`mi_displace.core.progress`).
        integrator: an ``mi.Integrator`` to render with instead of the scene's (e.g. an
            ``aov`` integrator wrapping it); then every channel the film develops is kept,
            ``(H, W, C)``, RGB first and the integrator's AOVs after it.

    Returns:
        ``(image, seconds)``: wall seconds of the whole render including the transfer to NumPy.

    Raises:
        ValueError, FileNotFoundError: bad arguments, or a plugin refused its input while
            the render was traced (unwrapped from Dr.Jit's ``RuntimeError``).
    """
    if spp is not None and (not isinstance(spp, (int, np.integer)) or spp < 1):
        raise ValueError(f"spp: must be a positive integer, got {spp!r}")
    if not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise ValueError(f"seed: must be an integer in [0, 2^32), got {seed!r}")
    if not 0 <= sensor < len(scene.sensors()):
        raise ValueError(f"sensor: index {sensor} out of range, the scene has {len(scene.sensors())}")
    total = int(spp) if spp is not None else scene_spp(scene, sensor)
    width, height = scene.sensors()[sensor].film().crop_size()
    per_pass = max(1, min(total, MAX_SAMPLES_PER_PASS // max(1, width * height)))
    passes = [per_pass] * (total // per_pass) + ([total % per_pass] if total % per_pass else [])

    bar = progress_bar(total, "render", "spp", enabled=progress if len(passes) > 1 else False)
    dr.sync_thread()
    start = time.perf_counter()
    image = None
    for index, count in enumerate(passes):
        try:
            rendered = mi.render(scene, spp=count, seed=_pass_seed(int(seed), index), sensor=sensor,
                                 integrator=integrator)
        except RuntimeError as e:
            raise _user_error_inside(e) from None
        part = np.asarray(rendered, dtype=np.float32)
        part = (part if integrator is not None else part[..., :3]) * (count / total)
        image = part if image is None else image + part
        bar.update(count)
    seconds = time.perf_counter() - start
    bar.close()
    return np.ascontiguousarray(image, dtype=np.float32), seconds


def apply_edits(scene, edits: dict) -> None:
    """Set ``mi.traverse`` parameters of a loaded scene and update it.

    Args:
        scene: a loaded ``mi.Scene``.
        edits: ``{"shape_id.param": value}``; values (numbers or their text) are converted to
            the parameter's current type (a scalar Dr.Jit array, ``int``, ``float`` or ``bool``).

    Raises:
        ValueError: a key the scene does not have (closest keys named), or a value that cannot
            be converted.
    """
    import difflib

    params = mi.traverse(scene)
    for key, value in edits.items():
        if key not in params:
            close = difflib.get_close_matches(key, list(params.keys()), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ValueError(f"scene parameter {key!r} does not exist (mi.traverse){hint}")
        current = params[key]
        try:
            number = float(value)
            if isinstance(current, bool):
                new = bool(number)
            elif isinstance(current, int):
                if number != int(number):
                    raise ValueError
                new = int(number)
            elif isinstance(current, float):
                new = number
            else:
                new = type(current)(number)
        except (TypeError, ValueError):
            raise ValueError(f"scene parameter {key!r}: cannot set {value!r} "
                             f"(current value {current!r})") from None
        params[key] = new
    params.update()
