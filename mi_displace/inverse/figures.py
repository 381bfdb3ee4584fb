"""Figures and JSON of a :class:`mi_displace.inverse.recover.Recovery`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def write(rec, out: Path, truth_label: str = "truth", error_label: str = "height RMS / range",
          extra: dict | None = None) -> None:
    """``out/recovery.json`` (with ``extra`` merged in), ``out/recovery_curves.png``,
    ``out/recovery_maps.png``; ``truth_label`` / ``error_label`` name the comparison map and
    the error curve."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
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
