"""Smallest reproduction (docs/platform.md): a Python plugin's ValueError reaches the caller
of ``mi.load_dict`` as a RuntimeError whose text embeds the Python traceback; the exception
object is not chained.  Usage: ``python python_plugin_error.py [VARIANT]`` (scalar_rgb)."""
import sys

import drjit as dr
import mitsuba as mi

mi.set_variant(sys.argv[1] if len(sys.argv) > 1 else "scalar_rgb")


class Raising(mi.BSDF):
    def __init__(self, props):
        raise ValueError("raising: parameter 'roughness' must be > 0, got -1")


mi.register_bsdf("raising", lambda props: Raising(props))
print(f"mitsuba {mi.__version__}, drjit {dr.__version__}, variant {mi.variant()}")
try:
    mi.load_dict({"type": "raising"})
except Exception as error:
    print(f"{type(error).__name__}, __cause__ {error.__cause__!r}, __context__ {error.__context__!r}")
    print(error)
