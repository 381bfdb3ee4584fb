"""Progress reports for long single-pass work: one line per stage with its wall time.

Every line is a record of the ``mi_displace`` :mod:`logging` logger (level INFO), so a script
or a notebook sees the stages with ``logging.basicConfig(level=logging.INFO)`` (or any handler
on that logger).  Without one, the lines go to stderr when progress is on (below).

.. code-block:: python

    from mi_displace.core import progress

    with progress.stage("vdm: table 128^2 x 32 x 8 x 16") as s:
        build()
        s.note = "302 MB"          # optional, appended to the closing line

logs (and, with progress on and no logging configured, prints to stderr)::

    [mi-displace] vdm: table 128^2 x 32 x 8 x 16 ...
    [mi-displace] vdm: table 128^2 x 32 x 8 x 16: 2.04 s (302 MB)

:func:`bar` is a tqdm bar over countable work (render passes) under the same switch.

When to print (:func:`is_enabled`): an explicit ``enabled=`` argument wins; else
:func:`set_enabled` (the CLI's ``--quiet``); else ``MI_DISPLACE_PROGRESS`` = ``1`` / ``0``;
else only when stderr is a terminal, so logs, pipes and the test suite stay quiet.  Bars are
``tqdm.auto`` bars (widgets in a notebook); stage lines are written through ``tqdm.write`` so
they do not break a running bar.
Stages nest (a plugin's build inside ``loading scene.xml``) and are indented under their
parent.  A stage that raises prints no closing line (the error says what happened).  Times are
wall seconds of the Python block; Dr.Jit work still queued at its end is not waited for.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass

PREFIX = "[mi-displace]"
ENV = "MI_DISPLACE_PROGRESS"

#: The package's logger; every stage line is an INFO record of it.
LOGGER = logging.getLogger("mi_displace")
LOGGER.addHandler(logging.NullHandler())

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


class _Console(logging.Handler):
    """Stage records meant for the console (``progress on``), to the current stderr through
    ``tqdm.write`` (a running bar is redrawn below the line, not broken)."""

    def filter(self, record) -> bool:
        return getattr(record, "console", False)

    def emit(self, record) -> None:
        from tqdm.auto import tqdm

        tqdm.write(f"{PREFIX} {record.getMessage()}", file=sys.stderr)


_CONSOLE = _Console()


def _say(message: str, show: bool) -> None:
    """Log ``message``; with ``show`` (progress on) it is also written to the console (so a
    script that configures logging and runs on a terminal sees it twice: set
    ``MI_DISPLACE_PROGRESS=0`` there)."""
    if show and _CONSOLE not in LOGGER.handlers:
        LOGGER.addHandler(_CONSOLE)
    if show and LOGGER.getEffectiveLevel() > logging.INFO:
        LOGGER.setLevel(logging.INFO)
    LOGGER.info(message, extra={"console": show})


def log(message: str, enabled: bool | None = None) -> None:
    """One progress line (a sweep point, a step of a long loop) under the same rules."""
    if enabled is not False:
        _say(message, is_enabled(enabled))


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
    if enabled is not False:
        _say(f"{indent}{label} ...", show)
    current = Stage(label, time.perf_counter())
    _depth += 1
    try:
        yield current
    finally:
        _depth -= 1
    if enabled is not False:
        note = f" ({current.note})" if current.note else ""
        _say(f"{indent}{label}: {current.elapsed():.2f} s{note}", show)


def bar(total: int, desc: str, unit: str = "it", enabled: bool | None = None):
    """A tqdm progress bar on stderr (a widget in a notebook) over ``total`` units (disabled
    under the same rules)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False, file=sys.stderr,
                disable=not is_enabled(enabled))
