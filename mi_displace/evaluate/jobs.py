"""Independent jobs (sweep points, showcase scenes, animation frames), run here or on a cluster.

:func:`run_jobs` calls ``fn(**job)`` for every job and hands each outcome to ``on_result`` as
soon as it exists, so a caller can persist it before the next one finishes.

* ``cluster=None``: one job after the other in this process.
* ``cluster="local:N"``: a Dask ``LocalCluster`` of ``N`` single-threaded worker processes on
  this machine (what the tests use).
* ``cluster="tcp://HOST:PORT"``: the Dask scheduler of an existing cluster.

Why Dask distributed: it is plain Python from PyPI (no daemon of its own beyond the
scheduler, no object store), a worker is just ``dask worker ADDRESS`` on any machine that has
this package installed, its nanny restarts a worker that dies and the scheduler re-runs the
worker's jobs elsewhere (``distributed.scheduler.allowed-failures`` times, then the job fails
with ``KilledWorker``), and ``LocalCluster`` starts the same machinery in a test.  Ray would
do as well but brings a C++ runtime and an object store a render sweep does not need.

Each job runs through :func:`_run_one`, which sets the caller's Mitsuba variant and registers
our plugins on the worker itself (``mi_displace.init``), and reports the host name, process
id and wall seconds of the worker that ran it.  A job that raises records the failure (type
and message) and the other jobs go on.
"""
from __future__ import annotations

import os
import socket
import time
import traceback
from typing import Callable, Iterable

from mi_displace.core.extras import require

#: Scheduler address of a Dask cluster started for the caller on this machine.
LOCAL_PREFIX = "local:"


def _run_one(fn: Callable, job: dict, variant: str) -> dict:
    """Run ``fn(**job)`` under ``variant``; the outcome as a plain dict (never raises)."""
    import mi_displace

    start = time.perf_counter()
    try:
        mi_displace.init(variant)
        value = fn(**job)
        outcome = {"ok": True, "value": value}
    except Exception as e:  # recorded, the sweep goes on (see module docstring)
        outcome = {"ok": False, "error": f"{type(e).__name__}: {' '.join(str(e).split())}",
                   "error_type": type(e).__name__}
        if not isinstance(e, (ValueError, FileNotFoundError)):  # a bug: keep the traceback
            outcome["traceback"] = traceback.format_exc()
    outcome.update(host=socket.gethostname(), pid=os.getpid(),
                   job_s=time.perf_counter() - start)
    return outcome


def check_cluster(cluster: str | None) -> None:
    """Validate a ``--cluster`` value before anything starts.

    Raises:
        ValueError: neither ``local:N`` with ``N >= 1`` nor a ``tcp://``/``tls://``/``ucx://``
            scheduler address.
        MissingExtraError: Dask's ``distributed`` is not installed (the ``[cluster]`` extra).
    """
    if cluster is None:
        return
    if cluster.startswith(LOCAL_PREFIX):
        count = cluster[len(LOCAL_PREFIX):]
        if not count.isdigit() or int(count) < 1:
            raise ValueError(f"--cluster: expected local:N with N >= 1 workers, got {cluster!r}")
    elif not any(cluster.startswith(p) for p in ("tcp://", "tls://", "ucx://", "inproc://")):
        raise ValueError(f"--cluster: expected a scheduler address such as tcp://HOST:8786 "
                         f"or local:N, got {cluster!r}")
    require("distributed", "cluster", "--cluster")


class _Cluster:
    """A connected Dask client (and the local cluster it owns, if it started one)."""

    def __init__(self, cluster: str):
        distributed = require("distributed", "cluster", "--cluster")
        Client, LocalCluster = distributed.Client, distributed.LocalCluster

        self.local = None
        if cluster.startswith(LOCAL_PREFIX):
            self.local = LocalCluster(n_workers=int(cluster[len(LOCAL_PREFIX):]),
                                      threads_per_worker=1, processes=True,
                                      dashboard_address=":0")
            self.client = Client(self.local)
        else:
            try:
                self.client = Client(cluster, timeout=30)
            except OSError as e:
                raise ValueError(f"--cluster: cannot reach the scheduler at {cluster!r}: {e}") from None

    def close(self):
        self.client.close()
        if self.local is not None:
            self.local.close()


def run_jobs(fn: Callable, jobs: Iterable[dict], cluster: str | None = None,
             on_result: Callable[[int, dict], None] | None = None,
             progress: bool | None = False,
             desc: str = "jobs") -> list[dict]:
    """Run ``fn(**job)`` for each job, locally or on a cluster.

    Args:
        fn: a module-level function (importable on the workers).
        jobs: keyword arguments of each call (picklable).
        cluster: ``None``, ``"local:N"`` or a scheduler address (module docstring).
        on_result: called with ``(index, outcome)`` as each job finishes.
        progress: a bar over the jobs with an ETA (``None``: on a terminal,
            :mod:`mi_displace.core.progress`).
        desc: the bar's label.

    Returns:
        One outcome per job, in job order: ``{"ok": True, "value": fn's result}`` or
        ``{"ok": False, "error": "Type: message", "error_type"}`` (and ``traceback`` for
        exceptions other than ``ValueError`` / ``FileNotFoundError``), each with ``host``,
        ``pid`` and ``job_s`` (wall seconds on the worker).
    """
    import mitsuba as mi

    from mi_displace.core.progress import bar as progress_bar

    check_cluster(cluster)
    jobs = list(jobs)
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("no Mitsuba variant is set: call mi_displace.init() first")
    outcomes: list[dict | None] = [None] * len(jobs)
    bar = progress_bar(len(jobs), desc, "job", enabled=progress)

    def finish(index, outcome):
        outcomes[index] = outcome
        if on_result is not None:
            on_result(index, outcome)
        bar.update(1)

    try:
        if cluster is None:
            for index, job in enumerate(jobs):
                finish(index, _run_one(fn, job, variant))
        else:
            _run_on_cluster(fn, jobs, cluster, variant, finish)
    finally:
        bar.close()
    return outcomes


def _run_on_cluster(fn, jobs, cluster, variant, finish) -> None:
    connection = _Cluster(cluster)
    as_completed = require("distributed", "cluster", "--cluster").as_completed
    try:
        futures = {connection.client.submit(_run_one, fn, job, variant, pure=False): index
                   for index, job in enumerate(jobs)}
        for future in as_completed(futures):
            index = futures[future]
            try:
                outcome = future.result()
            except Exception as e:  # KilledWorker after the retries, a lost scheduler, ...
                outcome = {"ok": False, "error": f"{type(e).__name__}: {' '.join(str(e).split())}",
                           "error_type": type(e).__name__, "host": None, "pid": None,
                           "job_s": None}
            finish(index, outcome)
    finally:
        connection.close()
