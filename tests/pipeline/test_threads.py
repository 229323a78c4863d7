"""mcbench.pipeline.threads: a job's thread pools held to the threads Snakemake gave it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from mcbench.pipeline.threads import THREAD_COUNT_VARIABLES, WAIT_VARIABLES, limit_threads, thread_environment

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_environment_sizes_every_pool_and_makes_waiting_threads_sleep():
    env = thread_environment(3)
    assert {name: env[name] for name in THREAD_COUNT_VARIABLES} == dict.fromkeys(THREAD_COUNT_VARIABLES, "3")
    assert env["OMP_WAIT_POLICY"] == "PASSIVE" and env["OIDN_SET_AFFINITY"] == "0"
    # the pools of this project's libraries: numba, PyTorch/OpenMP, OpenBLAS, OIDN
    assert {"NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OIDN_NUM_THREADS"} <= set(env)
    assert set(WAIT_VARIABLES) <= set(env)


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2"])
def test_a_thread_count_that_is_not_a_positive_integer_is_refused(threads):
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        thread_environment(threads)


def test_a_fresh_job_process_gets_one_thread_per_pool():
    """In a new process, as a workflow script calls it (before any heavy import): numba's and
    torch's pools have exactly the job's threads, on this 2-core machine and on any larger one."""
    code = ("from mcbench.pipeline.threads import limit_threads, thread_report\n"
            "limit_threads(1)\n"
            "import numba, torch\n"
            "print(numba.config.NUMBA_NUM_THREADS, numba.get_num_threads(), torch.get_num_threads())\n"
            "print(thread_report())\n")
    env = {k: v for k, v in os.environ.items() if k not in THREAD_COUNT_VARIABLES}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env,
                         check=True).stdout.splitlines()
    assert out[0] == "1 1 1", out
    assert out[1].startswith("mcbench threads: threads given 1, OS threads ")


def test_with_numba_running_the_pool_is_narrowed_without_touching_its_variable(monkeypatch):
    """numba refuses a changed NUMBA_NUM_THREADS once its pool runs: limit_threads leaves the
    variable and narrows the pool at run time instead (a script run inside a test process)."""
    import numba

    for name in (*THREAD_COUNT_VARIABLES, *WAIT_VARIABLES):
        monkeypatch.delenv(name, raising=False)
    before = numba.get_num_threads()
    try:
        assert limit_threads(1) == 1
        assert numba.get_num_threads() == 1
        assert "NUMBA_NUM_THREADS" not in os.environ and os.environ["OMP_NUM_THREADS"] == "1"
    finally:
        numba.set_num_threads(before)
