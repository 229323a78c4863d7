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
    the job's thread use (:func:`mcbench.pipeline.threads.thread_report`).

    On failure the error line goes to the terminal first, then the traceback to the log. When the
    log itself cannot be written (a full disk), the terminal line says so, naming the log and the
    reason, and the step still fails: nothing is lost but the traceback."""
    if not log_path:
        return step(*args, **kwargs)
    Path(log_path).parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    saved_err = os.dup(2)
    saved_out = os.dup(1)
    log = open(log_path, "w")
    try:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            result = step(*args, **kwargs)
            print(thread_report(), flush=True)
            return result
        except BaseException as exc:
            unwritable = _write_error(log)
            if unwritable is None:
                try:
                    for stream in (sys.stdout, sys.stderr):
                        stream.flush()
                    traceback.print_exc(file=log)
                    log.flush()
                except OSError as error:
                    unwritable = error.strerror or str(error)
            where = (f"{log_path}: cannot write the log ({unwritable})" if unwritable
                     else f"(full traceback in {log_path})")
            os.write(saved_err, f"ERROR: {exc}\n{where}\n".encode())
            raise SystemExit(1) from None
        finally:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except OSError:
                    pass
            os.dup2(saved_out, 1)
            os.dup2(saved_err, 2)
            os.close(saved_out)
            os.close(saved_err)
    finally:
        try:
            log.close()
        except OSError:
            pass                           # reported above when it mattered: the step failed


def _write_error(log) -> str | None:
    """Whether the open ``log`` still takes a write: None, or the reason it does not."""
    try:
        log.write("\n")
        log.flush()
    except OSError as error:
        return error.strerror or str(error)
    return None
