"""Time NFOR (methods/nfor.py) per image at 128², 256², 512² on synthetic inputs.

Inputs: the piecewise-smooth synthetic scene of tests/test_nfor.py with Gaussian noise
(sigma 0.1 per half buffer). A 32² run first compiles / loads the numba kernels, so the
timings exclude JIT. Prints seconds per image, the ratio to 128², and the ratio expected
from the pixel count (the algorithm is linear in pixels for fixed window sizes).

    .venv/bin/python benchmarks/bench_nfor.py [--sizes 128 256 512] [--repeats 1]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_nfor import make_buffers, synthetic_scene  # noqa: E402

from methods import nfor  # noqa: E402
from timing import timed  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512])
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()

    nfor.denoise(make_buffers(*synthetic_scene(32, 32), sigma_half=0.1))  # numba warm-up
    base = None
    print(f"{'size':>6} {'pixels':>8} {'seconds':>9} {'ratio':>7} {'pixel ratio':>11}")
    for size in args.sizes:
        buffers = make_buffers(*synthetic_scene(size, size), sigma_half=0.1)
        best, _ = timed(lambda: nfor.denoise(buffers), args.repeats)
        if base is None:
            base = (best, size * size)
        print(f"{size:>6} {size * size:>8} {best:>9.2f} {best / base[0]:>7.2f} "
              f"{size * size / base[1]:>11.1f}", flush=True)


if __name__ == "__main__":
    main()
