"""Warm worker processes for the study's case jobs.

Each test case is one job (mcbench.pipeline.cases), and after an edit of the config most of them
make little (one method, one metric). A process per
job would pay a Python start, Snakemake's script preamble and the imports (numpy, numba's cached
kernels, torch for the networks: 0.5--2 s), more than most methods' compute at 128 x 128 and
more than a rerun of one method costs. These rules therefore say ``run:`` and hand their step to
:func:`run_step`: a pool of worker processes that live as long as the Snakemake process, each
importing once and running one step at a time (its caches, :mod:`mcbench.io.file_cache`, keep
the case's render and reference decoded between jobs). Snakemake still plans, orders, checks and records every job (params, inputs, code,
mtimes); the pool only changes where a job's Python runs.

* Workers are started with ``forkserver`` (never ``fork`` from Snakemake's threaded process), with
  every library's thread pool held to ``threads`` (:func:`mcbench.pipeline.threads.limit_threads`
  before any import), freed memory kept for reuse (:func:`mcbench.pipeline.freed_memory.keep_freed_memory`:
  a network's inference no longer page-faults) and the checkout's folders on ``sys.path`` (``methods/``, ``scenes/``).
* A step runs under :func:`mcbench.pipeline.logs.run_logged` in the worker, so its stdout and
  stderr go to the job's log file alone; its failure comes back as :class:`mcbench.BenchError`
  naming the step and the log, and Snakemake fails the job as it would a script's.
* A worker that dies (a crash in a native library) breaks the pool: the job fails naming it and
  the next job starts a fresh pool.
* The pool needs the ``run:`` rules to execute in Snakemake's process (``force-use-threads``, set
  by the workflow; otherwise Snakemake would start a whole Snakemake process for each such job).
  On a cluster each job is a Snakemake process of its own and its pool has one worker.
"""

from __future__ import annotations

import atexit
import concurrent.futures
import importlib
import multiprocessing
import os
import sys
import threading

from mcbench import BenchError

__all__ = ["run_step", "shutdown_pool"]

_lock = threading.Lock()
_pool: concurrent.futures.ProcessPoolExecutor | None = None
_pool_key: tuple | None = None


def _init_worker(threads: int, environment: dict[str, str], paths: list[str]) -> None:
    """Worker set-up: thread limits before any heavy import, the job environment, the checkout's paths."""
    from mcbench.pipeline.freed_memory import keep_freed_memory
    from mcbench.pipeline.threads import limit_threads

    limit_threads(threads)
    keep_freed_memory()
    os.environ.update(environment)
    for path in reversed(paths):
        if path not in sys.path:
            sys.path.insert(0, path)


def _call_step(step: str, log_path: str | None, args: tuple, kwargs: dict) -> str | None:
    """Run ``module:function`` ``step`` in this worker under the job's log; the error line, or None."""
    from mcbench.pipeline.logs import run_logged

    module_name, _, function_name = step.partition(":")
    try:
        function = getattr(importlib.import_module(module_name), function_name)
        run_logged(log_path, function, *args, **kwargs)
    except SystemExit:                      # run_logged: the error is in the log and on stderr
        return f"{step} failed (traceback in {log_path})"
    except BaseException as exc:            # without a log (log_path None), or an import error
        return f"{step} failed: {exc}"
    return None


def _get_pool(workers: int, threads: int, environment: dict[str, str],
              paths: list[str]) -> concurrent.futures.ProcessPoolExecutor:
    global _pool, _pool_key
    key = (workers, threads, tuple(sorted(environment.items())), tuple(paths))
    with _lock:
        if _pool is None or _pool_key != key:
            if _pool is not None:
                _pool.shutdown(wait=True)
            context = multiprocessing.get_context("forkserver")
            _pool = concurrent.futures.ProcessPoolExecutor(
                max_workers=workers, mp_context=context, initializer=_init_worker,
                initargs=(threads, dict(environment), list(paths)))
            _pool_key = key
        return _pool


def run_step(step: str, *args, log_path: str | None, workers: int, threads: int = 1,
             environment: dict[str, str] | None = None, paths: list[str] = (), **kwargs) -> None:
    """Run ``step`` (``"package.module:function"``) with ``args``/``kwargs`` in a warm worker and wait.

    ``workers``: the pool's size (the cores Snakemake may use at once; every job using the pool
    has ``threads`` 1, so no more than ``workers`` steps run at a time). ``environment``: variables
    set in each worker; ``paths``: folders put first on its
    ``sys.path``. Arguments must pickle. Raises :class:`mcbench.BenchError` when the step fails
    (naming it and ``log_path``) or its worker dies.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    pool = _get_pool(workers, threads, dict(environment or {}), list(paths))
    try:
        error = pool.submit(_call_step, step, log_path, args, kwargs).result()
    except concurrent.futures.process.BrokenProcessPool as exc:
        with _lock:
            global _pool
            if _pool is pool:
                _pool = None
        raise BenchError(f"{step}: its worker process died ({exc}); see {log_path}") from None
    if error is not None:
        raise BenchError(error)


def shutdown_pool() -> None:
    """Stop the workers and the forkserver they were forked from, waiting for both.

    Called at exit: the forkserver reaps the workers and is reaped here, so their CPU time counts
    in this process's children (``time``, ``getrusage(RUSAGE_CHILDREN)``, Snakemake's benchmark
    of a job that runs Snakemake) instead of vanishing with an orphaned forkserver."""
    global _pool
    with _lock:
        if _pool is not None:
            _pool.shutdown(wait=True)
            _pool = None
        from multiprocessing import forkserver

        server = getattr(forkserver, "_forkserver", None)
        if server is not None and getattr(server, "_forkserver_pid", None) is not None:
            try:
                server._stop()             # closes its pipe and waits for it (no public API does)
            except OSError:
                pass                       # its socket already removed: it is going or gone


atexit.register(shutdown_pool)
