"""Long checks: the benchmark record and the raster/path consistency on DDM geometry."""
import json
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.evaluate import metrics

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "ddm_thorns_sphere.xml"


@pytest.mark.slow
def test_bench_ddm_record(variant_llvm, capsys):
    from mi_displace.bench import ddm

    assert ddm.main(json=True) == 0
    record = json.loads(capsys.readouterr().out)
    for key in ("vertices", "map_time_warm_s", "rms_error_rel", "max_error_rel", "maps_bytes",
                "mesh_bytes", "table1"):
        assert key in record
    assert record["vertices"] >= 3_000_000
    assert 0 < record["rms_error_rel"] <= record["max_error_rel"] < 1e-3
    assert record["mesh_bytes"] > record["hddm_bytes"] > record["maps_bytes"]
    assert len(record["table1"]) == 6 and all(r["ours_tiles"] > 0 for r in record["table1"])


@pytest.mark.slow
def test_raster_agrees_with_path_on_the_exact_ddm_geometry(variant):
    """DESIGN protocol item 4: same exact geometry, raster vs path within the noise floor."""
    def render(integrator, spp, seed):
        scene = mi.load_file(str(SCENE), mode="reference", integrator=integrator, res="96")
        return metrics.assert_finite(np.array(mi.render(scene, spp=spp, seed=seed))[..., :3], integrator)

    a, b = render("path", 256, 0), render("path", 256, 1)
    raster = render("raster", 1, 0)
    noise_floor, _ = metrics.flip(a, b)
    error, _ = metrics.flip(0.5 * (a + b), raster)
    assert error <= 1.5 * noise_floor
