"""Smallest reproduction (docs/platform.md): Dr.Jit's LLVM backend with libLLVM 19.1 crashes
(SIGSEGV inside LLVM's SelectionDAG instruction selection) compiling an unsigned division of
a loaded (evaluated) array by a per-lane divisor made of a clipped difference; the same
kernel over an array computed in the kernel compiles.  Usage:
``python llvm_division_crash.py {evaluated,inkernel}``.  Worked around in one place:
``mi_displace.render.pixel_order`` divides by constants only."""
import sys

import drjit as dr
from drjit.llvm import Int32, UInt32

print(f"drjit {dr.__version__}, libLLVM {'.'.join(map(str, dr.detail.llvm_version()))}", flush=True)
lane = dr.arange(UInt32, 4096)
if sys.argv[1] == "evaluated":
    dr.eval(lane)   # a loaded input, as dr.compress's output is
divisor = UInt32(4 * dr.clip(Int32(64) - Int32(lane // 256 * 4), 1, 4))
q = (lane % 256) // divisor
dr.eval(q)
print(f"ok {dr.sum(q)[0]}", flush=True)
