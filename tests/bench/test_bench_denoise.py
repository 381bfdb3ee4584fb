"""``bench denoise``: each row agrees with the comparison it ran (``metrics.json``): the
crossovers lie between the two curve points around the approximation's FLIP, the time ratio
is their quotient, and the FLIP at equal time is the best curve point no slower, by brute
force along the written curves."""
import json
import math

import pytest

from mi_displace.bench import denoise as bench


def test_rows_match_the_comparison(variant_llvm, tmp_path):
    sizes = bench.Sizes(("volume_nucleon_pull",), 24, 16, "fast")
    record = bench.run(sizes, tmp_path)
    assert [r["scene"] for r in record["rows"]] == ["volume_nucleon_pull"]
    row = record["rows"][0]
    info = json.loads((tmp_path / "volume_nucleon_pull" / "metrics.json").read_text())
    assert (row["width"], row["height"]) == (24, 24)
    assert row["approx_flip"] == info["flip_mean"] and row["approx_time_s"] == info["approx_time_warm_s"]
    for key, curve_key in (("raw", "path_curve"), ("denoised", "denoised_curve")):
        curve, entry = info[curve_key], row[key]
        assert curve and all(math.isfinite(c["flip"]) and c["time_s"] > 0 for c in curve)
        assert entry["first_point"] == {k: curve[0][k] for k in ("spp", "time_s", "flip")}
        within = [c["flip"] for c in curve if c["time_s"] <= row["approx_time_s"]]
        assert entry["flip_at_equal_time"] == (min(within) if within else None)
        within = [c["flip"] for c in curve
                  if c["render_s"] + c.get("denoise_s", 0) <= info["approx_render_warm_s"]]
        assert entry["flip_at_equal_render_time"] == (min(within) if within else None)
        reached = [i for i, c in enumerate(curve) if c["flip"] <= row["approx_flip"]]
        if not reached:
            assert entry["crossover_s"] is None and entry["time_ratio"] is None
            assert "does not reach" in entry["verdict"]
            continue
        around = curve[max(0, reached[0] - 1):reached[0] + 1]
        spps = [c["spp"] for c in around]
        assert min(spps) <= entry["crossover_spp"] <= max(spps)
        assert entry["time_ratio"] == pytest.approx(entry["crossover_s"] / row["approx_time_s"])
