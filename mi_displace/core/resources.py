"""The packaged scenes and assets, found through :mod:`importlib.resources`.

The scenes (with their ``integrators/`` include files and ``parts/``) and the assets that
they and the runtime read (meshes, the teapot patches, textures, volumes, each folder with
its ``LICENSE.txt``) ship as the packages ``mi_displace.scenes`` and ``mi_displace.data``.
In a checkout (``pip install -e .``) these are the repository's ``scenes/`` and ``data/``
folders (``package-dir`` in ``pyproject.toml``); installed from a wheel they lie side by
side inside the package.  Either way a scene's ``../data/...`` path holds, and
:func:`add_to_file_resolver` lets a scene copied anywhere find the include files and assets
by the same names.
"""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path

#: Default output folder of the figure commands and benches, ``docs/figures`` under the
#: current directory (the repository's own docs when run from the checkout's root).
FIGURES_DIR = Path("docs") / "figures"


def _folder(package: str) -> Path:
    """The folder of a data-only package, as a real path (Mitsuba opens files by name)."""
    root = files(package)
    if not isinstance(root, Path):
        raise FileNotFoundError(f"{package}: package data is not a folder on disk ({root!r}); "
                                "install mi-displace with pip, not as a zip")
    return root


def scenes_dir() -> Path:
    """The packaged scene folder (absolute): ``*.xml`` scenes, ``integrators/``, ``parts/``."""
    return _folder("mi_displace.scenes")


def scene_path(*parts: str) -> Path:
    """A file under :func:`scenes_dir`, e.g. ``scene_path("vdm_torus.xml")`` (absolute)."""
    return scenes_dir().joinpath(*parts)


def data_path(*parts: str) -> Path:
    """A packaged asset, e.g. ``data_path("spot", "spot_triangulated.obj")`` (absolute)."""
    return _folder("mi_displace.data").joinpath(*parts)


def add_to_file_resolver() -> None:
    """Append :func:`scenes_dir` to Mitsuba's (process-wide) file resolver, once.

    A relative file name in a scene (``<include filename="integrators/path.xml"/>``,
    ``parts/...``, ``../data/...``) resolves first against the scene file's own folder and
    then, through this entry, against the packaged scenes: a comparison scene copied out of
    the package loads unchanged.
    """
    import mitsuba as mi

    resolver = mi.file_resolver()
    folder = str(scenes_dir())
    if folder not in resolver:
        resolver.append(folder)
