"""Analytic check: a sphere displaced by a known function, baked onto the plain sphere."""
import numpy as np
from conftest import AMPLITUDE, sphere_height

from mi_displace.bake.baker import bake
from mi_displace.bake.formats import read_map
from mi_displace.bake.restore import restore


def test_map_matches_function(sphere_pair, tmp_path):
    high, low = sphere_pair
    r = bake(high, low, res=256, out_dir=tmp_path, map_formats=["float", "d16"], max_distance=0.2)
    c = r.record["counts"]
    assert c["ok"] > 0.95 * c["covered"] and c["miss"] == 0 and c["beyond"] == 0
    d = r.maps["displacement"]
    assert np.all(np.isfinite(d))
    # restored vertices are p + d n with d read from the map: the radius of each restored vertex must equal 1 + a f(direction) (the known function)
    out = restore(tmp_path / "low.obj", tmp_path / "float.exr", levels=3)
    radius = np.linalg.norm(out.positions, axis=1)
    truth = 1.0 + AMPLITUDE * sphere_height(out.positions)
    err = np.abs(radius - truth)
    assert np.all(np.isfinite(out.positions))
    # high-poly tessellation (256 x 128) and bilinear map lookup bound the error
    assert err.max() < 0.03 * AMPLITUDE, err.max()  # measured 0.02 A
    assert np.sqrt(np.mean(err ** 2)) < 0.006 * AMPLITUDE  # measured 0.0034 A


def check_quantised_restore(tmp_path, result):
    """d16 / d8 restorations within half a quantisation step of the float map's: the step
    from the bit depth and the baked range (over the texels holding a value), not the sidecar."""
    d = result.maps["displacement"][result.maps["filled"]]
    ref = restore(tmp_path / "low.obj", tmp_path / "float.exr", levels=1).positions
    for fmt, bits in (("d16.png", 16), ("d8.png", 8)):
        step = float(d.max() - d.min()) / ((1 << bits) - 1)
        got = restore(tmp_path / "low.obj", read_map(tmp_path / fmt), levels=1).positions
        assert np.abs(got - ref).max() <= 0.5 * step * 1.01 + 1e-6, fmt


def test_quantised_maps_restore_within_their_step(sphere_pair, tmp_path):
    high, low = sphere_pair
    r = bake(high, low, res=128, out_dir=tmp_path, map_formats=["float", "d16", "d8"], max_distance=0.2)
    check_quantised_restore(tmp_path, r)
