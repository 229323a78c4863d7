"""What keeping freed memory in the heap (mcbench.pipeline.freed_memory) saves a network's training.

Each repeat trains ``--network`` for ``--steps`` steps on one torch thread, in two child processes
in turn (the order alternating between repeats): one with glibc's default allocation, one after
:func:`mcbench.pipeline.freed_memory.keep_freed_memory`. A child reports its user and system CPU
seconds, minor page faults and wall seconds (``getrusage``); the parent prints each run, the
medians, the ratios kept / default, and the machine's load averages before and after. The
children train on ``--data`` (training crops, e.g. ``results/training`` after ``snakemake
training_data``) with validation and checkpoints out of the way, into a temporary folder.

    .venv/bin/python benchmarks/freed_memory.py [--network kpcn] [--steps 30] [--repeats 3] [--data results/training]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child(args: argparse.Namespace) -> None:
    """One training (kept or default allocation); prints one JSON line."""
    sys.path.insert(0, str(ROOT))
    from mcbench.pipeline.freed_memory import keep_freed_memory

    kept = keep_freed_memory() if args.child == "kept" else False
    from mcbench.nn.crops import crop_paths
    from mcbench.nn.train import train_network
    from mcbench.pipeline.training import learned_method

    module = learned_method(args.network)
    files = crop_paths(args.data)
    with tempfile.TemporaryDirectory() as folder:
        before, start = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        train_network(module, files, f"{folder}/w.pt", f"{folder}/w.json", f"{folder}/c.pt",
                      {"steps": args.steps, "threads": 1, "validate_every": 10 ** 9,
                       "checkpoint_every": 10 ** 9}, log=lambda message: None)
        after = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"kept": kept, "wall": time.perf_counter() - start,
                      "user": after.ru_utime - before.ru_utime, "sys": after.ru_stime - before.ru_stime,
                      "faults": after.ru_minflt - before.ru_minflt}))


def run_child(args: argparse.Namespace, mode: str) -> dict:
    command = [sys.executable, __file__, "--child", mode, "--network", args.network, "--steps", str(args.steps),
               "--data", args.data]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"child ({mode}) failed:\n{done.stderr[-3000:]}")
    return {"mode": mode, **json.loads(done.stdout.strip().splitlines()[-1])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--network", default="kpcn")
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--data", default="results/training")
    parser.add_argument("--child", choices=["kept", "default"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    if not Path(args.data).is_dir():
        raise SystemExit(f"--data {args.data}: no such folder of training crops (snakemake --cores 2 training_data)")
    load_before = os.getloadavg()
    runs = []
    for repeat in range(args.repeats):
        for mode in (("default", "kept") if repeat % 2 == 0 else ("kept", "default")):
            runs.append(run_child(args, mode))
            run = runs[-1]
            print(f"{run['mode']:8s} wall {run['wall']:7.2f} s  user {run['user']:7.2f} s  sys {run['sys']:6.2f} s  "
                  f"faults {run['faults']:9d}", flush=True)
    median = {mode: {key: statistics.median(r[key] for r in runs if r["mode"] == mode)
                     for key in ("wall", "user", "sys", "faults")} for mode in ("default", "kept")}
    print(f"\n{args.network}, {args.steps} steps on one thread, {args.repeats} repeats each, medians "
          f"({platform.processor() or platform.machine()}, {os.cpu_count()} CPUs):")
    for mode in ("default", "kept"):
        m = median[mode]
        print(f"  {mode:8s} wall {m['wall']:.2f} s, user {m['user']:.2f} s, sys {m['sys']:.2f} s, faults {m['faults']:.0f}")
    cpu = {mode: median[mode]["user"] + median[mode]["sys"] for mode in median}
    print(f"  kept / default: wall {median['kept']['wall'] / max(median['default']['wall'], 1e-9):.3f}, "
          f"CPU {cpu['kept'] / max(cpu['default'], 1e-9):.3f}")
    print(f"  load averages before {load_before}, after {os.getloadavg()}")


if __name__ == "__main__":
    main()
