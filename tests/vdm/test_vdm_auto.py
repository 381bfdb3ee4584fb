"""Table sizes from the projected size of one tile (issue 13): res / theta = "auto"."""
import math

import mitsuba as mi
import numpy as np
import pytest

from mi_displace.vdm import auto


def _sensor(width, distance=4.0, fov=30.0):
    return mi.load_dict({"type": "perspective", "fov": fov, "to_world": mi.ScalarTransform4f().look_at(
        origin=[0, -distance, 0], target=[0, 0, 0], up=[0, 0, 1]),
        "film": {"type": "hdrfilm", "width": width, "height": width}})


def _plane(sensor, **kw):
    height = {"type": "cells", "to_uv": mi.ScalarTransform4f().scale([4, 4, 1])}
    bsdf = dict({"type": "vdm", "height": height, "depth": 0.05, "tiling": 4, "res": "auto",
                 "theta": "auto", "phi": 8, "svd_terms": 4, "mvm_terms": 2}, **kw)
    if sensor is not None:
        bsdf["sensor"] = sensor
    # the plane faces the sensor: z = 0 plane rotated to face -y
    return mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolution": 4, "bsdf": bsdf,
                         "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], 90)})


def test_projected_tile_size_is_analytic(variant):
    # a 2 x 2 plane facing the camera at distance 4 with 4 x 4 tiles: tile 0.5 world units;
    # the view is 2 * 4 * tan(15 deg) wide, so one tile spans W * 0.5 / (8 tan 15 deg) px
    # at the centre (nearest faces, same depth everywhere on a facing plane)
    for width in (64, 256):
        shape = _plane(_sensor(width))
        stats = shape.bsdf().build_stats
        expected = width * 0.5 / (2 * 4.0 * math.tan(math.radians(15)))
        assert stats["auto"]["tile_px"] == pytest.approx(expected, rel=1e-4)
        assert stats["res"] == 2 ** math.ceil(math.log2(expected))
        assert stats["theta"] == min(16, max(4, 2 * math.ceil(math.pi * 0.1 * expected)))
        for key in ("table_bytes", "compressed_bytes", "cached", "tile_size"):
            assert key in stats, key
    # farther away: smaller on screen, coarser table
    near, far = _plane(_sensor(128, 4.0)), _plane(_sensor(128, 16.0))
    assert far.bsdf().build_stats["res"] < near.bsdf().build_stats["res"]


def test_auto_needs_a_sensor_and_sizes_are_bounded(variant):
    with pytest.raises(Exception, match="sensor"):
        _plane(None)
    assert auto.auto_sizes(1e-3, 0.1) == {"tile_px": 1e-3, "res": 16, "theta": 4}
    big = auto.auto_sizes(1e5, 0.1)
    assert big["res"] == 512 and big["theta"] == 16


def test_build_stats_of_every_mesostructure_bsdf(variant):
    height = {"type": "cells", "to_uv": mi.ScalarTransform4f().scale([2, 2, 1])}
    for kind, key in (("vdm", "res"), ("horizon", "azimuths"), ("relief", "steps")):
        bsdf = {"type": kind, "height": height, "depth": 0.05, "tiling": 2}
        if kind == "vdm":
            bsdf.update(res=16, theta=4, phi=8, svd_terms=4, mvm_terms=2)
        shape = mi.load_dict({"type": "vdm_mesh", "base": "plane", "resolution": 2, "bsdf": bsdf})
        stats = shape.bsdf().build_stats
        assert isinstance(stats, dict) and key in stats and "tile_size" in stats, (kind, stats)
        assert np.isfinite(stats["tile_size"])


def test_auto_from_xml_with_a_sensor_reference(variant):
    scene = mi.load_string("""<scene version="3.0.0">
        <sensor type="perspective" id="camera">
            <float name="fov" value="30"/>
            <transform name="to_world"><lookat origin="0, -4, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
            <film type="hdrfilm"><integer name="width" value="96"/><integer name="height" value="96"/></film>
        </sensor>
        <integrator type="raster"/>
        <emitter type="constant"/>
        <shape type="vdm_mesh">
            <string name="base" value="sphere"/>
            <integer name="resolution" value="16"/>
            <bsdf type="vdm">
                <texture type="cells" name="height">
                    <transform name="to_uv"><scale x="4" y="2"/></transform>
                </texture>
                <float name="depth" value="0.05"/>
                <float name="tiling_u" value="4"/>
                <float name="tiling_v" value="2"/>
                <string name="res" value="auto"/>
                <string name="theta" value="auto"/>
                <integer name="phi" value="8"/>
                <integer name="curvatures" value="2"/>
                <ref name="sensor" id="camera"/>
            </bsdf>
        </shape>
    </scene>""")
    stats = scene.shapes()[0].bsdf().build_stats
    assert 16 <= stats["res"] <= 512 and stats["auto"]["tile_px"] > 0
    assert np.all(np.isfinite(np.asarray(mi.render(scene))))
