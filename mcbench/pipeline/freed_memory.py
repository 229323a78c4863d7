"""A job's freed memory kept in its heap for the next allocation instead of handed back to the
kernel at once (glibc's malloc; elsewhere nothing changes).

glibc serves an allocation above its mmap threshold (128 KiB, rising to at most 32 MiB as such
blocks are freed) with fresh pages of its own ``mmap`` and unmaps them when it is freed, and it
returns the top of its heap to the kernel once more than its trim threshold (128 KiB) is free
there. A network's forward and backward pass allocate and free the same tensors of tens of MB at
every step, so every step maps new pages, and the kernel zeroes each one at its first touch (a
minor page fault). Measured on 2 AMD EPYC Zen 4 vCPUs (``benchmarks/freed_memory.py``,
docs/measurements.md): a one-thread KPCN training of 20 steps spent 2.57 s in the kernel beside
13.5 s of user time (1.45 million page faults), KPCN's inference on a 128 x 128 case 0.48 s beside
0.96 s; with both thresholds at :data:`KEEP_BYTES`, 0.28 s and 0.00 s, user time the same.

:func:`keep_freed_memory` sets both thresholds with ``mallopt`` (the environment's
``MALLOC_MMAP_THRESHOLD_`` and ``MALLOC_TRIM_THRESHOLD_`` do the same for a process started with
them). Called by the processes that run networks: the case jobs' workers
(:mod:`mcbench.pipeline.worker_pool`) and the training jobs. No number changes (where memory comes
from does not touch the arithmetic; tests/pipeline/test_freed_memory.py trains the same weights
either way); the price is that a process keeps its largest heap until it exits.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

__all__ = ["KEEP_BYTES", "M_TRIM_THRESHOLD", "M_MMAP_THRESHOLD", "keep_freed_memory"]

#: glibc's ``mallopt`` parameters (malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: freed blocks up to this size stay in the heap, and so may this much free memory at its top
KEEP_BYTES = 1 << 30


def keep_freed_memory(keep_bytes: int = KEEP_BYTES) -> bool:
    """Have glibc's malloc keep freed memory (up to ``keep_bytes`` per block and at the heap's top)
    for reuse: both thresholds of the module docstring set with ``mallopt``. Returns whether both
    were set (False off Linux or without glibc, where allocation stays as it was)."""
    if isinstance(keep_bytes, bool) or not isinstance(keep_bytes, int) or not 0 < keep_bytes < 2 ** 31:
        raise ValueError(f"keep_bytes must be an int in 1 .. 2^31 - 1, got {keep_bytes!r}")
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):   # musl and others: no mallopt
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, keep_bytes)) and bool(mallopt(M_TRIM_THRESHOLD, keep_bytes))
