"""Shared fixtures: a ``variant`` fixture per vectorised RGB variant (Mitsuba's pattern).

Each test that takes ``variant`` runs once per variant in ``MI_DISPLACE_TEST_VARIANTS``
(comma separated; default ``llvm_ad_rgb,cuda_ad_rgb``) whose backend exists on this machine:
as in Mitsuba's ``src/conftest.py``, a variant that cannot run gets no test items at all
(no phantom skips).  The fixture sets the variant and registers our plugins.
"""
import gc
import os
import zlib

import drjit as dr
import numpy as np
import pytest

import mi_displace

def _available(variant: str) -> bool:
    backend = dr.JitBackend.CUDA if variant.startswith("cuda") else dr.JitBackend.LLVM
    return dr.has_backend(backend)


REQUESTED_VARIANTS = os.environ.get("MI_DISPLACE_TEST_VARIANTS", "llvm_ad_rgb,cuda_ad_rgb").split(",")
TEST_VARIANTS = [v for v in REQUESTED_VARIANTS if _available(v)]


@pytest.fixture(params=TEST_VARIANTS)
def variant(request):
    return mi_displace.init(request.param)


@pytest.fixture
def variant_llvm():
    """The default CPU variant only (tests of CPU-specific behaviour)."""
    return mi_displace.init("llvm_ad_rgb")


@pytest.fixture
def rng(request):
    """A NumPy generator seeded by the test's own name: each test draws the same points
    whatever ran before it in its worker (a module-wide generator made results depend on
    pytest-xdist's distribution)."""
    return np.random.default_rng(zlib.crc32(request.node.name.encode()))


@pytest.fixture(autouse=True)
def _release_scenes():
    """Collect each test's garbage before the next test.

    The library no longer needs it for its own checks (a BSDF that is not set up fails only
    its own scene: tests/vdm/test_vdm_scene_sequence.py).  But tests drop scenes inside
    reference cycles (``pytest.raises`` keeps tracebacks), and Dr.Jit traces every live
    instance into each vectorised call through plain pointers: Python's collector, started
    by an allocation inside that trace, can free a dropped scene's instance before its turn
    (a segfault that depends on test order).  Our plugin methods and the raster integrator
    pause the collector (plugins/_guard.py ``collector_paused``); allocations in Dr.Jit's
    and nanobind's own code between instances, under Mitsuba's C++ integrators, cannot be
    covered from Python, so the suite does not leave garbage for them.

    What survives the collection (modules, session fixtures, caches) is then frozen
    (``gc.freeze``): the next test's collection scans only what was allocated since, not
    the whole process again (a full collection after every test took a third of the
    suite's time)."""
    yield
    gc.collect()
    gc.freeze()



@pytest.fixture(scope="session")
def built_once():
    """``built_once(name, build)``: the result of ``build()``, built once per test run and
    variant and shared by every test that asks for ``name`` (a fixture that takes ``variant``
    first, so that the variant is set).  For expensive inputs (a bake, captured depth images)
    that tests only read: a test must not change what it gets."""
    import mitsuba as mi

    built = {}

    def get(name, build):
        key = (mi.variant(), name)
        if key not in built:
            built[key] = build()
        return built[key]

    return get
