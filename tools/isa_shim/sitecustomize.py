"""Emulation shim of tools/isa_reproducibility.py: Dr.Jit's LLVM backend targeting another CPU.

Dr.Jit has no environment variable and no Python function for its LLVM target; its core library
exports the C++ function ``jit_llvm_set_target(cpu, features, vector_width)``. When this folder
is first on ``PYTHONPATH`` and ``MCBENCH_ISA_DRJIT_TARGET`` is ``CPU:WIDTH`` (e.g. ``haswell:8``,
the width Dr.Jit picks on an AVX2 CPU), every Python process (Snakemake's jobs and the pool's
workers alike) wraps ``mitsuba.set_variant`` so that after an LLVM variant is set the target is
overridden (features from ``NUMBA_CPU_FEATURES``, the same Haswell list) and a line says so on
stderr, i.e. in the job's log.
"""

import os
import sys

_TARGET = os.environ.get("MCBENCH_ISA_DRJIT_TARGET")


def _override(cpu: str, width: int) -> None:
    import ctypes

    import drjit

    core = ctypes.CDLL(os.path.join(os.path.dirname(drjit.__file__), "libdrjit-core.so"))
    features = os.environ.get("NUMBA_CPU_FEATURES")
    core._Z19jit_llvm_set_targetPKcS0_j(cpu.encode(), features.encode() if features else None, ctypes.c_uint32(width))
    name = core._Z19jit_llvm_target_cpuv
    name.restype = ctypes.c_char_p
    got = core._Z21jit_llvm_vector_widthv
    got.restype = ctypes.c_uint32
    print(f"isa shim: Dr.Jit LLVM target {name().decode()} width {got()}", file=sys.stderr, flush=True)


class _Finder:
    """Wrap ``mitsuba.set_variant`` once mitsuba is imported."""

    def find_spec(self, fullname, path, target=None):
        if fullname != "mitsuba":
            return None
        import importlib.machinery

        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        exec_module = spec.loader.exec_module

        def exec_and_wrap(module):
            exec_module(module)
            module = sys.modules[fullname]          # mitsuba replaces itself by its alias module
            original = module.set_variant

            def set_variant(*args, **kwargs):
                result = original(*args, **kwargs)
                if str(module.variant() or "").startswith("llvm"):
                    cpu, _, width = _TARGET.partition(":")
                    _override(cpu, int(width))
                return result

            module.set_variant = set_variant

        spec.loader.exec_module = exec_and_wrap
        return spec


if _TARGET:
    sys.meta_path.insert(0, _Finder())
