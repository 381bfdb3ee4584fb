"""Bad input to every plugin: one clear error naming the parameter or file, before any kernel.

The sweep is plugin x {misspelt parameter, wrong type, non-finite value, missing file,
garbage file} (the file cases only where the plugin reads files).  Each case loads a
dictionary through ``mi.load_dict`` and passes the error through the translation the CLI and
``render.scene.load`` use, so what is asserted is what a user reads:

* the error is a ``ValueError`` / ``FileNotFoundError`` (not a bug's traceback) whose message
  names the parameter (or the file) in quotes;
* for everything but the misspelt parameter, Dr.Jit compiled and launched no kernel while the plugin under
  test was loaded (nested objects are instantiated beforehand, so their own set-up kernels do
  not count; memory operations such as a 1-element memset are not kernels).  A misspelt parameter is found by Mitsuba's "unreferenced property" check, which
  runs after the constructor returns, i.e. after the plugin's build: only the message is
  asserted there (docs/testing.md).

Plugins from other branches join by adding a row to :data:`CASES`.  Cases that fail today in
code owned elsewhere are ``xfail(strict=True)`` with the reason, so they flip when fixed.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mi_displace.plugins import PLUGIN_MODULES
from mi_displace.render import scene as scenes

NAN = math.nan

def _garbage(tmp_path: Path, suffix: str) -> str:
    path = tmp_path / f"garbage{suffix}"
    path.write_bytes(b"this is not a " + suffix[1:].encode() + b" file\n\x00\xff\xfe junk\n" * 8)
    return str(path)


def _missing(tmp_path: Path, suffix: str) -> str:
    return str(tmp_path / f"no_such_file{suffix}")


# plugin -> {case: (dict builder, the name the message must quote)}; a builder takes
# (tmp_path, nested) where nested holds pre-built objects (see _nested).
def _displaced(extra):
    return lambda tmp, n: {"type": "displaced", "base": "sphere", "resolution": 8,
                           "height": n["cells"], **extra(tmp)}


def _ddm(extra):
    return lambda tmp, n: {"type": "ddm", "base": "plane", "tiles_u": 2, "tiles_v": 2,
                           "mode": "exact", **extra(tmp)}


def _vdm_mesh(extra):
    return lambda tmp, n: {"type": "vdm_mesh", "base": "sphere", "resolution": 8, **extra(tmp)}


def _bsdf(kind, extra):
    return lambda tmp, n: {"type": kind, "height": n["cells"], "depth": 0.05, **extra(tmp)}


BUNNY_MAP = Path(__file__).resolve().parents[1] / "scenes" / "parts" / "bake_bunny" / "d16.png"


def _restored(extra):
    return lambda tmp, n: {"type": "restored", "map": str(BUNNY_MAP), "levels": 1, **extra(tmp)}


def _mikk(extra):
    return lambda tmp, n: {"type": "mikk_normalmap", "nested": {"type": "diffuse"}, **extra(tmp, n)}


def _garbage_map(tmp_path: Path, suffix: str = ".png") -> str:
    """A garbage PNG (or EXR: the "float" format) next to a valid sidecar (so the image
    itself is what fails)."""
    path = _garbage(tmp_path, suffix)
    meta = json.loads(Path(f"{BUNNY_MAP}.json").read_text())
    meta["low"] = str(BUNNY_MAP.parent / meta["low"])
    meta["valid"], meta["file"] = None, Path(path).name
    if suffix == ".exr":
        meta["format"] = "float"
    Path(f"{path}.json").write_text(json.dumps(meta))
    return path


def _texture(kind, extra):
    return lambda tmp, n: {"type": kind, **extra(tmp)}


def _raster(extra):
    return lambda tmp, n: {"type": "raster", **extra(tmp)}


def _slicing(extra):
    return lambda tmp, n: {"type": "slicing", "base": "plane", "slices": 4, "height": n["cells"],
                           **extra(tmp)}


CUP_IMAGES = BUNNY_MAP.parents[1] / "slicing_cup_depth" / "cube.json"


def _depth_object(extra):
    return lambda tmp, n: {"type": "depth_object", "filename": str(CUP_IMAGES), "slices": 8,
                           **extra(tmp)}


PIGGY = {"type": "displaced_volume", "procedural": "piggy_bank", "resolution": 16}


def _volume(extra, procedural=True):
    base = dict(PIGGY) if procedural else {"type": "displaced_volume"}
    return lambda tmp, n: {**base, **extra(tmp)}


def _of_volume(kind, extra):
    return lambda tmp, n: {"type": kind, "volume": dict(PIGGY), **extra(tmp)}




CASES = {
    "displaced": {
        "misspelt": (_displaced(lambda t: {"scael": 0.1}), "scael"),
        "wrong_type": (_displaced(lambda t: {"scale": "big"}), "scale"),
        "non_finite": (_displaced(lambda t: {"scale": NAN}), "scale"),
        "object_for_number": (lambda t, n: {**_displaced(lambda t: {})(t, n), "midlevel": n["cells"]},
                              "midlevel"),
        "missing_file": (_displaced(lambda t: {"base": "mesh", "filename": _missing(t, ".obj")}),
                         "no_such_file.obj"),
        "garbage_file": (_displaced(lambda t: {"base": "mesh", "filename": _garbage(t, ".obj")}),
                         "garbage.obj"),
    },
    "ddm": {
        "misspelt": (_ddm(lambda t: {"hieght": 0.1}), "hieght"),
        "wrong_type": (_ddm(lambda t: {"tiles_u": "many"}), "tiles_u"),
        "non_finite": (_ddm(lambda t: {"height": NAN}), "height"),
        "missing_file": (_ddm(lambda t: {"tile": _missing(t, ".obj")}), "no_such_file.obj"),
        "garbage_file": (_ddm(lambda t: {"tile": _garbage(t, ".obj")}), "garbage.obj"),
    },
    "vdm_mesh": {
        "misspelt": (_vdm_mesh(lambda t: {"resolutoin": 8}), "resolutoin"),
        "wrong_type": (_vdm_mesh(lambda t: {"radius": "big"}), "radius"),
        "non_finite": (_vdm_mesh(lambda t: {"radius": NAN}), "radius"),
        "missing_file": (_vdm_mesh(lambda t: {"base": "mesh", "filename": _missing(t, ".ply")}),
                         "no_such_file.ply"),
        "garbage_file": (_vdm_mesh(lambda t: {"base": "mesh", "filename": _garbage(t, ".ply")}),
                         "garbage.ply"),
    },
    "vdm": {
        "misspelt": (_bsdf("vdm", lambda t: {"svd_term": 8}), "svd_term"),
        "wrong_type": (_bsdf("vdm", lambda t: {"svd_terms": "eight"}), "svd_terms"),
        "non_finite": (_bsdf("vdm", lambda t: {"depth": NAN}), "depth"),
        "not_a_boolean": (_bsdf("vdm", lambda t: {"shadows": "maybe"}), "shadows"),
    },
    "horizon": {
        "misspelt": (_bsdf("horizon", lambda t: {"azimuth": 16}), "azimuth"),
        "wrong_type": (_bsdf("horizon", lambda t: {"azimuths": "many"}), "azimuths"),
        "non_finite": (_bsdf("horizon", lambda t: {"max_distance": NAN}), "max_distance"),
    },
    "relief": {
        "misspelt": (_bsdf("relief", lambda t: {"shadow_step": 16}), "shadow_step"),
        "wrong_type": (_bsdf("relief", lambda t: {"steps": "many"}), "steps"),
        "non_finite": (_bsdf("relief", lambda t: {"tiling_u": NAN}), "tiling_u"),
    },
    "restored": {
        "misspelt": (_restored(lambda t: {"levles": 2}), "levles"),
        "wrong_type": (_restored(lambda t: {"levels": "two"}), "levels"),
        "non_finite": (_restored(lambda t: {"levels": NAN}), "levels"),
        "not_a_boolean": (_restored(lambda t: {"keep_holes": "maybe"}), "keep_holes"),
        "missing_file": (_restored(lambda t: {"map": _missing(t, ".png")}), "no_such_file.png"),
        "garbage_file": (_restored(lambda t: {"map": _garbage_map(t)}), "garbage.png"),
        "garbage_exr_file": (_restored(lambda t: {"map": _garbage_map(t, ".exr")}), "garbage.exr"),
        "missing_low": (_restored(lambda t: {"low": _missing(t, ".obj")}), "no_such_file.obj"),
        "garbage_low": (_restored(lambda t: {"low": _garbage(t, ".obj")}), "garbage.obj"),
    },
    "mikk_normalmap": {
        "misspelt": (_mikk(lambda t, n: {"normalmap": n["cells"], "nromal_scale": 1.0}), "nromal_scale"),
        "wrong_type": (_mikk(lambda t, n: {"normalmap": 3.0}), "normalmap"),
        "missing_texture": (_mikk(lambda t, n: {}), "normalmap"),
    },
    "raster": {
        "misspelt": (_raster(lambda t: {"max_layer": 4}), "max_layer"),
        "wrong_type": (_raster(lambda t: {"aa": "two"}), "aa"),
        "non_finite": (_raster(lambda t: {"aa": NAN}), "aa"),
    },
    "slicing": {
        "misspelt": (_slicing(lambda t: {"slcies": 4}), "slcies"),
        "wrong_type": (_slicing(lambda t: {"slices": "many"}), "slices"),
        "non_finite": (_slicing(lambda t: {"scale": NAN}), "scale"),
        "not_a_boolean": (_slicing(lambda t: {"draw_base": "maybe"}), "draw_base"),
        "missing_file": (_slicing(lambda t: {"base": "mesh", "filename": _missing(t, ".obj")}),
                         "no_such_file.obj"),
        "garbage_file": (_slicing(lambda t: {"base": "mesh", "filename": _garbage(t, ".obj")}),
                         "garbage.obj"),
    },
    "depth_object": {
        "misspelt": (_depth_object(lambda t: {"slcies": 8}), "slcies"),
        "wrong_type": (_depth_object(lambda t: {"slices": "many"}), "slices"),
        "non_finite": (_depth_object(lambda t: {"slices": NAN}), "slices"),
        "missing_file": (_depth_object(lambda t: {"filename": _missing(t, ".json")}),
                         "no_such_file.json"),
        "garbage_file": (_depth_object(lambda t: {"filename": _garbage(t, ".json")}),
                         "garbage.json"),
    },
    "displaced_volume": {
        "misspelt": (_volume(lambda t: {"densty_scale": 2.0}), "densty_scale"),
        "wrong_type": (_volume(lambda t: {"bits": "many"}), "bits"),
        "non_finite": (_volume(lambda t: {"density_scale": NAN}), "density_scale"),
        "missing_file": (_volume(lambda t: {"filename": _missing(t, ".raw")}, procedural=False),
                         "no_such_file.raw"),
        "garbage_file": (_volume(lambda t: {"filename": _garbage(t, ".vol")}, procedural=False),
                         "garbage.vol"),
    },
    "volume_slicer": {
        "misspelt": (_of_volume("volume_slicer", lambda t: {"spaceing": 1.0}), "spaceing"),
        "wrong_type": (_of_volume("volume_slicer", lambda t: {"spacing": "big"}), "spacing"),
        "non_finite": (_of_volume("volume_slicer", lambda t: {"spacing": NAN}), "spacing"),
        "not_a_boolean": (_of_volume("volume_slicer", lambda t: {"shadows": "maybe"}), "shadows"),
    },
    "volume_isosurface": {
        "misspelt": (_of_volume("volume_isosurface", lambda t: {"isso": 0.5}), "isso"),
        "wrong_type": (_of_volume("volume_isosurface", lambda t: {"iso": "half"}), "iso"),
        "non_finite": (_of_volume("volume_isosurface", lambda t: {"iso": NAN}), "iso"),
    },
    "volume_proxy": {
        "misspelt": (_of_volume("volume_proxy", lambda t: {"volumee": 1.0}), "volumee"),
        "wrong_type": (_of_volume("volume_proxy", lambda t: {"volume": 3.0}), "volume"),
    },
    "ripples": {
        "misspelt": (_texture("ripples", lambda t: {"frequncy": 4.0}), "frequncy"),
        "wrong_type": (_texture("ripples", lambda t: {"frequency": "high"}), "frequency"),
        "non_finite": (_texture("ripples", lambda t: {"phase": math.inf}), "phase"),
    },
    "bricks": {
        "misspelt": (_texture("bricks", lambda t: {"morter": 0.1}), "morter"),
        "wrong_type": (_texture("bricks", lambda t: {"rows": "eight"}), "rows"),
        "non_finite": (_texture("bricks", lambda t: {"bevel": NAN}), "bevel"),
    },
    "cells": {
        "misspelt": (_texture("cells", lambda t: {"radious": 0.4}), "radious"),
        "wrong_type": (_texture("cells", lambda t: {"cells": "many"}), "cells"),
        "non_finite": (_texture("cells", lambda t: {"jitter": NAN}), "jitter"),
    },
}

#: (plugin, case) -> reason, for cases that fail today in code owned by another branch.
XFAIL: dict = {}


def _params():
    for plugin, cases in CASES.items():
        for case, spec in cases.items():
            marks = [pytest.mark.xfail(strict=True, reason=XFAIL[plugin, case])] \
                if (plugin, case) in XFAIL else []
            yield pytest.param(plugin, case, spec, id=f"{plugin}-{case}", marks=marks)


def test_the_sweep_covers_every_registered_plugin():
    registered = {name.rsplit(".", 1)[1] for name in PLUGIN_MODULES}
    assert registered == set(CASES), "add the new plugin's row to CASES"


@pytest.fixture
def kernels():
    """Count the Dr.Jit kernels launched inside a block: ``with kernels() as launched: ...``."""
    from contextlib import contextmanager

    previous = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)

    @contextmanager
    def count():
        dr.sync_thread()
        dr.kernel_history()  # clears it
        launched = []
        yield launched
        dr.sync_thread()
        launched.extend(dr.kernel_history())

    yield count
    dr.set_flag(dr.JitFlag.KernelHistory, previous)


def _nested():
    """Objects nested into the cases, built before the counted load."""
    return {"cells": mi.load_dict({"type": "cells"})}


def _user_error(error: Exception) -> Exception:
    """What the CLI shows for a load error (a bug stays a ``RuntimeError``)."""
    return scenes._translate_load_error(Path("<dict>"), error) if isinstance(error, RuntimeError) else error


@pytest.mark.parametrize("plugin, case, spec", list(_params()))
def test_bad_input_is_one_clear_error(variant, tmp_path, kernels, plugin, case, spec):
    build, name = spec
    scene_dict = build(tmp_path, _nested())
    with kernels() as launched:
        with pytest.raises(Exception) as caught:
            mi.load_dict(scene_dict)
    error = _user_error(caught.value)
    message = " ".join(str(error).split())
    assert isinstance(error, (ValueError, FileNotFoundError)), f"not a user error: {caught.value}"
    assert "Traceback" not in message
    assert re.search(rf"(^|[/'\" ]){re.escape(name)}(['\"]|$)", message), message
    compiled = [k for k in launched if k["type"] == dr.KernelType.JIT]
    if case != "misspelt":
        assert compiled == [], f"{len(compiled)} kernel(s) ran before the error: {message}"


def test_boolean_strings_parse_as_booleans(variant, tmp_path, monkeypatch):
    """``bool("false")`` is True: a string ``false`` (load_dict, ``-D``) must switch off."""
    from mi_displace.core.properties import Param, PluginSpec

    spec = PluginSpec("vdm", "bsdf", "", (Param("flag", "bool", True, ""),))
    props = mi.Properties()
    for text, expected in (("false", False), ("False", False), (" no ", False), ("0", False),
                           ("true", True), ("TRUE", True), ("yes", True)):
        props["flag"] = text
        assert spec.read(props)["flag"] is expected, text
    props["flag"] = 0
    assert spec.read(props)["flag"] is False
    assert spec.read(mi.Properties())["flag"] is True    # the default
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    small = {"res": 8, "theta": 4, "phi": 8, "curvatures": 1, "svd_terms": 4, "mvm_terms": 2}
    for text, expected in (("false", False), ("true", True)):
        vdm = mi.load_dict({"type": "vdm", "height": {"type": "cells"}, "depth": 0.05,
                            "tile_size": 1.0, "shadows": text, "cache": text, **small})
        assert vdm.shadows is expected and vdm.use_cache is expected


# -- files that must load -------------------------------------------------------------------

LATIN1_OBJ = (b"# mod\xe8le \xe9crit en latin-1\n"
              b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
              b"vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
              b"f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")


def test_an_obj_with_a_latin1_comment_loads_everywhere(variant, tmp_path):
    """One non-UTF-8 byte in a comment: Mitsuba's reader (base meshes) and trimesh's (tiles,
    bake inputs; its encoding fallback needs charset-normalizer) both read the square."""
    from mi_displace.bake.meshdata import load_mesh
    from mi_displace.core.mesh_io import load_uv_mesh
    from mi_displace.ddm.tiles import load_tile_file

    path = tmp_path / "latin1.obj"
    path.write_bytes(LATIN1_OBJ)
    with pytest.raises(UnicodeDecodeError):
        LATIN1_OBJ.decode("utf-8")
    positions, _, uvs, faces = load_uv_mesh(str(path))
    assert positions.shape == (4, 3) and faces.shape == (2, 3)
    np.testing.assert_array_equal(np.sort(uvs, axis=0), np.sort(positions[:, :2], axis=0))
    mesh = load_mesh(path)
    assert len(mesh.faces) == 2 and np.isclose(np.ptp(mesh.positions[:, 0]), 1.0)
    tile = load_tile_file(path)
    assert tile is not None
    displaced = mi.load_dict({"type": "displaced", "base": "mesh", "filename": str(path),
                              "height": {"type": "cells"}, "scale": 0.0})
    assert displaced.build_stats["faces"] >= 2
