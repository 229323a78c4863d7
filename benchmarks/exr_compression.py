"""What the lossless EXR compressions save and cost on a finished study's EXRs.

    python benchmarks/exr_compression.py --results results [--every 4]

For the renders (``renders/<scene>/spp<N>.exr``), the base denoisers' outputs and one case's every
output (``outputs/<first scene>/spp<smallest>/``), each file (every ``--every``-th) is read and
written again in a temporary folder under each compression of :data:`mcbench.io.exr.COMPRESSIONS`
(:func:`mcbench.io.exr.write_layers`, CPU seconds of the write), and read back five times each
(wall time). Prints Markdown: per group and compression the bytes, their ratio to the uncompressed
file's, and the mean read and write time per file (milliseconds), with the machine's load
average. The pixels read back are checked equal to those written (lossless).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from mcbench.io.exr import COMPRESSIONS, read_layers, write_layers  # noqa: E402

READS = 5


def measure(files: list[Path], folder: Path) -> dict[str, tuple[float, float, float]]:
    """Per compression: (MB, ms per read, CPU ms per write), over ``files``."""
    totals = {name: [0.0, 0.0, 0.0] for name in COMPRESSIONS}
    for path in files:
        layers = read_layers(path)
        for name, total in totals.items():
            target = folder / f"{name}.exr"
            start = time.process_time()
            write_layers(target, layers, compression=name)
            total[2] += time.process_time() - start
            total[0] += target.stat().st_size
            start = time.perf_counter()
            for _ in range(READS):
                back = read_layers(target)
            total[1] += (time.perf_counter() - start) / READS
            if any(not np.array_equal(back[key], np.asarray(layers[key], np.float32)) for key in layers):
                raise SystemExit(f"{path}: {name} did not give back the pixels written")
    n = max(len(files), 1)
    return {name: (size / 1e6, read / n * 1e3, write / n * 1e3) for name, (size, read, write) in totals.items()}


def _base_outputs(results: Path) -> list[Path]:
    files = []
    for timing in sorted(results.glob("outputs/*/spp*/*.json")):
        exr = timing.with_suffix(".exr")
        if exr.exists() and json.loads(timing.read_text()).get("kind") == "denoiser":
            files.append(exr)
    return files


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results"))
    parser.add_argument("--every", type=int, default=4)
    args = parser.parse_args(argv)
    renders = sorted(args.results.glob("renders/*/spp*.exr"))
    first_case = sorted(args.results.glob("outputs/*/spp*"), key=lambda p: (p.parent.name, int(p.name[3:])))
    groups = {"renders": renders[::args.every], "base denoisers' outputs": _base_outputs(args.results)[::args.every],
              "one case's outputs": sorted(first_case[0].glob("*.exr")) if first_case else []}
    print(f"# EXR compression on {args.results} (load average {os.getloadavg()[0]:.2f})\n")
    print("| files | count | compression | MB | of uncompressed | ms per read | CPU ms per write |")
    print("|---|---:|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        for label, files in groups.items():
            sizes = measure(files, Path(folder))
            plain = max(sizes["none"][0], 1e-12)
            for name, (megabytes, read_ms, write_ms) in sizes.items():
                print(f"| {label} | {len(files)} | {name} | {megabytes:.1f} | {megabytes / plain:.2f} | "
                      f"{read_ms:.1f} | {write_ms:.1f} |")
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
