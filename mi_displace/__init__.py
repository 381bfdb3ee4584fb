"""mi_displace: displacement mapping for Mitsuba 3.

Call :func:`init` first: it picks the variant (argument, ``MI_DISPLACE_VARIANT`` or
``llvm_ad_rgb``), checks the LLVM backend and registers the plugins
(``displaced`` shape, ``raster`` integrator, procedural height textures); importing the
package registers them already when a supported variant is set.  After
``mi.load_file`` / ``mi.load_dict``, :func:`fit_to_sensors` sizes the shapes that follow the
scene's sensors (``dicing_rate``, ``"auto"``) as the CLI does.
"""
from mi_displace.core.backend import LLVMVersionError, check_llvm, ensure_registered, init
from mi_displace.core.dicing import fit_to_sensors

ensure_registered()    # a supported variant already set: its plugins are there at once

__version__ = "0.1.0"
__all__ = ["init", "check_llvm", "fit_to_sensors", "LLVMVersionError", "__version__"]
