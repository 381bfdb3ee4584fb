"""Helpers shared by the benchmark scripts: warm median times, the record's printout and
the folder a benchmark writes its figures to."""
from __future__ import annotations

import json
import statistics
import tempfile
import time
from pathlib import Path

import drjit as dr


def median_time(fn, repeats: int = 5) -> float:
    """Median wall seconds of ``repeats`` warm calls of ``fn`` after one cold call (tracing and
    JIT compilation), each timed between ``dr.sync_thread()`` so queued kernels count."""
    fn()
    times = []
    for _ in range(repeats):
        dr.sync_thread()
        start = time.perf_counter()
        fn()
        dr.sync_thread()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def print_record(record: dict, as_json: bool, width: int = 24) -> None:
    """A benchmark record on stdout: JSON, or one ``key: value`` line per entry right-aligned
    to ``width`` (floats to 4 significant digits, a list one line per row)."""
    if as_json:
        print(json.dumps(record, indent=2))
        return
    for key, value in record.items():
        for row in value if isinstance(value, list) else [value]:
            print(f"{key:>{width}}: {row:.4g}" if isinstance(row, float) else f"{key:>{width}}: {row}")


def output_dir(bench: str, out=None) -> Path:
    """The folder benchmark ``bench`` writes its files to, created: ``out`` when given, else
    ``mi_displace_bench/<bench>`` in the system's temporary directory (never the checkout,
    whose ``docs/figures`` a run refreshes only when named: ``--out docs/figures``)."""
    folder = Path(out) if out is not None else Path(tempfile.gettempdir()) / "mi_displace_bench" / bench
    folder.mkdir(parents=True, exist_ok=True)
    return folder
