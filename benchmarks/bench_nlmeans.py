"""Time the compiled NL-means filter (mcbench.filters.nlmeans.nl_means_filter) against its NumPy
reference path (nl_means_filter_reference) in the same run, for the two settings NFOR and RDFC
use most: the feature prefilter (R = 5, F = 3, one channel guiding one channel) and NFOR's MSE
filter (R = 9, F = 1, a 3-channel guide weighting 6 value channels). Random inputs; CPU seconds
of this process (best of ``--repeats``) after a warm-up call; prints the speed-up and the
largest relative difference of the two results.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_nlmeans.py [--sizes 128 512] [--repeats 1]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.filters.nlmeans import nl_means_filter, nl_means_filter_reference  # noqa: E402

SETTINGS = {"prefilter R5 F3 1ch": (dict(radius=5, patch_radius=3, k=0.5), 1, 1),
            "MSE filter R9 F1 3ch K6": (dict(radius=9, patch_radius=1, k=1.0), 3, 6)}


def cpu_best(function, repeats):
    best, result = float("inf"), None
    for _ in range(max(repeats, 1)):
        start = time.process_time()
        result = function()
        best = min(best, time.process_time() - start)
    return best, result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 512])
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    for size in args.sizes:
        for label, (params, channels, values_channels) in SETTINGS.items():
            guide = rng.random((size, size, channels))
            variance = rng.random((size, size, channels)) * 0.05
            values = rng.random((size, size, values_channels))
            nl_means_filter(values[:16, :16], guide[:16, :16], variance[:16, :16], **params)   # JIT
            t_new, new = cpu_best(lambda: nl_means_filter(values, guide, variance, **params), args.repeats)
            t_ref, ref = cpu_best(lambda: nl_means_filter_reference(values, guide, variance, **params), args.repeats)
            print(f"{size:>4}^2 {label:<24} compiled {t_new:7.3f} s  numpy {t_ref:7.3f} s  "
                  f"speed-up {t_ref / t_new:5.1f}x  max rel diff {np.max(np.abs(new - ref) / np.abs(ref)):.1e}",
                  flush=True)


if __name__ == "__main__":
    main()
