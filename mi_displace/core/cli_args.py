"""The command line's shared pieces: argparse types, the spp caps and the showcase scene
list, used by ``mi_displace.cli`` and by the technique modules that add sub-commands
(``evaluate/cli.py``, ``inverse/cli.py``, ...)."""
from __future__ import annotations

import argparse
import re
from pathlib import Path

#: Most reference samples per pixel of ``compare`` / ``showcase`` with ``--quick``, and without.
QUICK_MAX_SPP = 64
DEFAULT_MAX_SPP = 1024
SHOWCASE_MARK = re.compile(r"<!--\s*showcase\s*-->")


class UsageError(ValueError):
    """Bad command-line input found by the CLI itself."""


def define(text: str) -> tuple[str, str]:
    """argparse type of ``-D name=value``."""
    name, sep, value = text.partition("=")
    if not sep or not re.fullmatch(r"[A-Za-z_]\w*", name):
        raise argparse.ArgumentTypeError(f"expected name=value, got {text!r}")
    return name, value


def positive_int(text: str) -> int:
    """argparse type of a positive integer."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def seed(text: str) -> int:
    """argparse type of a sampler seed in [0, 2^32)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"expected an integer in [0, 2^32), got {text!r}")
    return value


def showcase_scenes(scenes_dir: Path) -> list[Path]:
    """Scene XML files under ``scenes_dir`` that contain ``<!-- showcase -->``, sorted."""
    if not scenes_dir.is_dir():
        raise FileNotFoundError(f"scene folder {str(scenes_dir)!r} does not exist")
    found = sorted(p for p in scenes_dir.rglob("*.xml") if SHOWCASE_MARK.search(p.read_text()))
    if not found:
        raise UsageError(f"no scene under {str(scenes_dir)!r} is marked <!-- showcase -->")
    return found
