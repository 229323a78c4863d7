"""CPU seconds of a reference chunk per scene, measured here (the cost side of tools/reference_budget.py).

    python tools/reference_cost.py veach_ajar fog_beams ... [--spp 1024]

Renders one reference chunk of ``--spp`` samples per scene at the scene's own resolution, one
thread, in this process, and prints its CPU time (user + system, seconds) and the CPU-hours a
reference of ``reference_spp`` samples would take (linear in spp). Writes nothing that stays.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.pipeline.rendering import render_reference_chunk  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--spp", type=int, default=1024)
    args = parser.parse_args(argv)
    print(f"load average at start: {os.getloadavg()}")
    for scene in args.scenes:
        with tempfile.TemporaryDirectory() as folder:
            before, start = resource.getrusage(resource.RUSAGE_SELF), time.time()
            render_reference_chunk(scene, args.spp, 0, str(Path(folder) / "chunk.exr"), threads=1)
            after = resource.getrusage(resource.RUSAGE_SELF)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        print(f"{scene}: {cpu:.1f} s CPU for {args.spp} spp (wall {time.time() - start:.1f} s); "
              f"{cpu / args.spp * 16384 / 3600:.4f} CPU-hours per 16384 spp")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
