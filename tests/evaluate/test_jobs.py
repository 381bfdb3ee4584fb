"""Job runner: local and two-worker Dask runs, failures recorded, a dying worker's job retried."""
import os
from pathlib import Path

import pytest

from mi_displace.evaluate import jobs


def square(x):
    return x * x


def refuse_odd(x):
    if x % 2:
        raise ValueError(f"x: odd value {x}")
    return x


def die_once(marker: str, x: int):
    """Kill the worker process the first time any worker runs it; return ``x`` afterwards."""
    path = Path(marker)
    if not path.exists():
        path.write_text("died")
        os._exit(1)
    return x


def test_local_runs_in_order_and_records_failures(variant_llvm):
    seen = []
    outcomes = jobs.run_jobs(refuse_odd, [{"x": i} for i in range(4)],
                             on_result=lambda i, o: seen.append(i))
    assert seen == [0, 1, 2, 3]
    assert [o["ok"] for o in outcomes] == [True, False, True, False]
    assert outcomes[2]["value"] == 2 and outcomes[1]["error"] == "ValueError: x: odd value 1"
    assert all(o["host"] and o["pid"] == os.getpid() for o in outcomes)


def test_cluster_of_two_workers_survives_a_dying_worker(variant_llvm, tmp_path):
    import cloudpickle

    cloudpickle.register_pickle_by_value(__import__(__name__))  # workers need no test import path
    marker = str(tmp_path / "died")
    outcomes = jobs.run_jobs(die_once, [{"marker": marker, "x": i} for i in range(4)],
                             cluster="local:2")
    assert Path(marker).read_text() == "died"           # one worker really died
    assert [o["value"] for o in outcomes] == [0, 1, 2, 3]  # and its job ran again elsewhere
    assert all(o["ok"] and o["pid"] != os.getpid() for o in outcomes)


@pytest.mark.parametrize("bad", ["local:0", "local:x", "localhost:8786", "8786"])
def test_bad_cluster_address(bad):
    with pytest.raises(ValueError, match="--cluster"):
        jobs.check_cluster(bad)
