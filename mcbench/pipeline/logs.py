"""Running a workflow step with its output captured in the rule's log file.

stdout and stderr (file descriptors 1 and 2, so C++ libraries' messages too) go to the log;
if the step fails, the one-line error, which names the offending file or config key, is also
printed to the terminal Snakemake runs in, so the user sees why the run stopped.
"""

from __future__ import annotations

import os
import sys
import traceback
from pathlib import Path

from mcbench.pipeline.threads import thread_report


def run_logged(log_path: str | None, step, *args, **kwargs):
    """Call ``step(*args, **kwargs)`` with fds 1 and 2 redirected to ``log_path``; the log ends with
    the job's thread use (:func:`mcbench.pipeline.threads.thread_report`)."""
    if not log_path:
        return step(*args, **kwargs)
    Path(log_path).parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    saved_err = os.dup(2)
    saved_out = os.dup(1)
    with open(log_path, "w") as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            result = step(*args, **kwargs)
            print(thread_report(), flush=True)
            return result
        except BaseException as exc:
            traceback.print_exc()
            sys.stderr.flush()
            os.write(saved_err, f"ERROR: {exc}\n(full traceback in {log_path})\n".encode())
            raise SystemExit(1) from None
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved_out, 1)
            os.dup2(saved_err, 2)
            os.close(saved_out)
            os.close(saved_err)
