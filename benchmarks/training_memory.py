"""Peak memory (RSS) of training each learned network, as the workflow's `train_network` job runs it.

For each network a child process does what the job does (``mcbench.pipeline.training.train_learned_method``:
the data loading of ``training_data`` -- a denoiser's crops, a combiner's crops with its
declared ``correlated_bases``' results -- then ``train_network``) for ``--steps`` steps, with a validation
pass and a checkpoint at the last step, into a temporary folder; the parent reads the child's peak
RSS from ``os.wait4`` (``ru_maxrss``; MiB, like the ``max_rss`` of Snakemake's benchmark records).

Data at the default sizes: the denoisers train on every crop of the default config (160 scenes x
4 crops = 640), the combiners on their subset (56 scenes x 2 = 112, those with every base's
results). When ``--data`` holds fewer crops they are read again in turn up to that count (the
memory is the same: every file read is stored), which the table says; a smaller count takes
evenly spaced crops (quick checks).

``--code DIR`` imports ``mcbench`` and ``methods`` from another copy of the code (e.g. an older
commit, ``git archive <rev> mcbench methods | tar -x -C DIR``), to compare two versions' memory.

    .venv/bin/python benchmarks/training_memory.py [--networks kpcn deep_combiner] [--steps 20]
        [--data results/training] [--crops 640] [--combiner-crops 112] [--code DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from itertools import cycle, islice
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NETWORKS = ["deep_combiner", "deep_combiner_mb", "kpcn", "mcgan", "optix_ae", "wskpn"]
DEFAULT_CROPS = 160 * 4          # training.count + training.fibre_count scenes, training.crops each
DEFAULT_COMBINER_CROPS = 56 * 2  # training.combiners: count + fibre_count scenes, crops each


def repeated(paths: list, count: int) -> list:
    """``count`` of ``paths``: evenly spaced when there are more, else all in turn, again and again."""
    if count <= len(paths):
        return [paths[i * len(paths) // count] for i in range(count)]
    return list(islice(cycle(paths), count))


def child(args: argparse.Namespace) -> None:
    """Train one network as the job does; print one JSON line (items, seconds, files read)."""
    sys.path.insert(0, str(Path(args.code).resolve()))
    from mcbench.contracts.method import method_spec
    from mcbench.nn.crops import crop_paths
    from mcbench.nn.train import correlated_paths
    from mcbench.pipeline.training import learned_method, train_learned_method

    spec = method_spec(learned_method(args.child))
    files = crop_paths(args.data)
    correlated = None
    count = args.crops
    if spec.kind == "combiner":
        files, correlated = correlated_paths(args.data, spec.learned.correlated_bases, files)
        count = args.combiner_crops
    available = len(files)
    files = repeated(files, count)
    correlated = correlated and {base: repeated(paths, count) for base, paths in correlated.items()}
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        lines = []
        record = train_learned_method(args.child, [str(f) for f in files], Path(folder) / "w.pt",
                                      Path(folder) / "w.json", Path(folder) / "w.ckpt",
                                      {"steps": args.steps, "threads": args.threads}, log=lines.append,
                                      correlated_files=correlated)
    print(json.dumps({"crops": len(files), "available": available, "items": record["data"]["crops"],
                      "seconds": time.perf_counter() - started}), flush=True)


def measure(name: str, args: argparse.Namespace) -> dict:
    """Run the child for ``name``; its result and peak RSS (MiB)."""
    command = [sys.executable, str(Path(__file__).resolve()), "--child", name, "--steps", str(args.steps),
               "--data", str(args.data), "--crops", str(args.crops), "--combiner-crops", str(args.combiner_crops),
               "--code", str(args.code), "--threads", str(args.threads)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    output = process.stdout.read()
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode:
        raise SystemExit(f"{name}: child exited with {process.returncode}")
    return {**json.loads(output.strip().splitlines()[-1]), "peak_mib": usage.ru_maxrss / 1024}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", nargs="+", default=NETWORKS)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--data", default=str(ROOT / "results" / "training"))
    parser.add_argument("--crops", type=int, default=DEFAULT_CROPS, help="a denoiser's crops")
    parser.add_argument("--combiner-crops", type=int, default=DEFAULT_COMBINER_CROPS, help="a combiner's crops")
    parser.add_argument("--code", default=str(ROOT), help="folder with the mcbench and methods to measure")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    print(f"code {args.code}, data {args.data}, {args.steps} steps")
    print(f"{'network':>17} {'crops':>11} {'items':>6} {'seconds':>8} {'peak RSS MiB':>13}")
    for name in args.networks:
        result = measure(name, args)
        crops = f"{result['crops']}" + (f" ({result['available']})" if result["available"] < result["crops"] else "")
        print(f"{name:>17} {crops:>11} {result['items']:>6} {result['seconds']:>8.1f} {result['peak_mib']:>13.0f}",
              flush=True)
    print("crops (n): n distinct files, read again in turn up to the default count")


if __name__ == "__main__":
    main()
