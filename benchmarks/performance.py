"""The performance figures of the benchmarks in one run (each script's own output, in order).

    python benchmarks/performance.py [--quick] [--results results]

1. ``bench_ensemble.py``: the ensemble's combine at 1024^2 (N = 2, 4, 8; iterative and exact),
   whole process with EXR reads, wall time and peak RSS beside the authors' C++ program, fitted
   exponents of time against pixels and N, numba against NumPy;
2. ``bench_solvers.py --image-side 1024``: both solvers on image-sized problems, optimality gaps,
   the fraction of pixel-channels stopped at 1024 iterations per start, and the QP baseline (Fig. 6);
3. ``bench_nfor.py`` and ``bench_rdfc.py`` at 128^2 and 512^2, against the baseline
   implementation (``benchmarks/baseline.py``) timed in the same run;
4. ``dag_overhead.py`` on a finished run's ``--results`` (when it has a timings.csv): compute
   against overhead per stage, overhead share and core utilisation.

Each script prints the machine's load with its numbers. ``--quick`` passes ``--quick`` (or the
smallest sizes) to each, for a smoke run of this script.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def run(script: str, *args: str) -> int:
    print(f"\n==== {script} {' '.join(args)}  (load {' '.join(f'{x:.2f}' for x in os.getloadavg())})", flush=True)
    start = time.perf_counter()
    code = subprocess.call([sys.executable, str(HERE / script), *args])
    print(f"==== {script}: exit {code}, {time.perf_counter() - start:.0f} s", flush=True)
    return code


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--results", type=Path, default=Path("results"))
    args = parser.parse_args(argv)
    sizes = ["--sizes", "64"] if args.quick else ["--sizes", "128", "512"]
    codes = [run("bench_ensemble.py", *(["--quick"] if args.quick else [])),
             run("bench_solvers.py", *(["--quick"] if args.quick else ["--image-side", "1024"])),
             run("bench_nfor.py", *sizes),
             run("bench_rdfc.py", *sizes)]
    if (args.results / "timings.csv").exists():
        codes.append(run("dag_overhead.py", "--results", str(args.results)))
    else:
        print(f"\n==== dag_overhead.py skipped: no {args.results / 'timings.csv'} (run the main job first)")
    return max(codes)


if __name__ == "__main__":
    raise SystemExit(main())
