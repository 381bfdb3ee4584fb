"""The runtime library never imports the lab.

Runtime: every module of ``mi_displace`` (the plugins, the technique packages, ``core``,
``render``, ``evaluate``) except the lab itself — ``mi_displace.figures`` (the documentation's
figures) and ``mi_displace.bench`` (benchmarks and their peers, ``bench.peers``) — and the
command layer (``mi_displace.cli``, ``mi_displace.<package>.cli``), which runs both.
"""
import ast
import importlib
import importlib.util
import pkgutil
import subprocess
import sys
from pathlib import Path

import mi_displace

LAB = ("mi_displace.figures", "mi_displace.bench")


def _is_lab(name: str) -> bool:
    return any(name == lab or name.startswith(lab + ".") for lab in LAB)


def _is_cli(name: str) -> bool:
    return name == "mi_displace.cli" or name.endswith(".cli")


def _modules() -> list[str]:
    """Every module of the package; ``mi_displace.plugins`` lives in its own folder (the
    ``package-dir`` of pyproject.toml), so it is walked on its own."""
    plugins = importlib.import_module("mi_displace.plugins")
    names = {m.name for m in pkgutil.walk_packages(mi_displace.__path__, "mi_displace.")}
    names |= {m.name for m in pkgutil.walk_packages(plugins.__path__, "mi_displace.plugins.")}
    return sorted(names | {"mi_displace.plugins"})


def _imported_names(path: Path) -> set[str]:
    """Every module an ``import`` statement of ``path`` names, at any depth (functions
    included): ``from a import b`` counts as ``a`` and ``a.b``."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            assert node.level == 0, f"{path}: relative import"
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_the_lab_packages_exist():
    """The figures of every technique are in one lab package, none inside a technique."""
    modules = _modules()
    assert importlib.util.find_spec("mi_displace.figures") is not None
    assert [m for m in modules if m.endswith(".figures") and not _is_lab(m)] == []
    assert {"mi_displace.figures.ddm", "mi_displace.figures.vdm", "mi_displace.figures.slicing",
            "mi_displace.figures.volume", "mi_displace.figures.inverse"} <= set(modules)


def test_no_runtime_module_names_the_lab():
    """Statically, including imports inside functions (a lazy import is still a dependency)."""
    runtime = [m for m in _modules() if not _is_lab(m) and not _is_cli(m)]
    assert "mi_displace.plugins.vdm" in runtime and "mi_displace.evaluate.tradeoff" in runtime
    offenders = {}
    for name in runtime:
        path = Path(importlib.util.find_spec(name).origin)
        bad = sorted(n for n in _imported_names(path) if _is_lab(n))
        if bad:
            offenders[name] = bad
    assert offenders == {}


def test_importing_the_runtime_loads_no_lab_module():
    """Dynamically: every runtime and CLI module imported in a fresh process, then no module
    of the lab is in ``sys.modules``."""
    modules = [m for m in _modules() if not _is_lab(m)]
    code = ("import importlib, sys\nimport mi_displace\nmi_displace.init()\n"
            f"for name in {modules!r}:\n"
            "    importlib.import_module(name)\n"
            f"print(sorted(m for m in sys.modules if m.startswith({LAB!r})))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"
