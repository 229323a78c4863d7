"""Compute time of methods.rdfc.denoise at window radius 10 and 20 on one 128x128 render
(docs/fidelity_rdfc.md): one process, one numba thread, a warm-up run of each radius first
(numba compilation), then ``--repeats`` timed runs of each, alternating; prints the medians.

    .venv/bin/python tools/rdfc/render_case.py cornell_box --ref-spp 1024 --out /tmp/rdfc   # the render
    NUMBA_NUM_THREADS=1 .venv/bin/python tools/rdfc/time_radius.py cornell_box --spp 4 --out /tmp/rdfc
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from mcbench.io.buffers import RenderBuffers
from methods import rdfc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--out", type=Path, default=Path("/tmp/rdfc"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--radii", default="10,20")
    args = ap.parse_args(argv)
    buffers = RenderBuffers(layers=dict(np.load(args.out / f"{args.scene}_spp{args.spp}.npz")), spp=args.spp)
    radii = [int(r) for r in args.radii.split(",")]
    times = {r: [] for r in radii}
    for r in radii:
        rdfc.denoise(buffers, radius=r)                       # warm-up (compilation)
    for _ in range(args.repeats):
        for r in radii:
            t = time.perf_counter()
            rdfc.denoise(buffers, radius=r)
            times[r].append(time.perf_counter() - t)
    for r in radii:
        print(f"{args.scene} {args.spp} spp {buffers.shape[1]}x{buffers.shape[0]} radius {r}: median "
              f"{statistics.median(times[r]):.2f} s of {', '.join(f'{t:.2f}' for t in times[r])}")


if __name__ == "__main__":
    main()
