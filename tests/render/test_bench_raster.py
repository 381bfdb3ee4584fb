"""`bench raster` on a small sphere: every timing field present and positive, the z-buffer
image equal to the ray-traced one, the GL peer reported as null with its reason when not
requested."""
import pytest

from mi_displace.bench import raster as bench


@pytest.mark.slow
def test_bench_raster_small(variant_llvm):
    record = bench.run(bench.QUICK, with_ddm=False, with_gl=False)
    assert record["faces"] > 5_000
    for key in ("zbuffer_s", "zbuffer_shadow_map_s", "raytrace_s", "raytrace_shadow_rays_s",
                "accel_build_s"):
        assert record[key] > 0, key
    assert record["zbuffer_vs_raytrace_pixels_differing"] < 2e-3
    assert record["llvmpipe_s"] is None and "not requested" in record["llvmpipe_reason"]
