"""Every ``mi-displace bench NAME`` runs: ``--quick --json`` of each benchmark in
``cli.bench_names()``, its JSON finite and holding its headline fields, a peer either
measured or reported as "peer unavailable: <why>" (so no benchmark can rot unnoticed)."""
import inspect
import importlib
import json
import math
import sys

import pytest

from mi_displace import cli

#: Headline fields of each benchmark's record (numbers, or lists / dicts of them).
FIELDS = {
    "bake": ("bake_time_warm_s", "speedup_vs_naive", "restore_hausdorff_rel", "compression_ratio",
             "timing_table", "cold_start", "spot", "multistep"),
    "bake_blender": ("spot_displaced",),
    "cluster": ("local_wall_s", "cluster_wall_s", "overhead_per_job_s", "mean_job_s_cluster"),
    "core": ("tessellate_4m_s", "accel_build_4m_s", "raster_512_1m_s", "path_1spp_512_1m_s"),
    "denoise": ("rows",),
    "ddm": ("map_time_warm_s", "rms_error_rel", "max_error_rel", "maps_bytes", "table1"),
    "dicing": ("adaptive_faces", "uniform_faces", "flip_adaptive", "noise_floor_flip",
               "cycles_sphere_faces", "cycles_sphere_flip_vs_uniform_4x"),
    "frames": ("rows",),
    "grad": ("forward_s", "backward_s", "grad_rel_error_scale", "grad_rel_error_height",
             "recovery_rms"),
    "grad_bunny": ("seconds_per_iteration", "iteration_ratio", "edit"),
    "raster": ("zbuffer_s", "zbuffer_shadow_map_s", "raytrace_s", "ddm_frame_s"),
    "slicing": ("render_time_warm_s", "build_time_warm_s", "flip", "depth_object_time_warm_s",
                "render_time_same_work_s"),
    "vdm": ("build_time_s", "compression_ratio", "render_time_warm_s", "flip_vs_reference",
            "methods"),
    "volume": ("render_time_warm_s", "displacement_overhead", "texture_bytes", "flip", "table2"),
}
#: Where a benchmark records its peer: (record -> the part holding it, time key, reason key).
PEERS = {
    "raster": (lambda r: r, "llvmpipe_s", "llvmpipe_reason"),
    "slicing": (lambda r: r, "llvmpipe_s", "llvmpipe_reason"),
    "volume": (lambda r: r, "vtk_s", "vtk_reason"),
    "bake_blender": (lambda r: r["spot_displaced"], "time", "blender_reason"),
}


def _numbers(value, where="record"):
    """Every number in a JSON value, with its path; bools and strings skipped, None kept."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _numbers(v, f"{where}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _numbers(v, f"{where}[{i}]")
    elif value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)):
        yield where, value


def run_quick(name, variant, tmp_path, capsys) -> dict:
    """``mi-displace --variant V bench NAME --quick --json [--out tmp]`` in this process."""
    argv = ["--variant", variant, "--quiet", "bench", name, "--quick", "--json"]
    if "out" in inspect.signature(importlib.import_module(f"mi_displace.bench.{name}").main).parameters:
        argv += ["--out", str(tmp_path / name)]
    assert cli.main(argv) == 0
    return json.loads(capsys.readouterr().out)


def check_record(name: str, record: dict) -> None:
    missing = [key for key in FIELDS[name] if record.get(key) is None]
    assert not missing, f"bench {name}: no {missing}"
    numbers = list(_numbers(record))
    bad = [(where, v) for where, v in numbers if v is not None and not math.isfinite(v)]
    assert not bad, f"bench {name}: not finite: {bad[:5]}"
    for key in FIELDS[name]:   # a headline field holds at least one number
        assert any(v is not None for _, v in _numbers(record[key])) or isinstance(
            record[key], (int, float)), f"bench {name}: {key} holds no number"
    if name in PEERS:
        part, measured, reason = PEERS[name]
        part = part(record)
        assert (part.get(measured) is not None) != (part.get(reason) is not None), part
        if part.get(reason) is not None:
            assert part[reason].startswith("peer unavailable: ")


def test_every_bench_has_a_quick_mode():
    """The default suite's guard: every benchmark's main takes ``json`` and ``quick`` and
    has its fields listed here (a new benchmark gets its quick run below)."""
    names = cli.bench_names()
    assert sorted(FIELDS) == names
    for name in names:
        parameters = inspect.signature(importlib.import_module(f"mi_displace.bench.{name}").main).parameters
        assert {"json", "quick"} <= set(parameters), name


def test_quick_bench_without_its_peer(variant_llvm, tmp_path, capsys, monkeypatch):
    """``bench raster --quick`` (seconds) with ``moderngl`` not importable: the record is
    complete and says why llvmpipe was not measured, with the line that installs it."""
    monkeypatch.setitem(sys.modules, "moderngl", None)
    record = run_quick("raster", variant_llvm, tmp_path, capsys)
    check_record("raster", record)
    assert record["llvmpipe_s"] is None
    assert "pip install 'mi-displace[peers]'" in record["llvmpipe_reason"]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FIELDS))
def test_bench_quick_runs(name, variant_llvm, tmp_path, capsys):
    check_record(name, run_quick(name, variant_llvm, tmp_path, capsys))
