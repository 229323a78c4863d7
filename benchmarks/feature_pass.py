"""What the Tungsten feature convention costs: noisy renders with ``features: tungsten`` against
``features: first_hit``, per scene, and the extra CPU seconds of a study's noisy renders.

Per scene of the config (its resolution): one warm-up render of each convention (loads the scene,
compiles the kernels), then ``--repeats`` rounds that time one render of ``--spp`` samples under
each convention, the two interleaved so that a change of the machine's load hits both; the best
round of each is kept (``benchmarks/timing.py``). CPU is the process's CPU time (Dr.Jit's worker
threads included), wall the elapsed time. The extra CPU of a study is the per-spp difference times
the spp the config renders per scene (every level of ``spp``, A + B = spp samples each); the
references are not counted (a Tungsten-convention reference chunk adds one feature pass of
``REFERENCE_FEATURE_SPP`` samples, measured separately as ``reference_feature_s``).

    python benchmarks/feature_pass.py --spp 64 --repeats 2            # the default study's scenes
"""

from __future__ import annotations

import argparse
import os
import time

import pandas as pd

from mcbench.pipeline.config import read_config_file
from mcbench.render.renderer import REFERENCE_FEATURE_SPP, render_buffers, render_reference_chunk
from mcbench.render.variants import pick_variant, set_threads
from scenes import load_scene, scene_spec

CONVENTIONS = ("first_hit", "tungsten")


def _cpu_and_wall(function) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    function()
    return time.process_time() - cpu, time.perf_counter() - wall


def measure_scene(scene: str, *, spp: int, repeats: int, resolution, variant: str) -> dict:
    """Best-of-``repeats`` CPU and wall seconds of one render of ``spp`` samples per convention."""
    module = load_scene(scene)
    size = tuple(resolution) if resolution else scene_spec(module).size
    best = {c: (float("inf"), float("inf")) for c in CONVENTIONS}
    for features in CONVENTIONS:
        render_buffers(module, 4, resolution=size, variant=variant, features=features)
    for _ in range(max(repeats, 1)):
        for features in CONVENTIONS:
            cpu, wall = _cpu_and_wall(lambda: render_buffers(module, spp, resolution=size, variant=variant,
                                                             features=features))
            best[features] = (min(best[features][0], cpu), min(best[features][1], wall))
    chunk = lambda features: render_reference_chunk(module, REFERENCE_FEATURE_SPP, 0, resolution=size,  # noqa: E731
                                                    variant=variant, features=features)
    reference_cpu = {features: min(_cpu_and_wall(lambda: chunk(features))[0] for _ in range(max(repeats, 1)))
                     for features in CONVENTIONS}
    row = {"scene": scene, "resolution": f"{size[0]}x{size[1]}"}
    for features in CONVENTIONS:
        row[f"{features}_cpu_s"], row[f"{features}_wall_s"] = best[features]
    row["cpu_ratio"] = best["tungsten"][0] / max(best["first_hit"][0], 1e-9)
    row["reference_feature_s"] = reference_cpu["tungsten"] - reference_cpu["first_hit"]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configfile", default="config.yaml")
    parser.add_argument("--spp", type=int, default=64, help="samples per pixel of each timed render")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--threads", type=int, default=1, help="render threads (the study's render_threads)")
    args = parser.parse_args()
    config = read_config_file(args.configfile)
    variant = pick_variant(config["variant"])
    set_threads(args.threads)
    load = os.getloadavg()
    rows = [measure_scene(scene, spp=args.spp, repeats=args.repeats, resolution=config.get("resolution"),
                          variant=variant) for scene in config["scenes"]]
    table = pd.DataFrame(rows)
    study_spp = sum(int(s) for s in config["spp"])
    extra = ((table.tungsten_cpu_s - table.first_hit_cpu_s) / args.spp * study_spp).sum()
    extra_references = table.reference_feature_s.sum() * int(config["reference"]["chunks"])
    print(f"variant {variant}, {args.threads} render thread(s), {args.spp} spp per timed render, best of "
          f"{args.repeats}; load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}\n")
    print(table.to_markdown(index=False, floatfmt=".3f"))
    print(f"\nnoisy renders: tungsten / first_hit CPU {table.tungsten_cpu_s.sum() / table.first_hit_cpu_s.sum():.3f}; "
          f"extra CPU of the study's noisy renders ({study_spp} spp per scene): {extra:.0f} s; "
          f"extra CPU of its references' feature passes: {extra_references:.0f} s")


if __name__ == "__main__":
    main()
