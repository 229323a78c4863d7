"""Time NFOR (methods/nfor.py) per image at 128², 256², 512² on synthetic inputs, against the
baseline implementation with the NumPy NL-means (``benchmarks/baseline.py``) in the same run.

Inputs: the piecewise-smooth synthetic scene of tests/methods/test_nfor.py (two albedo regions, a disk
with another normal and depth) with Gaussian noise of sigma 0.1 per half buffer
(tests/conftest.py's ``build_render_buffers``). A 24² run of each implementation first
compiles / loads the numba kernels, so the timings exclude JIT. Prints per size the wall and
CPU seconds of both, the speed-ups and the relMSE of the current outputs against the baseline's
and against the baseline with the current code's one behaviour change (``baseline_fix``: feature
differences within 1e-9 relative of zero count as 0, see methods/nfor.py). The baseline predates
the Tungsten switches, so this comparison runs the current code with its former settings
(``nfor.PAPER_READING``, ``new``); a second line per size times NFOR's defaults (Tungsten's behaviour,
``tungsten``) against ``nfor.PAPER_READING`` (``ours``) on the same input.
The DAG runs methods at one thread: ``NUMBA_NUM_THREADS=1``.

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_nfor.py [--sizes 128 512] [--repeats 1] [--no-baseline]
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from baseline import load_baseline, print_comparison, time_denoisers  # noqa: E402
from tests.conftest import build_render_buffers  # noqa: E402
from tests.methods.test_nfor import synthetic_scene  # noqa: E402

from methods import nfor  # noqa: E402


SNAP_OLD = "        xrow[3 + f] = features[qy, qx, f] - features[y, x, f]\n"
SNAP_NEW = ("        diff = features[qy, qx, f] - features[y, x, f]\n"
            "        if abs(diff) <= 1e-9 * max(abs(features[qy, qx, f]), abs(features[y, x, f])):\n"
            "            diff = 0.0\n"
            "        xrow[3 + f] = diff\n")


def synthetic_buffers(size: int):
    truth, albedo, normal, depth = synthetic_scene(size, size)
    return build_render_buffers(truth, albedo=albedo, normal=normal, depth=depth, half_std=0.1, spp=16)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 256, 512])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--no-baseline", action="store_true", help="time the current implementation only")
    args = parser.parse_args(argv)

    ours = functools.partial(nfor.denoise, **nfor.PAPER_READING)
    denoisers = {"new": ours}
    if not args.no_baseline:
        denoisers["baseline"] = load_baseline("methods/nfor.py").denoise
        # the baseline with the current code's one behaviour change (feature differences within 1e-9
        # relative of zero count as 0), untimed: the current outputs equal it to rounding
        denoisers["baseline_fix"] = load_baseline("methods/nfor.py", patches={SNAP_OLD: SNAP_NEW},
                                                  suffix="_fix").denoise
    for denoise in (*denoisers.values(), nfor.denoise):
        denoise(synthetic_buffers(24))    # numba compilation / cache load
    for size in args.sizes:
        buffers = synthetic_buffers(size)
        if not args.no_baseline:
            print_comparison(size, time_denoisers(denoisers, buffers, args.repeats))
        print_comparison(size, time_denoisers({"tungsten": nfor.denoise, "ours": ours}, buffers, args.repeats),
                         new="tungsten", old="ours")


if __name__ == "__main__":
    main()
