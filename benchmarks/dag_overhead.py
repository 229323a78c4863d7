"""Where a finished Snakemake run's time went: compute against overhead.

    python benchmarks/dag_overhead.py [--results results] [--log .snakemake/log/<run>.log] [--cores 2]

Reads, from a finished run:

* the run's wall time: the ``Elapsed time`` line of its Snakemake log (default: the newest log
  in ``.snakemake/log/`` beside ``--results``);
* per job, its wall and CPU seconds: the ``benchmark:`` records under ``results/benchmarks/``
  (rules without one, e.g. the small table and figure rules, are not counted);
* compute, i.e. the seconds a method, render or metric spends on its own work:
  ``results/timings.csv`` (each method's compute, I/O and warm-up excluded), the ``seconds``
  metadata of the noisy renders and of the merged references (the sum of their chunks' render
  time), and the CPU seconds of the case jobs' evaluation phase (``results/cases/*/spp*.json``,
  ``seconds.evaluation``: every entry's metrics and viewer images, reading included; runs whose
  case records lack it count it as overhead).

Prints per stage: jobs, summed job wall, summed job CPU, summed compute; and for the run: the
**overhead share** 1 - compute / (cores x wall), the share of the cores' time in which no
method, render or metric computes (process starts, imports, scheduling, idle cores), and the
**core utilisation** sum(job CPU) / (cores x wall) (the scheduler's own CPU not included), with the
machine's load averages at the time of the report.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from collections import defaultdict
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.io.exr import read_metadata  # noqa: E402

STAGES = {  # benchmark folder (and batch suffix) -> stage
    "render_noisy": "render (noisy)",
    "render_reference": "render (reference chunks)",
    "methods": "methods (one job each)",
    "batches/methods": "methods (one job per case)",
    "batches/combiners": "methods (combiner batches)",             # runs before the case jobs
    "batches/learned_denoisers": "methods (learned batches)",      # (records of older runs)
    "metrics": "metrics",
    "viewer": "viewer",
}


def elapsed_seconds(log: Path) -> float:
    """The ``Elapsed time: H:MM:SS.ffffff`` of a Snakemake log, in seconds."""
    match = re.search(r"Elapsed time: (\d+):(\d+):(\d+(?:\.\d+)?)", log.read_text())
    if not match:
        raise SystemExit(f"{log}: no 'Elapsed time' line (the run did not finish?)")
    hours, minutes, seconds = match.groups()
    return int(hours) * 3600 + int(minutes) * 60 + float(seconds)


def stage_of(record: Path, benchmarks: Path) -> str:
    relative = record.relative_to(benchmarks)
    folder = relative.parts[0] if len(relative.parts) > 1 else record.stem
    if folder == "batches":
        kind = record.stem.rsplit("_", 1)[-1]
        kind = "learned_denoisers" if kind == "denoisers" else kind
        return STAGES.get(f"batches/{kind}", f"batches/{kind}")
    return STAGES.get(folder, folder)


def job_records(benchmarks: Path) -> pd.DataFrame:
    """One row per benchmark record: stage, wall seconds, CPU seconds."""
    rows = []
    for record in sorted(benchmarks.rglob("*.tsv")):
        table = pd.read_csv(record, sep="\t")
        if table.empty:
            continue
        rows.append({"stage": stage_of(record, benchmarks), "wall": float(table["s"].iloc[0]),
                     "cpu": float(table["cpu_time"].iloc[0])})
    return pd.DataFrame(rows, columns=["stage", "wall", "cpu"])


def compute_seconds(results: Path) -> dict[str, float]:
    """Seconds of own work per stage (methods from timings.csv; renders and metrics from EXR metadata)."""
    compute = defaultdict(float)
    timings = pd.read_csv(results / "timings.csv")
    compute["methods (all)"] = float(timings["seconds"].sum())
    for path in (results / "renders").rglob("*.exr"):
        compute["render (noisy)"] += float(read_metadata(path).get("seconds", 0.0))
    for path in (results / "references").glob("*.exr"):
        compute["render (reference chunks)"] += float(read_metadata(path).get("seconds", 0.0))
    for path in (results / "cases").glob("*/spp*.json"):
        phases = json.loads(path.read_text()).get("seconds") or {}
        compute["evaluation (case jobs)"] += float(phases.get("evaluation", {}).get("cpu", 0.0))
    return dict(compute)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default="results")
    parser.add_argument("--log", default=None)
    parser.add_argument("--cores", type=int, default=2)
    args = parser.parse_args(argv)
    results = Path(args.results)
    log = Path(args.log) if args.log else max((results.parent / ".snakemake" / "log").glob("*.snakemake.log"),
                                              key=lambda p: p.stat().st_mtime)
    wall = elapsed_seconds(log)
    jobs = job_records(results / "benchmarks")
    compute = compute_seconds(results)
    per_stage = jobs.groupby("stage").agg(jobs=("wall", "size"), wall=("wall", "sum"), cpu=("cpu", "sum"))
    print(f"run: {log}  wall {wall / 60:.1f} min on {args.cores} cores; load now "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'stage':32s} {'jobs':>6s} {'job wall min':>13s} {'job CPU min':>12s} {'compute min':>12s}")
    for stage, row in per_stage.iterrows():
        own = compute.get(stage)
        own_text = f"{own / 60:12.2f}" if own is not None else f"{'(below)':>12s}"
        print(f"{stage:32s} {int(row.jobs):6d} {row.wall / 60:13.2f} {row.cpu / 60:12.2f} {own_text}")
    for stage in ("methods (all)", "evaluation (case jobs)"):
        print(f"{stage + ', compute':32s} {'':6s} {'':13s} {'':12s} {compute.get(stage, 0.0) / 60:12.2f}")
    total_compute = sum(compute.values())
    capacity = args.cores * wall
    print(f"compute {total_compute / 60:.1f} min of {capacity / 60:.1f} core-min: "
          f"overhead share {1 - total_compute / capacity:.1%}; "
          f"core utilisation (jobs' CPU) {jobs['cpu'].sum() / capacity:.1%}")


if __name__ == "__main__":
    main()
