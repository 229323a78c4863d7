"""Timing and optimality benchmark of the ensemble weight solvers and the weight filter
(Zheng et al. 2021, Sec. 4.1-4.2) on synthetic inputs. A script, not a timed test:

    python benchmarks/bench_ensemble.py [--sizes 512 1024] [--n 2 4 8] [--quick]

Synthetic data (linear radiance): a smooth truth image mu (H, W, 3); noisy halves
x^h = mu + sqrt(mu) * 0.3 * eps (heteroscedastic, plus 0.1 % fireflies); base outputs
y_i^h = mu + bias_i + 0.02 * eps, with bias_i a smooth per-denoiser field, y_i (full) the
same with less noise. Albedo is mu clipped to [0, 1]; normals are piecewise constant.

Every timing is taken after a warm-up call (numba compilation) and reported both in
seconds and as a ratio to the exact solver and to a NumPy reference op measured in the same
run (the Eq. 35 combination sum_i w_i y_i with np.einsum). The optimality gap of the
iterative solver is L(w_iter) - L(w_exact) per pixel-channel (Eq. 13), also divided by
scale^2 with scale = max(|x^A|, |x^B|, |y_i^A|, |y_i^B|) at that pixel-channel.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from methods import ensemble as E  # noqa: E402
from timing import timed  # noqa: E402


def synthetic(size: int, n: int, seed: int = 0):
    """Returns color_a, color_b (H, W, 3), y_full, y_a, y_b (N, H, W, 3), albedo, normal."""
    rng = np.random.default_rng(seed)
    H = W = size
    yy, xx = np.mgrid[0:H, 0:W] / size
    mu = np.stack([0.6 + 0.5 * np.sin(6 * xx) * np.cos(4 * yy),
                   0.4 + 0.3 * np.cos(5 * (xx + yy)),
                   0.3 + 0.25 * np.sin(9 * xx * yy)], -1) * 2.0
    mu = np.maximum(mu, 0.01)

    def noisy():
        x = mu + np.sqrt(mu) * 0.3 * rng.standard_normal(mu.shape)
        fire = rng.random((H, W)) < 1e-3
        x[fire] += rng.uniform(10, 100, (int(fire.sum()), 1))
        return x

    xa, xb = noisy(), noisy()
    ys = {"full": [], "a": [], "b": []}
    for i in range(n):
        fx, fy, ph = rng.uniform(1, 6), rng.uniform(1, 6), rng.uniform(0, 6.3)
        bias = (0.05 * (i + 1) / n) * np.sin(fx * xx + ph)[..., None] * np.cos(fy * yy)[..., None]
        bias = bias * rng.uniform(0.5, 1.5, 3)
        for key, sd in (("full", 0.015), ("a", 0.02), ("b", 0.02)):
            ys[key].append(mu + bias + sd * rng.standard_normal(mu.shape))
    albedo = np.clip(mu / mu.max(), 0, 1)
    normal = np.zeros((H, W, 3))
    normal[..., 2] = 1.0
    normal[:, W // 2:] = [0.0, 1.0, 0.0]
    return xa, xb, np.stack(ys["full"]), np.stack(ys["a"]), np.stack(ys["b"]), albedo, normal


def run(sizes, ns, repeats):
    # warm-up: compile every kernel once on a tiny problem
    xa, xb, yf, ya, yb, alb, nrm = synthetic(16, 2)
    for solver in E.SOLVERS:
        w = E.solve_weights(xa, xb, ya, yb, solver=solver)
    E.filter_weights(w, yf, ya, yb, alb, nrm)

    rows = []
    for size in sizes:
        for n in ns:
            xa, xb, yf, ya, yb, alb, nrm = synthetic(size, n)
            t_ref, _ = timed(lambda: np.einsum("nhwc,nhwc->hwc", ya, yb), repeats)
            t_exact, (we, codes) = timed(
                lambda: E.solve_weights(xa, xb, ya, yb, solver="exact", return_info=True),
                repeats)
            t_iter, (wi, iters) = timed(
                lambda: E.solve_weights(xa, xb, ya, yb, solver="iterative", return_info=True),
                repeats)
            t_filt, _ = timed(lambda: E.filter_weights(we, yf, ya, yb, alb, nrm), repeats)
            gap = E.objective(wi, xa, xb, ya, yb) - E.objective(we, xa, xb, ya, yb)
            scale = np.maximum.reduce([np.abs(xa), np.abs(xb), np.abs(ya).max(0),
                                       np.abs(yb).max(0), np.full(xa.shape, 1e-30)])
            rel = gap / scale ** 2
            rows.append(dict(
                size=f"{size}^2", N=n, ref_s=t_ref, exact_s=t_exact, iter_s=t_iter,
                filter_s=t_filt, iter_x_exact=t_iter / t_exact, filter_x_exact=t_filt / t_exact,
                exact_x_ref=t_exact / t_ref, iter_x_ref=t_iter / t_ref,
                filter_x_ref=t_filt / t_ref,
                gap_mean=gap.mean(), gap_max=gap.max(), gap_min=gap.min(),
                rel_mean=rel.mean(), rel_max=rel.max(),
                iters_mean=iters.mean(), hit_limit=(iters >= 1024).mean(),
                nonunique=(codes > 0).mean(), enum=(codes >= 2).mean()))
            print_row(rows[-1], header=len(rows) == 1)
    return rows


COLS = [("size", "{:>6}"), ("N", "{:>2}"), ("ref_s", "{:8.4f}"), ("exact_s", "{:8.3f}"),
        ("iter_s", "{:8.3f}"), ("filter_s", "{:8.3f}"), ("exact_x_ref", "{:8.1f}"),
        ("iter_x_ref", "{:8.1f}"), ("filter_x_ref", "{:8.1f}"), ("iter_x_exact", "{:8.2f}"),
        ("filter_x_exact", "{:8.2f}"), ("gap_mean", "{:9.2e}"), ("gap_max", "{:9.2e}"),
        ("gap_min", "{:9.1e}"), ("rel_mean", "{:9.2e}"), ("rel_max", "{:9.2e}"),
        ("iters_mean", "{:7.1f}"), ("hit_limit", "{:7.4f}"), ("nonunique", "{:7.4f}"),
        ("enum", "{:7.4f}")]


def print_row(row, header=False):
    if header:
        print(" ".join(f"{name:>{max(len(fmt.format(row[name])), len(name))}}"
                       for name, fmt in COLS), flush=True)
    print(" ".join(f"{fmt.format(row[name]):>{len(name)}}" for name, fmt in COLS), flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 4, 8])
    ap.add_argument("--quick", action="store_true", help="small sizes for a smoke run")
    ap.add_argument("--repeats", type=int, default=1, help="best of R timings")
    args = ap.parse_args(argv)
    sizes = [64, 128] if args.quick else args.sizes
    import numba
    print(f"numba threads: {numba.get_num_threads()}; ref = np.einsum sum_i y_i^A y_i^B "
          f"over (N, H, W, 3); *_x_ref / *_x_exact are time ratios; gap = L(iter) - L(exact) "
          f"per pixel-channel, rel = gap / scale^2")
    run(sizes, args.n, args.repeats)


if __name__ == "__main__":
    main()
