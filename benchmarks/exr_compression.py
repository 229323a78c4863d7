"""What lossless ZIP compression saves and costs on a finished study's EXRs.

    python benchmarks/exr_compression.py --results results [--every 4]

For the renders (``renders/<scene>/spp<N>.exr``), the base denoisers' outputs and one case's every
output (``outputs/<first scene>/spp<smallest>/``), each file (every ``--every``-th) is read and
written again twice in a temporary folder, uncompressed and ZIP-compressed
(:func:`mcbench.io.exr.write_layers`), and read back five times each. Prints Markdown: the files,
their bytes both ways, the ratio, and the mean read time per file both ways (milliseconds, with
the machine's load average). The pixels are the same both ways (lossless).
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

from mcbench.io.exr import read_layers, write_layers  # noqa: E402

READS = 5


def measure(files: list[Path], folder: Path) -> tuple[float, float, float, float]:
    """(MB uncompressed, MB ZIP, ms per read uncompressed, ms per read ZIP) over ``files``."""
    plain_bytes = zip_bytes = plain_seconds = zip_seconds = 0.0
    for path in files:
        layers = read_layers(path)
        plain, packed = folder / "plain.exr", folder / "zip.exr"
        write_layers(plain, layers)
        write_layers(packed, layers, compression="zip")
        plain_bytes += plain.stat().st_size
        zip_bytes += packed.stat().st_size
        for target, add in ((plain, "plain"), (packed, "zip")):
            start = time.perf_counter()
            for _ in range(READS):
                read_layers(target)
            seconds = (time.perf_counter() - start) / READS
            if add == "plain":
                plain_seconds += seconds
            else:
                zip_seconds += seconds
    n = max(len(files), 1)
    return plain_bytes / 1e6, zip_bytes / 1e6, plain_seconds / n * 1e3, zip_seconds / n * 1e3


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
    print("| files | count | MB uncompressed | MB ZIP | ZIP / uncompressed | ms per read uncompressed | ms per read ZIP |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        for label, files in groups.items():
            plain, packed, plain_ms, zip_ms = measure(files, Path(folder))
            print(f"| {label} | {len(files)} | {plain:.1f} | {packed:.1f} | {packed / max(plain, 1e-12):.2f} | "
                  f"{plain_ms:.1f} | {zip_ms:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
