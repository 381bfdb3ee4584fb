"""Variant selection, plugin registration and the LLVM version check."""
import glob
import os
import subprocess
import sys

import mitsuba as mi
import pytest

import mi_displace
from mi_displace.core import backend


def test_init_registers_plugins_and_reregisters(variant_llvm):
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "raster"},
                          "s": {"type": "displaced", "base": "sphere", "resolution": 8}})
    assert scene.shapes()[0].build_stats["faces"] > 0
    mi.set_variant("scalar_rgb")
    assert mi_displace.init("llvm_ad_rgb") == "llvm_ad_rgb"  # back again, plugins re-made
    assert mi.load_dict({"type": "displaced", "resolution": 4}).face_count() > 0


def test_variant_resolution(monkeypatch):
    monkeypatch.setenv("MI_DISPLACE_VARIANT", "llvm_ad_rgb")
    assert backend.resolve_variant() == "llvm_ad_rgb"
    with pytest.raises(ValueError, match="scalar_rgb"):
        backend.resolve_variant("scalar_rgb")
    with pytest.raises(ValueError, match="not_a_variant"):
        backend.resolve_variant("not_a_variant")


def test_llvm_version_is_new_enough():
    assert backend.check_llvm() >= (17, 0, 0)


OLD_LLVM = sorted(p for p in glob.glob("/usr/lib/*/libLLVM-1[0-6].so*")
                  + glob.glob("/usr/lib/*/libLLVM.so.1[0-6]*") + glob.glob("/lib/*/libLLVM-1[0-6].so*"))


@pytest.mark.skipif(not OLD_LLVM, reason="no libLLVM older than 17 on this machine")
def test_old_llvm_raises_clear_error_instead_of_aborting():
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=OLD_LLVM[0])
    code = "import mi_displace; mi_displace.init('llvm_ad_rgb')"
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 1  # a Python exception, not an abort (-6)
    assert "LLVMVersionError" in r.stderr
    assert "libllvm19" in r.stderr and "DRJIT_LIBLLVM_PATH" in r.stderr
    assert "LLVM ERROR" not in r.stderr
