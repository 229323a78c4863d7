"""What each metric costs per entry, and so per study: the evaluation share of a case job.

    python benchmarks/metric_costs.py RESULTS [--scene veach_ajar] [--spp 64] [--repeats 3]

Reads one finished run's noisy render and reference of a case (``RESULTS/renders/<scene>/spp<N>.exr``,
``RESULTS/references/<scene>.exr``) and times each metric plugin of ``metrics/`` on that pair as a
case job computes it (:func:`mcbench.pipeline.evaluation.entry_metrics`, the value and the viewer's
map), one thread (``OMP_NUM_THREADS=1``: HDR-FLIP's library runs OpenMP loops, and a case job has
one thread), best of ``--repeats``. Prints per metric the wall and CPU seconds of one entry and,
scaled by the run's entries (``RESULTS/metrics.csv``: entries per case times cases), the CPU
minutes per study, with the machine's load averages. The render stands in for every entry: a
metric's cost depends on the image size and, for HDR-FLIP, on the number of exposures, which the
reference alone sets.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.io.exr import read_layers  # noqa: E402
from mcbench.pipeline.evaluation import entry_metrics  # noqa: E402
from mcbench.pipeline.registry import load_metrics  # noqa: E402


def time_metric(spec, image, reference, variance, *, repeats: int) -> tuple[float, float]:
    """(wall s, CPU s) of the best of ``repeats`` evaluations of one metric's value and map."""
    best = (float("inf"), float("inf"))
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        entry_metrics({spec.name: spec}, image, reference, variance, maps=True)
        best = min(best, (time.perf_counter() - wall, time.process_time() - cpu))
    return best


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", type=Path)
    parser.add_argument("--scene", default="veach_ajar")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    image = read_layers(args.results / "renders" / args.scene / f"spp{args.spp}.exr", ["color"])["color"]
    reference_layers = read_layers(args.results / "references" / f"{args.scene}.exr")
    reference, variance = reference_layers["color"], reference_layers.get("variance")
    table = pd.read_csv(args.results / "metrics.csv")
    metrics = list(dict.fromkeys(table["metric"]))
    evaluations = len(table.drop_duplicates(["scene", "spp", "entry"]))
    print(f"{args.scene} spp{args.spp} {image.shape[1]}x{image.shape[0]}; {evaluations} entry evaluations in the run; "
          f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'metric':18s} {'wall s':>8s} {'CPU s':>8s} {'study CPU min':>14s}")
    total = 0.0
    for name, spec in load_metrics(metrics).items():
        wall, cpu = time_metric(spec, image, reference, variance, repeats=args.repeats)
        total += cpu * evaluations
        print(f"{name:18s} {wall:8.3f} {cpu:8.3f} {cpu * evaluations / 60:14.1f}")
    print(f"{'all':18s} {'':8s} {'':8s} {total / 60:14.1f}")


if __name__ == "__main__":
    main()
