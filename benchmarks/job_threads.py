"""Where a job's cores go: two jobs side by side, as ``snakemake --cores 2`` runs them, with the
libraries' default thread pools against pools held to the job's one thread
(:func:`mcbench.pipeline.threads.limit_threads`).

    python benchmarks/job_threads.py [--results results] [--scene cornell_box] [--spp 4] [--repeats 3]

Needs a finished run (the smoke run is enough): it reads the case's render and reference. Each
configuration runs ``--concurrent`` identical jobs at once (default 2, the default run's
``--cores 2`` with one-thread jobs), ``--repeats`` times; per job it records the wall time, the
CPU time (user + system, from ``wait4``), and the peak number of OS threads (``/proc/<pid>/status``
polled every 20 ms). Two jobs:

* ``methods`` -- :func:`mcbench.pipeline.methods.run_methods` on the case: OIDN, JBF and the
  ensemble of both (OIDN's TBB pool, numba's OpenMP pool);
* ``metrics`` -- the case job :func:`mcbench.pipeline.cases.run_case` with no method, evaluating the
  noisy input with every metric and its viewer images (HDR-FLIP's OpenMP pool, OpenBLAS under SciPy).

Configurations: ``defaults`` leaves the libraries their own pools (the method scripts set only
``NUMBA_NUM_THREADS`` and ``OMP_NUM_THREADS``, the metrics script nothing); ``limited`` is
:func:`mcbench.pipeline.threads.thread_environment` of 1. Prints a Markdown table with the
ratios limited / defaults measured in the same run, and the machine's load averages.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mcbench.pipeline.threads import THREAD_COUNT_VARIABLES, WAIT_VARIABLES, thread_environment  # noqa: E402

JOBS = {
    "methods": """
import json, sys
from mcbench.pipeline.methods import run_methods
render, out = sys.argv[1], sys.argv[2]
entries = [dict(name=n, module=n, params={}, input_paths=[], exr=f"{out}/{n}.exr", timing=f"{out}/{n}.json")
           for n in ("oidn", "jbf")]
entries.append(dict(name="ensemble", module="ensemble", params={}, input_paths=[f"{out}/oidn.exr", f"{out}/jbf.exr"],
                    exr=f"{out}/ensemble.exr", timing=f"{out}/ensemble.json"))
run_methods(entries, render, scene="bench", spp=0, threads=1)
""",
    "metrics": """
import sys
from mcbench.pipeline.cases import run_case
render, out, reference = sys.argv[1], sys.argv[2], sys.argv[3]
run_case({"scene": "bench", "spp": 0, "render": render, "reference": reference,
          "metrics": ["relmse", "relmse_corrected", "smape", "dssim", "flip"], "methods": [],
          "entries": [{"entry": "noisy", "image": render, "values": f"{out}/values/noisy.json",
                       "viewer": f"{out}/viewer_entries/noisy", "weight_inputs": []}],
          "outputs": {"metrics": f"{out}/metrics.csv", "viewer": f"{out}/viewer_case", "record": f"{out}/case.json"}})
""",
}


def environment(config: str, job: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_COUNT_VARIABLES and k not in WAIT_VARIABLES}
    env["PYTHONPATH"] = str(ROOT)
    if config == "limited":
        env.update(thread_environment(1))
    elif job == "methods":   # the two variables a method script sets without mcbench.pipeline.threads
        env.update(NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return env


def threads_of(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("Threads:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def run_concurrently(job: str, config: str, args, concurrent: int) -> list[dict]:
    """``concurrent`` copies of ``job`` at once; per copy wall, CPU seconds and peak threads."""
    procs = []
    for _ in range(concurrent):
        out = tempfile.mkdtemp(prefix=f"job_threads_{job}_")
        command = [sys.executable, "-c", JOBS[job], args.render, out, args.reference]
        start = time.perf_counter()
        proc = subprocess.Popen(command, env=environment(config, job), cwd=ROOT)
        procs.append({"proc": proc, "start": start, "peak": 0, "out": out})
    running = {p["proc"].pid: p for p in procs}
    while running:
        for pid, p in list(running.items()):
            p["peak"] = max(p["peak"], threads_of(pid))
            done, status, usage = os.wait4(pid, os.WNOHANG)
            if done:
                if status != 0:
                    raise SystemExit(f"{job} ({config}) failed with status {status}")
                p["wall"] = time.perf_counter() - p["start"]
                p["cpu"] = usage.ru_utime + usage.ru_stime
                del running[pid]
        time.sleep(0.02)
    return [{"wall": p["wall"], "cpu": p["cpu"], "peak_threads": p["peak"]} for p in procs]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default="results")
    parser.add_argument("--scene", default="cornell_box")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--concurrent", type=int, default=2)
    parser.add_argument("--json", default=None, help="also write the raw records here")
    args = parser.parse_args(argv)
    results = Path(args.results)
    args.render = str(results / "renders" / args.scene / f"spp{args.spp}.exr")
    args.reference = str(results / "references" / f"{args.scene}.exr")
    for path in (args.render, args.reference):
        if not Path(path).is_file():
            raise SystemExit(f"{path}: missing; run the smoke config first (README)")
    load_before = os.getloadavg()
    records = []
    for repeat in range(args.repeats):
        for job in JOBS:
            for config in ("defaults", "limited"):   # interleaved: drift in the load hits both alike
                for record in run_concurrently(job, config, args, args.concurrent):
                    records.append({"job": job, "config": config, "repeat": repeat, **record})
    load_after = os.getloadavg()
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))
    print(f"# Two jobs at once, library default pools against pools held to 1 thread\n")
    print(f"{args.concurrent} concurrent jobs, {args.repeats} repeats, case {args.scene} at {args.spp} spp; "
          f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}; {os.cpu_count()} cores.\n")
    print("| job | pools | wall s (median) | CPU s (median) | CPU / wall | peak threads | wall ratio | CPU ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for job in JOBS:
        medians = {}
        for config in ("defaults", "limited"):
            rows = [r for r in records if r["job"] == job and r["config"] == config]
            wall = sorted(r["wall"] for r in rows)[len(rows) // 2]
            cpu = sorted(r["cpu"] for r in rows)[len(rows) // 2]
            peak = max(r["peak_threads"] for r in rows)
            medians[config] = (wall, cpu)
            ratio = ("" if config == "defaults" else
                     f"| {wall / medians['defaults'][0]:.2f} | {cpu / medians['defaults'][1]:.2f} ")
            print(f"| {job} | {config} | {wall:.2f} | {cpu:.2f} | {cpu / wall:.2f} | {peak} "
                  + (ratio if ratio else "| 1 | 1 ") + "|")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
