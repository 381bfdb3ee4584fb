"""Sphinx configuration of the mi_displace documentation (MyST Markdown, furo theme).

Build it with ``./scripts/docs.sh`` (``sphinx-build -W --keep-going -n docs build/docs``);
``tests/test_docs.py`` runs the same build.  The tutorials in ``tutorials/*.ipynb`` are
rendered as committed (without outputs) and never executed here: ``tests/test_tutorials.py``
executes them.
"""
import os

import mi_displace

project = "mi_displace"
author = "the mi_displace authors"
copyright = "the mi_displace authors, BSD-3-Clause"
version = release = mi_displace.__version__

extensions = [
    "myst_nb",                  # Markdown (MyST) pages and the Jupyter notebooks
    "sphinx.ext.autodoc",       # the API pages, from the docstrings
    "sphinx.ext.napoleon",      # Google-style "Args:" / "Returns:" sections
    "sphinx.ext.mathjax",
]

# Markdown and notebooks; figures/ (data and tables the guides link) and atlas/ (a generated
# HTML page) are not pages.
source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["figures/**", "atlas/**", "**/.ipynb_checkpoints"]
root_doc = "index"

# MyST: $...$ maths, ::: fences, anchors for headings down to #### so that links such as
# `volume.md#conventions` resolve.
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 4
# Notebooks are shown as committed; tests/test_tutorials.py is what executes them.
nb_execution_mode = "off"

# autodoc: the variant the suite uses, set before the modules are imported (plugin classes
# subclass variant-specific Mitsuba types).
os.environ.setdefault("MI_DISPLACE_VARIANT", "llvm_ad_rgb")
mi_displace.init(os.environ["MI_DISPLACE_VARIANT"])
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True
napoleon_google_docstring = True
napoleon_numpy_docstring = False
# "Args:" / "Returns:" entries are prose ("cage / cage_offset: ...", "dict of int arrays:
# ..."): shown as written, not parsed into cross-referenced types.
napoleon_use_param = False
napoleon_use_rtype = False

# -n: every cross reference must resolve.  Names of other packages (Mitsuba, Dr.Jit, NumPy,
# the standard-library modules the docstrings name) have no inventory here (the build runs
# offline, without intersphinx), so they are exempt.
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(mi|mitsuba|dr|drjit|np|numpy|pathlib|types|importlib)(\..*)?"),
]

html_theme = "furo"
html_title = f"mi_displace {release}"


def _resolve_in_package(app, env, node, contnode):
    """Resolve a Python reference the way the docstrings write it: relative to the
    documenting module's package (``tessellate.displace_parametric`` inside
    ``mi_displace.core.displaced`` is ``mi_displace.core.tessellate.displace_parametric``).

    A target documented on these pages becomes a link; one that exists in ``mi_displace``
    but is internal (not on the API pages) is shown as code without a link; a name that
    exists nowhere stays unresolved, so ``-n`` reports it.
    """
    import importlib

    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    module = node.get("py:module") or "mi_displace"
    parts = module.split(".")
    candidates = [".".join(parts[:i] + [target]) for i in range(len(parts), 0, -1)]
    if target.startswith("mi_displace"):
        candidates = [target]
    domain = env.get_domain("py")
    for name in candidates:
        if name in domain.objects:
            return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], name,
                                       node, contnode)
    for name in candidates:
        head, *rest = name.split(".")
        for cut in range(len(rest), -1, -1):     # the longest importable module, then attributes
            try:
                obj = importlib.import_module(".".join([head, *rest[:cut]]))
            except ImportError:
                continue
            try:
                for attr in rest[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                break
            return contnode
    return None


def _copy_atlas(app, exception):
    """The atlas (a generated HTML page with its images beside it, linked relatively) is
    copied into the site as a folder, where its links keep working."""
    import shutil
    from pathlib import Path

    if exception is None and app.builder.format == "html":
        shutil.copytree(Path(app.srcdir) / "atlas", Path(app.outdir) / "atlas",
                        dirs_exist_ok=True)


def setup(app):
    app.connect("missing-reference", _resolve_in_package)
    app.connect("build-finished", _copy_atlas)
