"""Where a finished study's disk goes: which layers and which methods fill it.

    python benchmarks/disk_usage.py --results results

Prints Markdown: the bytes of each top-level folder of ``results/``, then the method outputs
(``outputs/<scene>/spp<N>/<method>.exr``) split by what their layers hold and by the kind of
method (base denoiser or combiner, from the output's timing record ``<method>.json``), and the
renders (``renders/``) by layer. A layer's share is its uncompressed size (height x width x
channels x bytes of its pixel type, from the EXR header, the pixels not read); a file's header
is the rest. A hard-linked file counts once, in the first folder (by name) that holds it. Reads
headers only.
"""

from __future__ import annotations

import argparse
import json
import re
from collections import defaultdict
from pathlib import Path

import OpenEXR

# What a layer holds, by name: the first pattern that matches.
OUTPUT_KINDS = [("colour (full image)", r"^color$"), ("halves A, B", r"^color_[ab]$"),
                ("sub-buffer results", r"_sub\d$"), ("filtered weights", r"^weights_filtered_"),
                ("raw weights", r"^weights_raw_"), ("other extras", r".")]
RENDER_KINDS = [("colour and halves", r"^color(_[ab])?$"), ("colour variance", r"^variance(_[ab])?$"),
                ("sample bins", r"_bin\d"), ("features", r"^(albedo|normal|depth|position|visibility)"),
                ("other", r".")]


def _kind(name: str, kinds) -> str:
    return next(label for label, pattern in kinds if re.search(pattern, name))


def layer_bytes(path: Path) -> dict[str, int]:
    """Uncompressed bytes of each layer of the EXR at ``path`` (channels ``name.R``, ``name.G``,
    ``name.B`` or ``name`` grouped by layer; every pixel type counted as 4 bytes, which is what
    this project writes), from its header."""
    with OpenEXR.File(str(path), header_only=True) as exr:
        header = exr.header()
        (x0, y0), (x1, y1) = header["dataWindow"]
        pixels = int(x1 - x0 + 1) * int(y1 - y0 + 1)
        sizes: dict[str, int] = defaultdict(int)
        for channel in header["channels"]:
            sizes[channel.name.rsplit(".", 1)[0] if channel.name.endswith((".R", ".G", ".B")) else channel.name] += \
                pixels * 4
        return dict(sizes)


def _table(title: str, rows: dict[str, float], total: float) -> list[str]:
    lines = [f"| {title} | MB | share |", "|---|---:|---:|"]
    for label, size in sorted(rows.items(), key=lambda item: -item[1]):
        lines.append(f"| {label} | {size / 1e6:.1f} | {size / max(total, 1):.1%} |")
    return lines + [""]


def report(results: Path) -> str:
    """The Markdown report of ``results`` (see the module docstring)."""
    seen: set[tuple[int, int]] = set()       # a hard-linked file (the viewer's) counts once

    def once(path: Path) -> int:
        stat = path.stat()
        if (stat.st_dev, stat.st_ino) in seen:
            return 0
        seen.add((stat.st_dev, stat.st_ino))
        return stat.st_size

    folders = {p.name: sum(once(f) for f in sorted(p.rglob("*")) if f.is_file()) for p in sorted(results.iterdir())
               if p.is_dir()}
    files = sum(f.stat().st_size for f in results.iterdir() if f.is_file())
    total = sum(folders.values()) + files
    lines = [f"# Disk use of {results}: {total / 1e9:.2f} GB", ""]
    lines += _table("folder", {**{f"{k}/": v for k, v in folders.items()}, "(files at the top)": files}, total)
    by_layer: dict[str, int] = defaultdict(int)
    by_method_kind: dict[str, int] = defaultdict(int)
    for exr in sorted((results / "outputs").rglob("*.exr")):
        record = exr.with_suffix(".json")
        kind = json.loads(record.read_text()).get("kind", "unknown") if record.exists() else "unknown"
        by_method_kind[kind] += exr.stat().st_size
        for name, size in layer_bytes(exr).items():
            by_layer[_kind(name, OUTPUT_KINDS)] += size
    outputs = folders.get("outputs", 0)
    if outputs:
        lines += _table("method outputs by layer (uncompressed)", by_layer, outputs)
        lines += _table("method outputs by method kind (file bytes)", by_method_kind, outputs)
    render_layers: dict[str, int] = defaultdict(int)
    for exr in sorted((results / "renders").rglob("*.exr")):
        for name, size in layer_bytes(exr).items():
            render_layers[_kind(name, RENDER_KINDS)] += size
    if render_layers:
        lines += _table("renders by layer (uncompressed)", render_layers, folders.get("renders", 0))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results"))
    args = parser.parse_args(argv)
    print(report(args.results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
