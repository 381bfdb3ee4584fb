"""mi_displace: displacement mapping for Mitsuba 3.

Call :func:`init` first: it picks the variant (argument, ``MI_DISPLACE_VARIANT`` or
``llvm_ad_rgb``), checks the LLVM backend and registers the plugins
(``displaced`` shape, ``raster`` integrator, procedural height textures).
"""
from mi_displace.core.backend import LLVMVersionError, check_llvm, init

__version__ = "0.1.0"
__all__ = ["init", "check_llvm", "LLVMVersionError", "__version__"]
