"""On-disk table cache keyed by the inputs."""
from pathlib import Path

import numpy as np

from mi_displace.vdm import build, cache


def _heights():
    return np.random.default_rng(4).random((8, 8)).astype(np.float32)


def test_key_depends_on_every_input():
    h = _heights()
    base = cache.key(h, depth=0.1, n_theta=8)
    assert cache.key(h, depth=0.1, n_theta=8) == base
    assert cache.key(h, depth=0.2, n_theta=8) != base
    assert cache.key(h, depth=0.1, n_theta=4) != base
    h2 = h.copy()
    h2[0, 0] += 0.01
    assert cache.key(h2, depth=0.1, n_theta=8) != base


def test_hit_miss_and_corrupt_entry(variant, tmp_path, monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_CACHE", str(tmp_path))
    spec = build.VDMSpec(res=8, n_theta=4, n_phi=4, n_curv=2, depth=0.1, c_range=(0.0, 1.0))
    first = build.build(_heights(), spec)
    assert first.stats["cached"] is False
    second = build.build(_heights(), spec)
    assert second.stats["cached"] is True
    np.testing.assert_array_equal(first.compressed.weights, second.compressed.weights)
    np.testing.assert_array_equal(first.mvm_full, second.mvm_full)
    path = cache.cache_dir() / f"{first.stats['key']}.npz"
    assert path.is_file() and str(path).startswith(str(tmp_path))
    path.write_bytes(b"not a zip")
    third = build.build(_heights(), spec)
    assert third.stats["cached"] is False
    np.testing.assert_allclose(third.compressed.weights, first.compressed.weights, atol=1e-6)


def test_key_depends_on_the_builder_code(tmp_path, monkeypatch):
    h = _heights()
    base = cache.key(h, depth=0.1)
    # the digest covers every builder module's bytes: an edited copy gives another version
    copies = []
    for name in cache.BUILDER_MODULES:
        src = Path(cache.__file__).with_name(name)
        (tmp_path / name).write_bytes(src.read_bytes())
        copies.append(tmp_path / name)
    assert cache.code_version(copies) == cache.code_version()
    copies[0].write_bytes(copies[0].read_bytes() + b"# a fix\n")
    assert cache.code_version(copies) != cache.code_version()
    # and the key follows the code version
    monkeypatch.setattr(cache, "code_version", lambda files=None: "another build")
    assert cache.key(h, depth=0.1) != base
