"""Timing benchmark of RDFC (methods/rdfc.py) on synthetic buffers, against the baseline
implementation with the NumPy NL-means (``benchmarks/baseline.py``) in the same run. A script, not a test:

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_rdfc.py [--sizes 128 256 512] [--repeats 1] [--no-baseline]

Synthetic data: smooth colour with a piecewise-constant albedo (two regions), Gaussian
half-buffer noise of known variance, noise-free normal/position/visibility. Every timing is taken after a
warm-up call (numba compilation) on a 32^2 image. Reported per size: total seconds per image
(full + both half buffers, i.e. one ``denoise`` call), the stages (feature prefiltering; one
three candidate filters, r = 10; selection and blend), and the ratio of
the total to the 128^2 total next to the pixel-count ratio; then (unless ``--no-baseline``) the
wall and CPU seconds of the current and the baseline's ``denoise``, the speed-ups and the relMSE of
the current outputs against the baseline's. The DAG runs methods at one thread: NUMBA_NUM_THREADS=1.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from mcbench.io.buffers import RenderBuffers  # noqa: E402
from methods import rdfc  # noqa: E402
from baseline import load_baseline, print_comparison, time_denoisers  # noqa: E402
from timing import timed  # noqa: E402


def synthetic(size: int, seed: int = 0, half_variance: float = 0.02) -> RenderBuffers:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size] / size
    region = (np.sin(9 * xx) * np.cos(7 * yy)) > 0
    truth = np.stack([0.5 + 0.3 * xx, 0.3 + 0.4 * yy, 0.4 + 0.2 * xx * yy], -1)
    albedo = np.where(region[..., None], [0.8, 0.3, 0.5], [0.2, 0.6, 0.1])
    truth = truth * albedo
    layers = {}
    for s in ("_a", "_b"):
        layers["color" + s] = (truth + rng.normal(size=truth.shape) * np.sqrt(half_variance)).astype(np.float32)
        layers["variance" + s] = np.full(truth.shape, half_variance, np.float32)
    layers["color"] = (layers["color_a"] + layers["color_b"]) / 2
    layers["variance"] = layers["variance_a"] / 2
    normal = np.zeros(truth.shape, np.float32)
    normal[..., 2] = 1
    position = np.stack([xx, yy, np.ones_like(xx)], -1).astype(np.float32)
    for s in ("", "_a", "_b"):
        layers["albedo" + s] = albedo.astype(np.float32)
        layers["normal" + s] = normal
        layers["depth" + s] = np.ones((size, size), np.float32)
        layers["position" + s] = position
        layers["visibility" + s] = np.ones((size, size), np.float32)
        for name in ("albedo", "normal", "position"):
            layers[f"{name}_variance{s}"] = np.zeros(truth.shape, np.float32)
        layers["visibility_variance" + s] = np.zeros((size, size), np.float32)
    return RenderBuffers(layers=layers, spp=8)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--no-baseline", action="store_true", help="time the current implementation only")
    args = parser.parse_args(argv)

    rdfc.denoise(synthetic(32))   # warm-up (numba compile / cache load)
    denoisers = {"new": rdfc.denoise}
    if not args.no_baseline:
        denoisers["baseline"] = load_baseline("methods/rdfc.py").denoise
        denoisers["baseline"](synthetic(32))
    base = None
    print(f"{'size':>6} {'total_s':>8} {'prefilt_s':>9} {'kernel_s':>8} {'select_s':>8} "
          f"{'x128_time':>9} {'x128_pixels':>11}")
    for size in args.sizes:
        buffers = synthetic(size)
        t_total, _ = timed(lambda: rdfc.denoise(buffers), args.repeats)
        features, max_pos = rdfc.authors_features(buffers)
        t_pre, feats = timed(lambda: rdfc.prefilter_features(features), args.repeats)
        a = np.asarray(buffers.color_a, np.float64)
        b = np.asarray(buffers.color_b, np.float64)
        y = (a + b) / 2
        v = rdfc.scaled_sample_variance(a, b, np.asarray(buffers.variance, np.float64))
        t_kernel, cands = timed(lambda: rdfc.candidates(a, b, y, v, feats, max_pos, radius=rdfc.WINDOW_RADIUS),
                                args.repeats)
        t_sel, _ = timed(lambda: rdfc.select_and_blend(*cands, y, v), args.repeats)
        if base is None:
            base = (t_total, size * size)
        print(f"{size:>4}^2 {t_total:8.3f} {t_pre:9.3f} {t_kernel:8.3f} {t_sel:8.3f} "
              f"{t_total / base[0]:9.2f} {size * size / base[1]:11.2f}", flush=True)
    if len(denoisers) > 1:
        for size in args.sizes:
            print_comparison(size, time_denoisers(denoisers, synthetic(size), args.repeats))


if __name__ == "__main__":
    main()
