"""`mi-displace bench bake` writes where --out says, never into the checkout by default (issue 15
item 11).  The benchmark's parts are replaced by stubs: this checks where files go, not figures."""
import json
from pathlib import Path

import pytest

from mi_displace.bench import bake as bench
from mi_displace.bench._timing import output_dir

REPO = Path(__file__).resolve().parents[2]   # the checkout


@pytest.fixture
def stubbed(monkeypatch):
    table = [{"res": 2048, "aa": 1, "ours_s": 1.0, "naive_s": 2.0, "speedup": 2.0}]
    comp = [{"codec": "png16", "res": 1024, "ratio": 10.0, "hausdorff_rel": 0.001}]
    meshdiff = {"hausdorff_rel": 0.001, "rms_rel": 0.0001}
    monkeypatch.setattr(bench, "_pair", lambda: (_Mesh(), _Mesh()))
    monkeypatch.setattr(bench, "timing_table", lambda *a: table)
    monkeypatch.setattr(bench, "cold_start", lambda *a: {})
    monkeypatch.setattr(bench, "multistep_example", lambda *a: {})
    monkeypatch.setattr(bench, "spot_pairs", lambda *a: [])
    monkeypatch.setattr(bench, "restoration_sweep", lambda *a: [])
    monkeypatch.setattr(bench, "restoration_and_compression", lambda *a: (meshdiff, comp))
    monkeypatch.setattr("mi_displace.bake.baker.default_max_distance", lambda h, l: (0.1, {}))
    monkeypatch.setattr(bench, "_plot", lambda table, comp, sweep, out: (out / "bake_bench.png").write_bytes(b""))


class _Mesh:
    faces = [0]
    diagonal = 1.0


def test_default_out_is_outside_the_checkout():
    assert not output_dir("bake").resolve().is_relative_to(REPO.resolve())


def test_bench_writes_only_under_out(stubbed, tmp_path, capsys):
    figures = REPO / "docs" / "figures"
    before = {p: p.stat().st_mtime_ns for p in figures.iterdir()} if figures.is_dir() else {}
    from mi_displace.cli import main

    assert main(["bench", "bake", "--out", str(tmp_path / "o")]) == 0
    written = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert "bake_bench.json" in written and "bake_bench.png" in written and len(written) == 8
    assert json.loads((tmp_path / "o" / "bake_bench.json").read_text())["speedup_vs_naive"] == 2.0
    after = {p: p.stat().st_mtime_ns for p in figures.iterdir()} if figures.is_dir() else {}
    assert after == before                                     # docs/figures untouched
    assert str(tmp_path / "o") in capsys.readouterr().out


def test_out_refused_by_benchmarks_that_write_nothing(variant_llvm, capsys):
    from mi_displace.cli import main

    with pytest.raises(SystemExit) as e:
        main(["bench", "core", "--out", "/tmp/x"])
    assert e.value.code == 2 and "--out" in capsys.readouterr().err
