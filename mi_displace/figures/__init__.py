"""The figures and tables of the documentation: lab code beside the library.

One module per technique (:data:`TECHNIQUES`), run by ``mi-displace figures TECHNIQUE
[--out DIR] [--quick] [options]``; ``mi-displace figures --list`` prints the techniques.
Each module defines

* ``add_options(parser)``: its own options (``--out`` and ``--quick`` are common);
* ``run(args) -> int``: writes its files under ``args.out``; ``args.quick`` runs the same
  code at tiny sizes (seconds to minutes; checks that it runs, numbers not comparable).

The runtime library (plugins, the technique packages, ``render``, ``evaluate``) never imports
this package (``tests/test_layers.py``); it may import the library.
"""
from __future__ import annotations

import importlib
from types import ModuleType

#: technique -> what ``mi-displace figures TECHNIQUE`` makes
TECHNIQUES = {
    "ddm": "HDDM accuracy tables and plots, normal methods, map_resolution sweep (docs/ddm.md)",
    "vdm": "VDM methods tables (the paper's Table 1), unseen scenes, term and size sweeps "
           "(docs/vdm.md)",
    "slicing": "slicing: Fig. 10 made numeric, the donut trade-off, depth object vs hull "
               "(docs/slicing.md)",
    "volume": "volume trade-off sweeps: bits, D_k, spacing, composition, normals (docs/volume.md)",
    "inverse": "height maps recovered from renders: the Bricks102 plane and the bunny "
               "(docs/differentiable.md)",
}


def module(technique: str) -> ModuleType:
    """The figures module of ``technique`` (a key of :data:`TECHNIQUES`)."""
    if technique not in TECHNIQUES:
        raise ValueError(f"figures: unknown technique {technique!r}; available: "
                         f"{', '.join(TECHNIQUES)}")
    return importlib.import_module(f"{__name__}.{technique}")
