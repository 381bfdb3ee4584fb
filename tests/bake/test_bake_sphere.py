"""Analytic check: a sphere displaced by a known function, baked onto the plain sphere."""
import numpy as np
from bake_meshes import AMPLITUDE, _sphere_mesh, sphere_height

from mi_displace.bake.baker import bake
from mi_displace.bake.formats import read_map
from mi_displace.bake.meshdata import MeshData
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


def test_object_normals_of_a_sphere_are_radial(variant):
    # a finer sphere of radius 1.02 over the unit sphere: the high-poly's smooth shading normal
    # at each texel is the radial direction of the texel's UV point (analytic parametrisation)
    import drjit as dr
    import mitsuba as mi

    from mi_displace.core import surfaces

    high = _sphere_mesh(96, 48, 0.0)
    high = MeshData(high.positions * np.float32(1.02), high.faces, None)
    r = bake(high, _sphere_mesh(48, 24, 0.0), res=64, max_distance=0.1, pad=0)
    rows, cols = np.nonzero(r.covered)
    u, v = (cols + 0.5) / 64, 1 - (rows + 0.5) / 64       # formats.UV_CONVENTION
    s = surfaces.make_base("sphere", radius=1.0).sample(mi.Float(u), mi.Float(v))
    radial = np.stack([np.asarray(c) for c in dr.normalize(s.p)], 1)
    n = r.maps["normal_object"][rows, cols]
    cos = (n * radial).sum(1)
    assert len(cos) > 0.9 * 64 * 64 and np.median(cos) > 0.9999 and cos.min() > 0.998
    # the low-poly's chords lie inside the unit sphere by at most 1 - cos(pi / 24) (24 rings)
    d = r.maps["displacement"][rows, cols]
    assert d.min() > 0.02 - 1e-3 and d.max() < 0.02 + (1 - np.cos(np.pi / 24)) * 1.02
