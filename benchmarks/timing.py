"""Best-of-N wall-clock timing shared by the benchmark scripts (machines here are shared and
noisy, so the minimum over repeats is the least disturbed measurement)."""

from __future__ import annotations

import time


def timed(function, repeats: int = 1):
    """Run ``function()`` ``repeats`` times; return (best seconds, the last result)."""
    best, result = float("inf"), None
    for _ in range(max(int(repeats), 1)):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return best, result
