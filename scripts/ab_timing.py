"""The timing of the in-process A/B scripts (``constant_ab.py``, ``module_ab.py``,
``coherent_ab.py``): frames of two configurations drawn alternately, so both see the same
moments of a shared machine."""
import os
import statistics
import time


def alternate(frame, labels: tuple, before=lambda rep: None) -> None:
    """Print ROUNDS lines (environment; default 3) of the median wall seconds of REPS
    (default 7) calls of ``frame(label)`` for each of the two ``labels``, called in turn
    (after ``before(rep)``, e.g. a camera move), queued kernels drained around each, and the
    ratio second / first."""
    import drjit as dr

    reps, rounds = int(os.environ.get("REPS", 7)), int(os.environ.get("ROUNDS", 3))
    for _ in range(rounds):
        times = {label: [] for label in labels}
        for rep in range(reps):
            before(rep)
            for label in labels:
                dr.sync_thread()
                start = time.perf_counter()
                frame(label)
                dr.sync_thread()
                times[label].append(time.perf_counter() - start)
        a, b = (statistics.median(times[label]) for label in labels)
        print(f"{labels[0]} {a:.4f} s  {labels[1]} {b:.4f} s  {labels[1]}/{labels[0]} {b / a:.3f}")
