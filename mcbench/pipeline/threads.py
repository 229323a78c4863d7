"""Every job uses exactly the threads Snakemake gave it (the rule's ``threads:``), no more.

A job is one Python process, and several libraries in it start thread pools of their own,
sized by default to every core of the machine: numba's parallel loops (its ``omp`` threading
layer, GNU OpenMP), PyTorch's intra-op pool (its own OpenMP), OpenBLAS under NumPy/SciPy,
and OIDN's TBB arena, which also pins its threads to cores. With
``snakemake --cores 2`` running two one-thread jobs, each such pool adds threads that compete for
the same two cores, and OpenMP threads that spin while they wait for work burn CPU that the
other job needed. :func:`limit_threads`, called by every workflow script before it imports
anything heavy, sets each library's thread count to the job's ``threads`` and makes waiting
threads sleep instead of spin:

* ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``, ``GOTO_NUM_THREADS``,
  ``VECLIB_MAXIMUM_THREADS``, ``NUMEXPR_NUM_THREADS`` (what Snakemake itself sets for ``shell:``
  rules, but not for ``script:`` rules), ``NUMBA_NUM_THREADS`` and ``OIDN_NUM_THREADS``: the job's
  ``threads``; these are read when each library loads, so they must be set before its import;
* ``OMP_WAIT_POLICY=PASSIVE`` (GNU OpenMP's threads sleep at once instead of spinning about
  0.3 ms per wait, for numba and PyTorch alike) and ``OIDN_SET_AFFINITY=0`` (two jobs of
  one thread each would otherwise both pin OIDN to core 0);
* for a library already imported when it is called (numba, torch), its runtime setter as well.

Dr.Jit's pool (Mitsuba's renders) is sized by :func:`mcbench.render.variants.set_threads` in the
render steps, which receive the same ``threads``. No thread count changes a number the study
reports: every parallel loop here splits work by pixels or bands whose arithmetic does not depend
on the split, and the method jobs already ran numba and torch on one thread.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["THREAD_COUNT_VARIABLES", "WAIT_VARIABLES", "thread_environment", "limit_threads",
           "os_thread_count", "thread_report"]

#: Environment variables that size a library's thread pool when it loads.
THREAD_COUNT_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS",
                          "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS", "OIDN_NUM_THREADS")
#: ... and those that make idle threads sleep and leave cores unpinned.
WAIT_VARIABLES = {"OMP_WAIT_POLICY": "PASSIVE", "OIDN_SET_AFFINITY": "0"}

_given: int | None = None   # the count of the last limit_threads call in this process


def thread_environment(threads: int) -> dict[str, str]:
    """The environment variables (name -> value) that hold every pool of a job to ``threads``."""
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return {**{name: str(threads) for name in THREAD_COUNT_VARIABLES}, **WAIT_VARIABLES}


def limit_threads(threads) -> int:
    """Hold this process's thread pools to ``threads`` (see the module docstring); returns it.

    Sets the environment (for libraries loaded later and for child processes), then the runtime
    thread count of numba and torch if they are already imported (with numba imported, its
    ``NUMBA_NUM_THREADS`` is left as it is: numba stops on a changed value once its pool runs)."""
    global _given
    threads = int(threads)
    environment = thread_environment(threads)
    numba = sys.modules.get("numba")
    if numba is not None:
        # numba refuses a changed NUMBA_NUM_THREADS once its pool has started (it re-reads the
        # environment before each compilation): leave the variable, narrow the pool at run time
        environment.pop("NUMBA_NUM_THREADS")
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    os.environ.update(environment)
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(threads)
    _given = threads
    return threads


def os_thread_count() -> int:
    """Threads of this process now (Linux ``/proc/self/status``; 0 where it is not available)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Threads:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def thread_report() -> str:
    """One line for a job's log: the threads it was given (by :func:`limit_threads`), the process's
    OS threads now, and the pool size of numba and torch when they are loaded."""
    parts = [f"threads given {'unset' if _given is None else _given}", f"OS threads {os_thread_count()}"]
    numba = sys.modules.get("numba")
    if numba is not None:
        parts.append(f"numba {numba.get_num_threads()}")
    torch = sys.modules.get("torch")
    if torch is not None:
        parts.append(f"torch {torch.get_num_threads()}")
    return "mcbench threads: " + ", ".join(parts)
