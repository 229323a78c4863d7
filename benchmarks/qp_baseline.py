"""The QP baseline of Sec. 5.2.2 (one quadprog solve per pixel-channel): quadprog called directly
against the same solves through qpsolvers, on random problems of a 128x128 image's size.

    python benchmarks/qp_baseline.py [--problems 49152] [--bases 2 4 8] [--repeats 2]

Prints per ensemble size the best CPU seconds of each path, their ratio (direct / qpsolvers),
whether the weights are equal bit for bit, and the machine's load averages.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.combine.simplex_solvers.qp import qp_simplex_weights, qp_simplex_weights_through_qpsolvers  # noqa: E402


def _best_cpu(function, *args, repeats: int):
    best, result = float("inf"), None
    for _ in range(repeats):
        start = time.process_time()
        result = function(*args)
        best = min(best, time.process_time() - start)
    return best, result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", type=int, default=128 * 128 * 3)
    parser.add_argument("--bases", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    warm = rng.lognormal(size=(64, 2, 2)), rng.lognormal(size=(64, 2))
    qp_simplex_weights(*warm), qp_simplex_weights_through_qpsolvers(*warm)
    print(f"load averages at the start: {os.getloadavg()}")
    print("| bases | qpsolvers CPU s | direct CPU s | direct / qpsolvers | equal |")
    print("|---:|---:|---:|---:|---|")
    for n in args.bases:
        points = rng.lognormal(size=(args.problems, n, 2))
        targets = points.mean(axis=1) + 0.3 * rng.standard_normal((args.problems, 2)) * points.std(axis=1)
        library, expected = _best_cpu(qp_simplex_weights_through_qpsolvers, points, targets, repeats=args.repeats)
        direct, got = _best_cpu(qp_simplex_weights, points, targets, repeats=args.repeats)
        print(f"| {n} | {library:.2f} | {direct:.2f} | {direct / library:.2f} | {np.array_equal(got, expected)} |")
    print(f"load averages at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
