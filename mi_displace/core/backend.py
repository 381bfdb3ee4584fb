"""Variant selection, the LLVM version check and plugin registration.

Dr.Jit 1.5's LLVM backend aborts the whole process inside the JIT on LLVM < 17
(``LLVM ERROR: Cannot select: ... fminimum``).  :func:`check_llvm` reads the
version Dr.Jit loaded *before* any kernel is compiled and raises instead.
"""
from __future__ import annotations

import os

import drjit as dr
import mitsuba as mi

DEFAULT_VARIANT = "llvm_ad_rgb"
MIN_LLVM = (17, 0, 0)

LLVM_FIX = (
    "install LLVM 19 (Debian/Ubuntu: `sudo apt-get install -y libllvm19`; Dr.Jit finds it "
    "by itself) or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version >= 17"
)


class LLVMVersionError(RuntimeError):
    """Dr.Jit's LLVM backend is missing or too old to run our kernels."""


def check_llvm() -> tuple[int, int, int]:
    """Return Dr.Jit's libLLVM version; raise :class:`LLVMVersionError` if < 17 or absent.

    Runs no kernel: Dr.Jit only loads the library to answer.
    """
    if not dr.has_backend(dr.JitBackend.LLVM):
        path = os.environ.get("DRJIT_LIBLLVM_PATH", "<unset>")
        raise LLVMVersionError(
            f"Dr.Jit could not load libLLVM (DRJIT_LIBLLVM_PATH={path}); {LLVM_FIX}."
        )
    version = tuple(int(x) for x in dr.detail.llvm_version())
    if version < MIN_LLVM:
        raise LLVMVersionError(
            f"Dr.Jit loaded libLLVM {'.'.join(map(str, version))}, but Dr.Jit 1.5 aborts the "
            f"process on LLVM < 17; {LLVM_FIX}."
        )
    return version


def resolve_variant(variant: str | None = None) -> str:
    """The variant to use: the argument, else ``MI_DISPLACE_VARIANT``, else ``llvm_ad_rgb``."""
    variant = variant or os.environ.get("MI_DISPLACE_VARIANT") or DEFAULT_VARIANT
    if variant not in mi.variants():
        raise ValueError(
            f"variant {variant!r} is not one of Mitsuba's variants: {', '.join(mi.variants())}"
        )
    if not variant.endswith("_rgb") or variant.startswith("scalar"):
        raise ValueError(
            f"variant {variant!r}: mi_displace needs a vectorised RGB variant "
            "(llvm_ad_rgb or cuda_ad_rgb)"
        )
    return variant


def supported(variant: str | None) -> bool:
    """Whether ``variant`` is one mi_displace's plugins can be registered for."""
    return (variant is not None and variant.endswith("_rgb") and not variant.startswith("scalar")
            and variant in mi.variants())


def ensure_registered() -> None:
    """Register the plugins for Mitsuba's current variant when it is a supported one and they
    are not yet registered for it (after ``import mi_displace`` or an ``mi.set_variant``);
    our loaders call it, so a variant change never ends in "Plugin not found"."""
    from mi_displace import plugins

    variant = mi.variant()
    if supported(variant) and plugins.registered_variant() != variant:
        init(variant)


def init(variant: str | None = None) -> str:
    """Set the Mitsuba variant, register every mi_displace plugin for it and put the packaged
    scenes on Mitsuba's file resolver (:func:`mi_displace.core.resources.add_to_file_resolver`).

    Call again after any ``mi.set_variant``: plugin classes derive from the variant's
    own ``mi.Mesh`` / ``mi.Texture`` / ... and are redefined for it.

    Returns:
        The variant name that is now active.
    """
    variant = resolve_variant(variant)
    if variant.startswith("llvm"):
        check_llvm()
    elif variant.startswith("cuda") and not dr.has_backend(dr.JitBackend.CUDA):
        raise ValueError(f"variant {variant!r} needs a CUDA GPU and driver; none was found "
                         f"(use {DEFAULT_VARIANT} on the CPU)")
    mi.set_variant(variant)
    from mi_displace import plugins
    from mi_displace.core.resources import add_to_file_resolver

    plugins.register_all()
    add_to_file_resolver()
    return variant
