"""Progress reports for long single-pass work: one line per stage with its wall time.

.. code-block:: python

    from mi_displace.core import progress

    with progress.stage("vdm: table 128^2 x 32 x 8 x 16") as s:
        build()
        s.note = "302 MB"          # optional, appended to the closing line

prints to stderr::

    [mi-displace] vdm: table 128^2 x 32 x 8 x 16 ...
    [mi-displace] vdm: table 128^2 x 32 x 8 x 16: 2.04 s (302 MB)

:func:`bar` is a tqdm bar over countable work (render passes) under the same switch.

When to print (:func:`is_enabled`): an explicit ``enabled=`` argument wins; else
:func:`set_enabled` (the CLI's ``--quiet``); else ``MI_DISPLACE_PROGRESS`` = ``1`` / ``0``;
else only when stderr is a terminal, so logs, pipes and the test suite stay quiet.
Stages nest (a plugin's build inside ``loading scene.xml``) and are indented under their
parent.  A stage that raises prints no closing line (the error says what happened).  Times are
wall seconds of the Python block; Dr.Jit work still queued at its end is not waited for.
"""
from __future__ import annotations

import os
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass

PREFIX = "[mi-displace]"
ENV = "MI_DISPLACE_PROGRESS"

_forced: bool | None = None
_depth = 0  # stages open now: nested ones are indented under their parent


def set_enabled(flag: bool | None) -> None:
    """Force progress on (``True``) or off (``False``) for this process; ``None``: automatic."""
    global _forced
    _forced = None if flag is None else bool(flag)


def is_enabled(flag: bool | None = None) -> bool:
    """Whether progress is shown (see the module docstring for the order of the switches)."""
    if flag is not None:
        return bool(flag)
    if _forced is not None:
        return _forced
    env = os.environ.get(ENV, "").strip()
    if env in ("0", "1"):
        return env == "1"
    return _stderr_is_terminal()


def _stderr_is_terminal() -> bool:
    """Whether stderr is an interactive terminal (progress is for people watching)."""
    return sys.stderr.isatty()


@dataclass
class Stage:
    """A running stage: ``label``, its start time, and a ``note`` for the closing line."""

    label: str
    start: float
    note: str = ""

    def elapsed(self) -> float:
        """Wall seconds since the stage began."""
        return time.perf_counter() - self.start


@contextmanager
def stage(label: str, enabled: bool | None = None):
    """Report ``label ...`` now and ``label: T s (note)`` when the block ends without error.

    Args:
        label: what the user waits for, e.g. ``"displaced: tessellating 8,388,608 triangles"``.
        enabled: force on/off; ``None`` follows :func:`is_enabled`.

    Yields:
        The :class:`Stage` (set ``.note`` to add a result to the closing line).
    """
    global _depth
    show = is_enabled(enabled)
    indent = "  " * _depth
    if show:
        print(f"{PREFIX} {indent}{label} ...", file=sys.stderr, flush=True)
    current = Stage(label, time.perf_counter())
    _depth += 1
    try:
        yield current
    finally:
        _depth -= 1
    if show:
        note = f" ({current.note})" if current.note else ""
        print(f"{PREFIX} {indent}{label}: {current.elapsed():.2f} s{note}", file=sys.stderr,
              flush=True)


def bar(total: int, desc: str, unit: str = "it", enabled: bool | None = None):
    """A tqdm progress bar on stderr over ``total`` units (disabled under the same rules)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False, file=sys.stderr,
                disable=not is_enabled(enabled))
