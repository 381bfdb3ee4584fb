"""The benchmarks' peers live in the lab (``mi_displace.bench.peers``): a missing one raises
on first use with the line that installs it, a benchmark records "peer unavailable: <why>",
and no library code installs anything or imports a peer."""
import ast
import sys
from pathlib import Path

import pytest

from mi_displace.bench import peers
from mi_displace.bench.peers import blender, llvmpipe, vtk_volume

PACKAGE = Path(peers.__file__).resolve().parents[2]   # the mi_displace package
PEER_MODULES = {"moderngl", "vtk", "bpy", "mi_displace.bench.peers"}


def test_require_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "moderngl", None)
    with pytest.raises(ImportError, match=r"moderngl .*pip install 'mi-displace\[peers\]'"):
        peers.require("moderngl")
    with pytest.raises(peers.PeerUnavailable, match=r"pip install 'mi-displace\[cluster\]'"):
        peers.require("moderngl", extra="cluster")


@pytest.mark.parametrize("blocked, call", [
    ("moderngl", lambda: llvmpipe.context()),
    ("moderngl", lambda: llvmpipe.mesh_frame(None, None, None, None, 30.0, 8, (0, 0, 1), (1, 1, 1))),
    ("vtk", lambda: vtk_volume.raycast_time(None, (0, -2, 0), (0, 0, 0), 30.0, 8, 0.3)),
])
def test_a_missing_peer_is_measured_as_unavailable(blocked, call, monkeypatch):
    monkeypatch.setitem(sys.modules, blocked, None)
    value, reason = peers.measure(call)
    assert value is None
    assert reason.startswith(f"peer unavailable: {blocked} is not installed")
    assert "pip install 'mi-displace[peers]'" in reason


@pytest.mark.parametrize("fails_to_import, says", [(True, "cannot import bpy"),
                                                     (False, "does not run")])
def test_blender_without_bpy_is_unavailable(fails_to_import, says, monkeypatch, tmp_path):
    python = tmp_path / "python"
    if fails_to_import:   # a Python whose `import bpy` fails
        python.write_text("#!/bin/sh\nexit 1\n")
        python.chmod(0o755)
    monkeypatch.setenv("MI_DISPLACE_BLENDER_PYTHON", str(python))
    out = tmp_path / "out"
    out.mkdir()
    value, reason = peers.measure(blender.bake, tmp_path / "h.obj", tmp_path / "l.obj", 8, 0.1, out)
    assert value is None and reason.startswith("peer unavailable: ") and says in reason
    assert not list(out.iterdir())   # nothing ran
    value, reason = peers.measure(blender.decode, tmp_path / "l.obj", 8, out, [tmp_path / "m.png"])
    assert value is None and reason.startswith("peer unavailable: ") and says in reason
    assert not list(out.iterdir())


def test_measure_lets_bugs_through():
    with pytest.raises(ZeroDivisionError):
        peers.measure(lambda: 1 / 0)


def _sources():
    return sorted(PACKAGE.rglob("*.py"))


def test_no_library_code_installs_anything():
    """No call in mi_displace runs pip or apt-get (scripts/setup_peers.sh does, on request)."""
    offenders = []
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                words = {n.value for n in ast.walk(node)
                         if isinstance(n, ast.Constant) and isinstance(n.value, str)}
                if "apt-get" in words or {"pip", "install"} <= words:
                    offenders.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert not offenders


def test_the_library_imports_no_peer():
    """Outside mi_displace/bench nothing imports a peer (the runtime stands without them)."""
    offenders = []
    for path in _sources():
        if (PACKAGE / "bench") in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            offenders += [f"{path.relative_to(PACKAGE)}:{node.lineno} {n}" for n in names
                          if any(n == m or n.startswith(m + ".") for m in PEER_MODULES)]
    assert not offenders
