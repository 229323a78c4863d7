"""Progress lines of long jobs: reference chunks, training, NFOR and RDFC on large images.

Lines go to stdout, flushed at once: inside a workflow step, :func:`mcbench.pipeline.logs.run_logged`
sends stdout to the job's log file, so ``tail -f results/logs/...`` shows a running job's
progress. Printing never changes what a job computes.
"""

from __future__ import annotations

import time
from typing import Callable

__all__ = ["LARGE_IMAGE_PIXELS", "eta_seconds", "progress_line", "StageLog"]

# Denoisers report their stages only above this many pixels (256 x 256), so the small images
# of tests and the smoke study stay quiet.
LARGE_IMAGE_PIXELS = 256 * 256


def eta_seconds(elapsed: float, done: float, total: float) -> float:
    """Seconds left if the remaining ``total - done`` units go at the rate so far
    (``elapsed`` seconds for ``done`` units); 0 when nothing is left, inf before any unit."""
    if done >= total:
        return 0.0
    if done <= 0:
        return float("inf")
    return elapsed * (total - done) / done


def progress_line(label: str, what: str, elapsed: float, eta: float) -> str:
    """``'<label>: <what>, elapsed 1.2 s, eta 3.4 s'`` (seconds, one decimal; an infinite
    ``eta`` reads ``unknown``)."""
    eta_text = f"{eta:.1f} s" if eta != float("inf") else "unknown"
    return f"{label}: {what}, elapsed {elapsed:.1f} s, eta {eta_text}"


class StageLog:
    """Prints ``'<label>: <stage> done, elapsed 12.3 s'`` for each stage of a job when enabled.

    ``StageLog.for_image(label, height, width)`` is enabled only for images of more than
    :data:`LARGE_IMAGE_PIXELS` pixels. ``clock`` (seconds) is ``time.perf_counter``.
    """

    def __init__(self, label: str, *, enabled: bool = True, clock: Callable[[], float] = time.perf_counter):
        self.label = label
        self.enabled = enabled
        self.clock = clock
        self.start = clock()

    @classmethod
    def for_image(cls, label: str, height: int, width: int, **kwargs) -> "StageLog":
        return cls(f"{label} ({width}x{height})", enabled=height * width > LARGE_IMAGE_PIXELS, **kwargs)

    def __call__(self, stage: str) -> None:
        if self.enabled:
            print(f"{self.label}: {stage} done, elapsed {self.clock() - self.start:.1f} s", flush=True)
