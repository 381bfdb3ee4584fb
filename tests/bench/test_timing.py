"""The benchmarks' shared helpers: warm medians leave the cold call out, records print alike."""
import json
import time

from mi_displace.bench._timing import median_time, print_record


def test_median_time_is_the_median_of_the_warm_calls():
    durations = iter([0.3, 0.01, 0.05, 0.03])   # the cold call (JIT), then three warm ones
    calls = []

    def fn():
        calls.append(1)
        time.sleep(next(durations))

    seconds = median_time(fn, 3)
    assert len(calls) == 4
    assert 0.03 <= seconds < 0.05


def test_print_record_lines_and_json(capsys):
    record = {"build_s": 0.123456, "rows": [{"res": 512}, {"res": 1024}], "faces": 42}
    print_record(record, False, width=8)
    assert capsys.readouterr().out.splitlines() == [
        " build_s: 0.1235", "    rows: {'res': 512}", "    rows: {'res': 1024}", "   faces: 42"]
    print_record(record, True)
    assert json.loads(capsys.readouterr().out) == record
