"""The recovery figures of docs/differentiable.md (``mi-displace figures inverse``), and the
figures and JSON of any :class:`mi_displace.inverse.recover.Recovery` (:func:`write`, also
behind ``mi-displace recover`` / ``recover-bunny`` and ``bench grad``).

``mi-displace figures inverse [--out DIR] [--quick] [--only plane|bunny]`` writes
``DIR/recovery/`` (the Bricks102 map recovered on a ``displaced`` plane,
:func:`mi_displace.inverse.recover.recover` with its defaults: 64² map, 3 views x 2 lights,
64² images, 8 spp, 40 Adam steps) and ``DIR/recovery_bunny/`` (the bunny's map from renders
of the scan, :func:`mi_displace.inverse.bunny.recover_bunny` with its defaults): each
``recovery.json``, ``recovery_curves.png``, ``recovery_maps.png``.  ``--quick``: 16² maps and
images, one view and light, 2 spp, 2 steps.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def write(rec, out: Path, truth_label: str = "truth", error_label: str = "height RMS / range",
          extra: dict | None = None) -> None:
    """``out/recovery.json`` (with ``extra`` merged in), ``out/recovery_curves.png``,
    ``out/recovery_maps.png`` (``out`` created if missing); ``truth_label`` / ``error_label`` name the comparison map and
    the error curve."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name, values in (("estimate", rec.estimate), ("loss", rec.loss), ("rms", rec.rms)):
        if not np.all(np.isfinite(values)):
            raise FloatingPointError(f"recovery {name} holds NaN/Inf")
    (out / "recovery.json").write_text(json.dumps(
        {"summary": rec.summary(), "loss": rec.loss, "rms": rec.rms, "seconds": rec.seconds,
         **(extra or {})},
        indent=2))

    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.4))
    a.semilogy(rec.loss, label="image loss (mean L2)")
    floor = rec.settings.get("loss_noise_floor")
    if floor:
        a.axhline(floor, ls="--", c="grey", label="noise floor (true map)")
    a.set_xlabel("iteration"), a.legend()
    b.plot(rec.rms, c="C1")
    b.set_xlabel("iteration"), b.set_ylabel(error_label), b.set_ylim(0, None)
    s = rec.settings
    fig.suptitle(f"{s['integrator']}: {s['map_size']}² map, {s['views']} views x {s['lights']} "
                 f"lights, {s['image_size']}² images, {s['spp']} spp")
    fig.tight_layout()
    fig.savefig(out / "recovery_curves.png", dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(1, 4, figsize=(12, 3.3))
    lo, hi = float(rec.truth.min()), float(rec.truth.max())
    start = np.full_like(rec.truth, 0.5)
    for ax, img, title in zip(axes, (start, rec.estimate, rec.truth),
                              ("start (flat)", f"recovered (error {rec.rms[-1]:.3f})", truth_label)):
        ax.imshow(img, cmap="gray", vmin=lo, vmax=hi)
        ax.set_title(title), ax.axis("off")
    err = axes[3].imshow(rec.estimate - rec.truth, cmap="coolwarm", vmin=-(hi - lo) / 2,
                         vmax=(hi - lo) / 2)
    axes[3].set_title(f"recovered - {truth_label.split()[0]}"), axes[3].axis("off")
    fig.colorbar(err, ax=axes[3], fraction=0.046)
    fig.tight_layout()
    fig.savefig(out / "recovery_maps.png", dpi=100)
    plt.close(fig)


PARTS = ("plane", "bunny")
FOLDERS = {"plane": "recovery", "bunny": "recovery_bunny"}
#: what :func:`write` calls the comparison map and the error curve of the bunny's recovery
BUNNY_LABELS = {"truth_label": "baked (mi-displace bake)",
                "error_label": "map error vs baked / range"}
#: ``--quick`` sizes of both recoveries
QUICK = {"iterations": 2, "views": 1, "image_size": 16, "spp": 2, "target_spp": 4}


def add_options(parser) -> None:
    parser.add_argument("--only", choices=PARTS, action="append", default=None,
                        help="only this recovery (repeatable; default: both)")


def run(args) -> int:
    """``mi-displace figures inverse``: the folders of the module docstring under ``args.out``."""
    from mi_displace.inverse import bunny, recover

    parts = args.only or PARTS
    quick = QUICK if args.quick else {}
    out = Path(args.out)
    if "plane" in parts:
        truth = recover.load_height_map(size=16 if args.quick else 64)
        write(recover.recover(truth, **quick, **({"lights": 1} if args.quick else {}), log=print),
              out / FOLDERS["plane"])
    if "bunny" in parts:
        write(bunny.recover_bunny(**quick, **({"map_size": 16} if args.quick else {}), log=print),
              out / FOLDERS["bunny"], **BUNNY_LABELS)
    print(f"wrote {' and '.join(FOLDERS[p] for p in parts)} under {out}")
    return 0
