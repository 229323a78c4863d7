"""Mitsuba variant discovery: which variant this process renders with, and its thread pool.

``auto`` picks, in order, ``cuda_ad_rgb`` (Dr.Jit finds a CUDA GPU), ``llvm_ad_rgb`` (a
libLLVM >= :data:`MIN_LLVM_MAJOR` is found, see :func:`find_libllvm`; older versions crash
Dr.Jit 1.5) and ``scalar_rgb`` (single-lane and much slower, with a one-line notice on
stderr). The variant is set once per process (:func:`pick_variant`).
"""

from __future__ import annotations

import glob
import os
import re
import sys

from mcbench import BenchError

__all__ = ["MIN_LLVM_MAJOR", "LLVM_SEARCH_PATTERNS", "find_libllvm", "pick_variant", "set_threads",
           "register_integrator_once"]

MIN_LLVM_MAJOR = 19              # older libLLVM versions crash Dr.Jit 1.5
LLVM_SEARCH_PATTERNS = ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*",
                        "/usr/lib64/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*",
                        "/usr/lib/libLLVM*.so*", "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib")

_active_variant: str | None = None


def _llvm_major(path: str) -> int | None:
    """LLVM major version from a library file name (``libLLVM.so.19.1``, ``libLLVM-19.so``)."""
    match = re.search(r"libLLVM(?:\.so\.|-|\.)(\d+)", os.path.basename(path))
    return int(match.group(1)) if match else None


def find_libllvm() -> tuple[str | None, str]:
    """Path of a usable libLLVM (major >= 19) and a one-line reason when there is none.

    ``DRJIT_LIBLLVM_PATH`` is used when it names an existing file whose version is >= 19 or
    cannot be told from its name; otherwise the newest libLLVM >= 19 in the usual folders.
    """
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    reason = "no libLLVM >= %d found" % MIN_LLVM_MAJOR
    if env:
        major = _llvm_major(env)
        if os.path.isfile(env) and (major is None or major >= MIN_LLVM_MAJOR):
            return env, ""
        reason = (f"DRJIT_LIBLLVM_PATH={env} is " +
                  ("missing" if not os.path.isfile(env) else f"LLVM {major} (< {MIN_LLVM_MAJOR})"))
    found = [(major, path) for pattern in LLVM_SEARCH_PATTERNS for path in glob.glob(pattern)
             if (major := _llvm_major(path)) is not None and major >= MIN_LLVM_MAJOR
             and os.path.isfile(path)]
    if found:
        return max(found)[1], ""
    return None, reason


def pick_variant(requested: str = "auto") -> str:
    """Set the Mitsuba variant once per process and return its name.

    ``"auto"`` gives ``cuda_ad_rgb`` when Dr.Jit finds a CUDA GPU (cluster/GPU runs of the
    paper-scale config), else ``llvm_ad_rgb`` when a libLLVM >= 19 is usable (``DRJIT_LIBLLVM_PATH`` is
    then set to it), else ``scalar_rgb`` with one line on stderr saying why. An explicit
    variant is honoured; a variant Mitsuba lacks raises :class:`BenchError` naming the config
    key ``variant``. Asking for a different variant after one was set raises too.
    """
    global _active_variant
    import mitsuba as mi

    if _active_variant is not None:
        if requested in ("auto", _active_variant):
            return _active_variant
        raise BenchError(f"config key 'variant': this process already renders with "
                         f"'{_active_variant}' and cannot switch to '{requested}'")
    if requested == "auto" and _cuda_usable():
        variant = "cuda_ad_rgb"
    elif requested == "auto":
        library, reason = find_libllvm()
        variant = "scalar_rgb"
        if library is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = library
            import drjit as dr
            if "llvm_ad_rgb" in mi.variants() and dr.has_backend(dr.JitBackend.LLVM):
                variant = "llvm_ad_rgb"
            else:
                reason = f"Dr.Jit cannot use the LLVM backend with {library}"
        if variant == "scalar_rgb":
            print(f"mcbench.render.variants: using scalar_rgb (3-4x slower): {reason}", file=sys.stderr)
    else:
        variant = requested
        if variant not in mi.variants():
            raise BenchError(f"config key 'variant': Mitsuba {mi.__version__} has no variant "
                             f"'{variant}'; available: {', '.join(mi.variants())}")
        if variant.startswith("llvm_"):
            library, reason = find_libllvm()
            if library is None:
                raise BenchError(f"config key 'variant': '{variant}' needs libLLVM >= "
                                 f"{MIN_LLVM_MAJOR} ({reason}); use 'auto' or 'scalar_rgb'")
            os.environ["DRJIT_LIBLLVM_PATH"] = library
    mi.set_variant(variant)
    _active_variant = variant
    return variant


def _cuda_usable() -> bool:
    """True when Mitsuba has ``cuda_ad_rgb`` and Dr.Jit can initialise its CUDA backend."""
    import drjit as dr
    import mitsuba as mi

    try:
        return "cuda_ad_rgb" in mi.variants() and bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # no driver, no device: fall through to the CPU variants
        return False


def set_threads(threads: int | None) -> None:
    """Set the Dr.Jit thread pool size (used by both scalar and LLVM variants) when given."""
    if threads is not None:
        import drjit as dr
        if int(threads) < 1:
            raise BenchError(f"config key 'render_threads': must be >= 1, got {threads}")
        dr.set_thread_count(int(threads))


_registered_integrators: set[tuple[str, str]] = set()


def register_integrator_once(plugin: str, integrator_class) -> str:
    """Register the Python integrator ``plugin`` for Mitsuba's current variant, once per variant
    (``mi.SamplingIntegrator`` and so the class are per variant: ``integrator_class()`` makes it),
    and return ``plugin``. Call after the variant is set (:func:`pick_variant`)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise ValueError("set a Mitsuba variant (mcbench.render.variants.pick_variant) before registering "
                         f"the {plugin} integrator")
    if (plugin, variant) not in _registered_integrators:
        cls = integrator_class()
        mi.register_integrator(plugin, lambda props: cls(props))
        _registered_integrators.add((plugin, variant))
    return plugin
