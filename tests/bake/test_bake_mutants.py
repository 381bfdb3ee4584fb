"""Tests written for mutants of bake/ that survived the suite (issue 19; docs/testing.md,
"Bake, volume and slicing modules").  Each asserts numbers against an independent truth:
planes at known heights, closed forms, or a NumPy re-computation."""
import re

import numpy as np
import pytest
from conftest import plane

from mi_displace.bake import baker
from mi_displace.bake.baker import bake
from mi_displace.bake.meshdata import MeshData


def _stack(*meshes):
    pos = np.concatenate([m.positions for m in meshes])
    faces, off = [], 0
    for m in meshes:
        faces.append(m.faces + off)
        off += len(m.positions)
    return MeshData(pos, np.concatenate(faces))


def test_cage_ray_flags_a_second_crossing_and_only_that(variant):
    # cage 0.1 above the low-poly: the ray from the cage meets z = 0.02 first (t = 0.08),
    # then z = -0.02 within max_distance: a fold along the cage direction (ambiguous);
    # one layer alone is unambiguous
    low = plane(n=2)
    r = bake(_stack(plane(z=0.02, n=4), plane(z=-0.02, n=4)), low, res=8, cage_offset=0.1,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["ambiguous"] == 64
    assert np.allclose(r.maps["displacement"], 0.02, atol=1e-6)
    r = bake(_stack(plane(z=0.02, n=4), plane(z=-0.07, n=4)), low, res=8, cage_offset=0.1,
             max_distance=0.05, pad=0)
    assert r.record["counts"]["ambiguous"] == 0 and r.record["counts"]["ok"] == 64


def test_dual_depth_is_the_next_surface_behind(variant):
    # the front surface at +0.03 and a far wall at -0.02 (facing away, as a thin shell's
    # inner side does): back_depth is -0.02; without a second surface it is -max_distance
    low = plane(n=2)
    r = bake(_stack(plane(z=0.03, n=4), plane(z=-0.02, n=4, flip=True)), low, res=8,
             max_distance=0.1, pad=0, map_formats=["dual_d8_n16"])
    assert np.allclose(r.maps["displacement"], 0.03, atol=1e-5)
    assert np.allclose(r.maps["back_depth"], -0.02, atol=1e-5)
    r = bake(plane(z=-0.04, n=4), low, res=8, max_distance=0.1, pad=0, map_formats=["dual_d8_n16"])
    assert np.allclose(r.maps["displacement"], -0.04, atol=1e-5)
    assert np.allclose(r.maps["back_depth"], -0.1, atol=1e-6)


def test_without_meminfo_a_default_bake_still_fits(monkeypatch):
    # no MemAvailable to read (not Linux, or /proc hidden): the fallback must be an amount
    # that admits an ordinary bake (a 1024^2 map, aa 2), not zero
    class NoProc:
        def __init__(self, *args):
            pass

        def read_text(self):
            raise OSError("no /proc")

    monkeypatch.delenv("MI_DISPLACE_BAKE_MEMORY", raising=False)
    monkeypatch.setattr(baker, "Path", NoProc)
    have = baker.available_memory()
    assert have > baker.memory_estimate(1024, 1024, 2) / 0.8
    assert baker.check_settings(1024, 2, None, 8) == (1024, 1024)


def test_uv_warning_is_the_whole_sentence(variant):
    low = plane(n=2)
    low.uvs[4] = low.uvs[0]
    with pytest.warns(UserWarning) as w:
        r = bake(plane(z=0.01, n=4), low, res=32, max_distance=0.1)
    n_deg, n_over = r.record["low"]["uv_degenerate_triangles"], r.record["counts"]["uv_overlap_texels"]
    assert re.fullmatch(rf"low-poly UVs: {n_deg} degenerate triangles, {n_over} texels covered by "
                        r"overlapping triangles \(texture mapping not unambiguous, §3\.1\)",
                        str(w[0].message))
