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


def test_area_sweep_small(variant_llvm):
    """`--area-sweep` at 32²: every row measured, more light points closer to path, the
    shadow-mapped row close to its shadow-ray twin."""
    record = bench.area_sweep(res=32, ref_spp=256, aa=2, counts=(1, 16), map_points=4,
                              map_resolutions=(256,))
    rows = {(r["area_samples"], r.get("shadows", "ray")): r for r in record["raster"]}
    assert set(rows) == {(1, "ray"), (4, "ray"), (16, "ray"), (4, "map")}
    assert all(r["render_s"] > 0 and 0 < r["flip"] < 1 for r in rows.values())
    assert rows[(16, "ray")]["flip"] < rows[(1, "ray")]["flip"]
    assert rows[(4, "map")]["flip_vs_shadow_rays"] < 0.02
    assert [p["spp"] for p in record["path"]] == [4, 16, 64]
