"""Fig. 6 of Zheng et al. 2021 (Sec. 5.2.2): per-problem solve time of the ensemble's weight
solvers -- iterative (Sec. 4.1), exact (hull projection) and a general-purpose QP
(``solver="qp"``: qpsolvers with quadprog, one call per problem) -- for N = 2..8 base
denoisers, and each one's objective gap to the exact optimum; then both fast solvers on
image-sized problem sets (``--image-side``) with the iterative solver's
fraction of problems stopped at the 1024-iteration limit, for each of its starts
(``start=`` random: the paper's; vertex; pair). A script, not a timed test:

    python benchmarks/bench_solvers.py [--n 2 3 4 5 6 7 8] [--pixels 1024] [--threads 1]
                                       [--channels rgb] [--repeats 3] [--quick]

Problems (one per pixel-channel, or per pixel with ``--channels single``):
* ``random``: x^A, x^B, y_i^A, y_i^B standard normals (b mostly outside the hull);
* ``realistic``: ``bench_ensemble.synthetic`` (smooth radiance, heteroscedastic noisy halves
  with 0.1 % fireflies, per-denoiser smooth biases), a square crop of about ``--pixels``
  pixels.

Times are the best of ``--repeats`` runs after a warm-up (numba compilation), divided by the
number of problems, in microseconds; numba runs on ``--threads`` threads (default 1, so every
solver uses one core like the QP loop). ``speedup`` is t_qp / t_solver, both measured in the
same run. The gap is L(w) - L(w_exact) per problem (Eq. 13; channel-summed for ``single``)
divided by scale^2, scale = max(|x^A|, |x^B|, |y_i^A|, |y_i^B|) of the problem; median and
99th percentile. ``load`` is os.getloadavg()'s 1-minute value when the row was measured (the
machine is shared: compare ratios, not absolute times, across loads). The paper: the
iterative solver about 10x faster than the general-purpose solver (FBstab) at every N.

Why problems reach the iteration limit: the stopping rule asks that no weight moves by more
than 1e-9 over a cycle, and the exact line steps of Eq. 31 (towards one vertex at a time, alpha
in [0, 1], the paper's default; also away from it with ``away_steps=True``, not measured here)
converge only linearly, slowly on ill-conditioned problems: when b lies inside the hull of the
points (the minimisers form an (N - 3)-dimensional set for N >= 4, every step zig-zags along
it), the optimum lies on a long thin edge, or (without away steps) a denoiser that should get
weight 0 loses it only as the others gain. The weights then still creep near the optimum
(on the random problems of tests/combine/test_ensemble.py after at most 1024 iterations: all
within 2e-3 scale^2 and 67 % within 1e-6 without away steps, 99.6 % within 1e-6 with them). The "pair" start (the best two-denoiser ensemble
by Eq. 29) is the optimum outright when the optimal support has two points, which removes those
cases; the inside-hull ones remain.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_ensemble import synthetic  # noqa: E402
from mcbench.combine.ensemble_weights import CHANNELS, solve_weights  # noqa: E402
from mcbench.combine.simplex_solvers.iterative import STARTS  # noqa: E402
from mcbench.combine.simplex_solvers.problem import objective  # noqa: E402
from mcbench.combine.simplex_solvers.qp import QP_BACKEND  # noqa: E402
from timing import timed  # noqa: E402


def random_problems(pixels: int, n: int, seed: int = 0):
    """color_a, color_b (1, P, 3), denoised_a, denoised_b (N, 1, P, 3): standard normals."""
    rng = np.random.default_rng(seed)
    xa, xb = rng.normal(size=(2, 1, pixels, 3))
    ya, yb = rng.normal(size=(2, n, 1, pixels, 3))
    return xa, xb, ya, yb


def realistic_problems(pixels: int, n: int, seed: int = 0):
    """bench_ensemble.synthetic on a square of side ceil(sqrt(pixels))."""
    side = max(int(np.ceil(np.sqrt(pixels))), 2)
    xa, xb, _, ya, yb, _, _ = synthetic(side, n, seed)
    return xa, xb, ya, yb


PROBLEMS = {"random": random_problems, "realistic": realistic_problems}
SOLVER_ORDER = ("iterative", "exact", "qp")


def channel_objective(weights, xa, xb, ya, yb, channels):
    value = objective(weights, xa, xb, ya, yb)
    return value.sum(axis=-1) if channels == "single" else value


def problem_scale2(xa, xb, ya, yb, channels):
    s = np.maximum.reduce([np.abs(xa), np.abs(xb), np.abs(ya).max(0), np.abs(yb).max(0),
                           np.full(xa.shape, 1e-30)])
    return (s.max(axis=-1) if channels == "single" else s) ** 2


def measure(kind: str, n: int, pixels: int, channels: str, repeats: int) -> dict:
    xa, xb, ya, yb = PROBLEMS[kind](pixels, n)
    count = xa.size // (xa.shape[-1] if channels == "single" else 1)
    row = dict(kind=kind, N=n, problems=count)
    weights = {}
    for solver in SOLVER_ORDER:
        reps = 1 if solver == "qp" else repeats   # the slow loop: its noise is averaged
        seconds, weights[solver] = timed(
            lambda: solve_weights(xa, xb, ya, yb, solver=solver, channels=channels), reps)
        row[f"{solver}_us"] = seconds / count * 1e6
    optimum = channel_objective(weights["exact"], xa, xb, ya, yb, channels)
    scale2 = problem_scale2(xa, xb, ya, yb, channels)
    for solver in SOLVER_ORDER:
        gap = (channel_objective(weights[solver], xa, xb, ya, yb, channels) - optimum) / scale2
        row[f"{solver}_gap_med"] = float(np.median(gap))
        row[f"{solver}_gap_p99"] = float(np.percentile(gap, 99))
        row[f"{solver}_speedup"] = row["qp_us"] / row[f"{solver}_us"]
    row["load"] = os.getloadavg()[0]
    return row


COLS = [("kind", "{:>9}"), ("N", "{:>2}"), ("problems", "{:>8d}"),
        ("iterative_us", "{:12.3f}"), ("exact_us", "{:8.3f}"), ("qp_us", "{:8.2f}"),
        ("iterative_speedup", "{:17.1f}"), ("exact_speedup", "{:13.1f}"),
        ("iterative_gap_med", "{:17.1e}"), ("iterative_gap_p99", "{:17.1e}"),
        ("exact_gap_p99", "{:13.1e}"),
        ("qp_gap_med", "{:10.1e}"), ("qp_gap_p99", "{:10.1e}"), ("load", "{:5.2f}")]


def print_row(row, header=False):
    widths = [max(len(name), 9) for name, _ in COLS]
    if header:
        print(" ".join(f"{name:>{w}}" for (name, _), w in zip(COLS, widths)), flush=True)
    print(" ".join(f"{fmt.format(row[name]).strip():>{w}}" for (name, fmt), w in zip(COLS, widths)),
          flush=True)


def image_sized(kind: str, n: int, side: int) -> list[dict]:
    """Both solvers on the problems of a side x side image (all numba threads, like combine):
    seconds, the iterative solver's gap to the exact optimum ((L - L_exact) / scale^2: median,
    99th percentile, max), its mean iteration count and the fraction of problems stopped at the
    1024-iteration limit, for each start of the iterative solver (``STARTS``; "random" is the
    paper's)."""
    xa, xb, ya, yb = PROBLEMS[kind](side * side, n)
    seconds, exact = timed(lambda: solve_weights(xa, xb, ya, yb, solver="exact"), 1)
    optimum = objective(exact, xa, xb, ya, yb)
    scale2 = problem_scale2(xa, xb, ya, yb, "rgb")
    rows = [dict(kind=kind, N=n, solver="exact", start="-", seconds=seconds, gap_med=0.0,
                 gap_p99=0.0, gap_max=0.0, iterations=float("nan"), at_limit=float("nan"))]
    for start in STARTS:
        seconds, (w, iterations) = timed(lambda: solve_weights(
            xa, xb, ya, yb, solver="iterative", start=start, return_info=True), 1)
        gap = (objective(w, xa, xb, ya, yb) - optimum) / scale2
        rows.append(dict(kind=kind, N=n, solver="iterative", start=start, seconds=seconds,
                         gap_med=float(np.median(gap)), gap_p99=float(np.percentile(gap, 99)),
                         gap_max=float(gap.max()), iterations=float(iterations.mean()),
                         at_limit=float((iterations >= 1024).mean())))
    return rows


def print_image_sized(side: int, ns, kinds):
    import numba
    print(f"\nimage-sized problems: {side}^2 pixels x 3 channels, {numba.get_num_threads()} numba "
          f"threads; gap = (L - L_exact) / scale^2; at_limit = fraction stopped at 1024 iterations")
    print(f"{'kind':>9} {'N':>2} {'solver':>9} {'start':>6} {'seconds':>8} {'gap_med':>9} "
          f"{'gap_p99':>9} {'gap_max':>9} {'iters':>6} {'at_limit':>8} {'load':>5}")
    for kind in kinds:
        for n in ns:
            for r in image_sized(kind, n, side):
                print(f"{r['kind']:>9} {r['N']:>2} {r['solver']:>9} {r['start']:>6} "
                      f"{r['seconds']:8.2f} {r['gap_med']:9.1e} {r['gap_p99']:9.1e} "
                      f"{r['gap_max']:9.1e} {r['iterations']:6.1f} {r['at_limit']:8.4f} "
                      f"{os.getloadavg()[0]:5.2f}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=list(range(2, 9)))
    ap.add_argument("--pixels", type=int, default=1024,
                    help="pixels per problem set (x3 channels for --channels rgb)")
    ap.add_argument("--kinds", nargs="+", default=list(PROBLEMS), choices=list(PROBLEMS))
    ap.add_argument("--channels", default="rgb", choices=list(CHANNELS))
    ap.add_argument("--threads", type=int, default=1, help="numba threads")
    ap.add_argument("--repeats", type=int, default=3, help="best of R timings (not qp)")
    ap.add_argument("--quick", action="store_true", help="few pixels, N = 2 4 8")
    ap.add_argument("--image-side", type=int, default=1024,
                    help="side of the image-sized problems of both solvers and every start "
                         "(0: skip; all numba threads)")
    args = ap.parse_args(argv)
    import numba
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    pixels, ns = (64, [2, 4, 8]) if args.quick else (args.pixels, args.n)
    # warm-up: compile every kernel once
    xa, xb, ya, yb = random_problems(4, 3)
    for solver in SOLVER_ORDER:
        solve_weights(xa, xb, ya, yb, solver=solver, channels=args.channels)
    load = os.getloadavg()
    print(f"numba threads: {numba.get_num_threads()}; channels: {args.channels}; QP backend: "
          f"{QP_BACKEND}; load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
          f"({os.cpu_count()} CPUs)\n*_us: microseconds per problem; *_speedup: t_qp / t_solver "
          f"(same run); gaps: (L(w) - L(w_exact)) / scale^2 per problem, median and p99",
          flush=True)
    rows = []
    for kind in args.kinds:
        for n in ns:
            rows.append(measure(kind, n, pixels, args.channels, args.repeats))
            print_row(rows[-1], header=len(rows) == 1)
    for kind in args.kinds:
        speedups = {solver: [r[f"{solver}_speedup"] for r in rows if r["kind"] == kind]
                    for solver in ("iterative", "exact")}
        print(f"{kind}: speed-up over the QP solver, iterative "
              f"{min(speedups['iterative']):.1f}-{max(speedups['iterative']):.1f}x, exact "
              f"{min(speedups['exact']):.1f}-{max(speedups['exact']):.1f}x "
              f"(paper: iterative ~10x)", flush=True)
    if args.image_side:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        print_image_sized(64 if args.quick else args.image_side, [2, 4, 8], args.kinds)
    return rows


if __name__ == "__main__":
    main()
