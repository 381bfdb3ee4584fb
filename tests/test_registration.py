"""The plugins are there for the variant in use after ``import mi_displace`` with a supported
variant already set (no bare "Plugin not found" for a user who skipped ``init()``)."""
import subprocess
import sys


def test_import_registers_for_a_variant_already_set(variant):
    code = ("import mitsuba as mi; mi.set_variant('llvm_ad_rgb'); import mi_displace; "
            "print(type(mi.load_dict({'type': 'cells'})).__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "Cells", out.stderr[-2000:]
