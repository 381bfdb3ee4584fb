"""Packaged scenes and assets: every name the code and the scenes use resolves through
mi_displace.core.resources, and a scene copied out of the package loads unchanged."""
import ast
import re
import shutil
import sys
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

import mi_displace
from mi_displace import cli
from mi_displace.core import bezier, resources
from mi_displace.core.extras import MissingExtraError, require
from mi_displace.evaluate import jobs

PACKAGE = Path(mi_displace.__file__).resolve().parent
#: relative file names in the scenes: <include filename=...>, <string name="filename|map" ...>
SCENE_FILE = re.compile(r'(?:<include filename|name="(?:filename|map)" value)="([^"$]+)"')


def _literal_resource_calls():
    """(function, parts) of every ``data_path(...)`` / ``scene_path(...)`` call in the package
    whose arguments are all string literals."""
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ("data_path", "scene_path")
                    and all(isinstance(a, ast.Constant) for a in node.args)):
                yield path.relative_to(PACKAGE), node.func.id, [a.value for a in node.args]


def test_packaged_folders_hold_what_the_code_names():
    scenes, data = resources.scenes_dir(), resources.data_path()
    assert scenes.is_absolute() and (scenes / "integrators" / "path.xml").is_file()
    # the scenes' ../data/... names hold because both folders are siblings, in a checkout
    # (scenes/, data/) and in a wheel (mi_displace/scenes, mi_displace/data)
    assert (scenes / ".." / "data").resolve() == data.resolve()
    assert cli.default_scenes_dir() == scenes
    assert Path(bezier.DEFAULT_TEAPOT).is_file()
    calls = list(_literal_resource_calls())
    assert len(calls) >= 20   # bezier, benches, figures, inverse, ddm.accuracy, ...
    missing = [(str(f), fn, parts) for f, fn, parts in calls
               if not getattr(resources, fn)(*parts).exists()]
    assert not missing


def test_every_file_a_packaged_scene_names_is_packaged():
    scenes = resources.scenes_dir()
    named = {(xml.relative_to(scenes).as_posix(), name)
             for xml in scenes.rglob("*.xml") for name in SCENE_FILE.findall(xml.read_text())}
    assert len(named) > 50
    # Mitsuba resolves a name against the scene's folder, the including file's folder, then
    # the resolver's folders (the packaged scenes among them)
    missing = [(xml, name) for xml, name in named
               if not any((base / name).exists()
                          for base in (scenes / Path(xml).parent, scenes, scenes / "tradeoff"))]
    assert not missing


@pytest.mark.parametrize("name, defines", [
    ("displaced_sphere.xml", {"res": "16", "resolution": "16", "spp": "4"}),  # integrators/, parts/
    ("volume_nucleon_pull.xml", {"res": "16"}),                                 # ../data/volumes
    ("bake_bunny.xml", {"res": "16", "mode": "approximation"}),                 # parts/bake_bunny/
])
def test_scene_copied_anywhere_loads(variant, tmp_path, monkeypatch, name, defines):
    copy = tmp_path / "elsewhere" / name
    copy.parent.mkdir()
    shutil.copy(resources.scene_path(name), copy)
    monkeypatch.chdir(tmp_path)
    scene = mi.load_file(str(copy), **defines)
    assert scene.shapes()
    if name == "displaced_sphere.xml":
        image = np.asarray(mi.render(scene, seed=0))
        assert image.shape == (16, 16, 3) and np.isfinite(image).all() and image.mean() > 0.01


def test_init_adds_the_packaged_scenes_to_the_file_resolver_once(variant):
    mi_displace.init(variant)
    folders = [str(p) for p in mi.file_resolver()]
    assert folders.count(str(resources.scenes_dir())) == 1


def test_missing_extra_names_the_install_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(MissingExtraError, match=r"pip install 'mi-displace\[cluster\]'"):
        jobs.check_cluster("local:2")
    jobs.check_cluster(None)   # no cluster, no dask needed
    with pytest.raises(MissingExtraError, match=r"mi-displace\[peers\]"):
        require("no_such_module_mi_displace", "peers", "the test")


def test_missing_extra_is_a_one_line_cli_error(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(SystemExit) as e:
        cli.main(["--variant", "llvm_ad_rgb", "showcase", "--out", "unused", "--cluster", "local:2"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["mi-displace: error: --cluster needs 'distributed', which is not installed: "
                   "pip install 'mi-displace[cluster]'"]
