"""Shared fixtures: a ``variant`` fixture per vectorised RGB variant (Mitsuba's pattern).

Each test that takes ``variant`` runs once per variant in ``MI_DISPLACE_TEST_VARIANTS``
(comma separated; default ``llvm_ad_rgb,cuda_ad_rgb``) and is skipped where the
backend is missing.  The fixture sets the variant and registers our plugins.
"""
import os

import drjit as dr
import pytest

import mi_displace

TEST_VARIANTS = os.environ.get("MI_DISPLACE_TEST_VARIANTS", "llvm_ad_rgb,cuda_ad_rgb").split(",")


def _available(variant: str) -> bool:
    backend = dr.JitBackend.CUDA if variant.startswith("cuda") else dr.JitBackend.LLVM
    return dr.has_backend(backend)


@pytest.fixture(params=TEST_VARIANTS)
def variant(request):
    if not _available(request.param):
        pytest.skip(f"{request.param}: backend not available on this machine")
    return mi_displace.init(request.param)


@pytest.fixture
def variant_llvm():
    """The default CPU variant only (tests of CPU-specific behaviour)."""
    return mi_displace.init("llvm_ad_rgb")
