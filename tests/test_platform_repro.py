"""The reproductions of docs/platform.md still show what the notes say (so a note goes stale
loudly when Mitsuba changes), and our loader still undoes what they show."""
import subprocess
import sys
from pathlib import Path

import pytest

REPRO = Path(__file__).resolve().parents[1] / "scripts" / "repro"


def outcome(script: str, args: list, header: str, crashes: bool, abort_text: str) -> list:
    """Run ``scripts/repro/SCRIPT ARGS`` in a fresh process: its stdout starts with
    ``header``; it aborts with ``abort_text`` on stderr (``crashes``) or exits 0.  Returns
    its stdout lines."""
    run = subprocess.run([sys.executable, str(REPRO / script), *args],
                         capture_output=True, text=True, timeout=300)
    assert run.stdout.startswith(header)
    if crashes:
        assert run.returncode < 0, (run.returncode, run.stdout, run.stderr[-2000:])
        assert abort_text in run.stderr
    else:
        assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout.splitlines()


def test_plugin_constructor_error_reaches_load_dict_as_text_in_a_runtime_error(variant):
    """A Python BSDF raising ValueError in its constructor: ``mi.load_dict`` raises a
    RuntimeError with nothing chained, whose text is Mitsuba's location, the Python
    traceback (one line per frame) and the ValueError's line; ``_translate_load_error``
    (the loader of the CLI and ``mi_displace.render.scene.load``) makes it one line again."""
    import mitsuba as mi
    from mi_displace.render.scene import _translate_load_error

    run = subprocess.run([sys.executable, str(REPRO / "python_plugin_error.py"), variant],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    versions, kind, *message = run.stdout.splitlines()
    assert versions == f"mitsuba {mi.__version__}, drjit {__import__('drjit').__version__}, variant {variant}"
    assert kind == "RuntimeError, __cause__ None, __context__ None"
    assert message[0].startswith('[parser.cpp:') and message[0].endswith(
        'plugin of type "raising": Traceback (most recent call last):')
    assert [line.split(", in ")[-1] for line in message[1:-1]] == ["<module>", "<lambda>", "__init__"]
    assert message[-1] == "ValueError: raising: parameter 'roughness' must be > 0, got -1"
    user = _translate_load_error(Path("scene.xml"), RuntimeError("\n".join(message)))
    assert type(user) is ValueError and "\n" not in str(user) and "Traceback" not in str(user)
    assert str(user).startswith("scene 'scene.xml': At dictionary node \"root\": failed to instantiate")
    assert str(user).endswith("\"raising\": raising: parameter 'roughness' must be > 0, got -1")


@pytest.mark.parametrize("mode, crashes", [("bare", True), ("methods", True), ("frame", False),
                                           ("turn", False), ("after", False)])
def test_collector_inside_a_trace_frees_a_dropped_instance(variant_llvm, mode, crashes):
    """scripts/repro/collector_trace.py (docs/platform.md): a collection while Dr.Jit traces a
    Python BSDF that only a reference cycle holds aborts the process, also with every BSDF
    method run with the collector paused; pausing it around the whole render protects, and
    an instance freed before or after its turn does no harm.  When Mitsuba/Dr.Jit fix it, the crashing
    modes exit 0 and this fails: the note and the workaround can go."""
    lines = outcome("collector_trace.py", [mode, variant_llvm],
                    f"mitsuba {__import__('mitsuba').__version__}, drjit ", crashes,
                    "pointer is not registered")
    assert crashes or lines[-1].startswith("ok, mean ")


@pytest.mark.parametrize("mode, crashes", [("empty", True), ("width1", False)])
def test_freeze_with_an_empty_array_input_aborts(mode, crashes):
    """scripts/repro/freeze_empty_array.py (docs/platform.md): ``dr.freeze`` given an empty
    array among its inputs aborts the process; a width-1 array records.  Why
    ``lights.area_samples`` holds a width-1 null emitter for a scene without area lights
    (``raster``'s ``freeze`` passes it to the recording).  When Dr.Jit fixes it, "empty"
    exits 0 and this fails: the note can go."""
    lines = outcome("freeze_empty_array.py", [mode], f"drjit {__import__('drjit').__version__}",
                    crashes, "unknown variable")
    assert crashes or lines[-1] == "ok [2, 3]"


@pytest.mark.parametrize("mode, crashes", [("evaluated", True), ("inkernel", False)])
def test_llvm_crashes_on_a_per_lane_divisor_of_a_loaded_array(mode, crashes):
    """scripts/repro/llvm_division_crash.py (docs/platform.md): libLLVM 19.1 crashes compiling
    a division of a loaded array by a clipped per-lane divisor (why ``pixel_order`` divides by
    constants only); over an array made in the kernel it compiles.  When a Dr.Jit or LLVM
    release fixes it, "evaluated" exits 0 and this fails: the note can go."""
    import drjit as dr

    if dr.detail.llvm_version()[:2] != (19, 1):
        pytest.skip(f"measured with libLLVM 19.1; this process loaded {dr.detail.llvm_version()}")
    lines = outcome("llvm_division_crash.py", [mode], f"drjit {dr.__version__}, libLLVM 19.1",
                    crashes, "")
    assert crashes or lines[-1] == "ok 30720"


@pytest.mark.parametrize("mode", ["leaves", "registry"])
def test_freeze_call_overhead_reproduction_runs(mode):
    """scripts/repro/freeze_call_overhead.py (docs/platform.md, the fixed cost of a frozen
    call) runs and prints its per-call times, all finite and positive.  Its figures are
    timings, which no test asserts; this keeps the script from rotting."""
    import re

    lines = outcome("freeze_call_overhead.py", [mode, "8"], f"drjit {__import__('drjit').__version__}",
                    False, "")
    times = [float(t) for line in lines[1:] for t in re.findall(r"(-?[0-9.]+) us a call", line)]
    assert len(times) == (5 if mode == "leaves" else 2)
    assert all(0 < t < 1e6 for t in times)
