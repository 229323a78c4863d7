"""Measure each scene's render cost and extrapolate the CPU-hours a config needs.

For every scene of a config: one warm-up render (loads the scene, compiles kernels), then a
timed render of ``--spp`` samples per pixel at the config's resolution; seconds per spp times
the spp the config asks for (noisy levels: A + B = spp each; the reference) gives wall
seconds, times the render threads gives CPU-hours. Timings on shared machines are noisy:
the cost *ratios* between scenes are the robust part.

    python benchmarks/scene_costs.py --config workflow/configs/paper.yaml --spp 32
"""

from __future__ import annotations

import argparse
import time

import pandas as pd
import yaml

from mcbench.render.renderer import render_buffers
from mcbench.render.variants import pick_variant, set_threads
from scenes import load_scene, scene_spec


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="config.yaml")
    parser.add_argument("--spp", type=int, default=32, help="samples per pixel of the timed render")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    config = yaml.safe_load(open(args.config))
    variant = pick_variant(config.get("variant", "auto"))
    set_threads(args.threads)
    reference = config["reference"]
    rows = []
    for scene in config["scenes"]:
        module = load_scene(scene)
        resolution = tuple(config["resolution"]) if config.get("resolution") else scene_spec(module).size
        render_buffers(module, 2, resolution=resolution, variant=variant)
        start = time.perf_counter()
        render_buffers(module, args.spp, resolution=resolution, variant=variant)
        per_spp = (time.perf_counter() - start) / args.spp
        noisy_spp = sum(config["spp"])
        reference_spp = reference.get("scene_spp", {}).get(scene, reference["spp"])
        rows.append({"scene": scene, "resolution": f"{resolution[0]}x{resolution[1]}",
                     "ms_per_spp": 1e3 * per_spp,
                     "render_cpu_hours": per_spp * noisy_spp * args.threads / 3600,
                     "reference_spp": reference_spp,
                     "reference_cpu_hours": per_spp * reference_spp * args.threads / 3600})
    table = pd.DataFrame(rows)
    print(f"variant {variant}, {args.threads} threads, timed at {args.spp} spp\n")
    print(table.to_markdown(index=False, floatfmt=".3f"))
    print(f"\ntotal: renders {table.render_cpu_hours.sum():.2f} CPU-h, "
          f"references {table.reference_cpu_hours.sum():.2f} CPU-h")


if __name__ == "__main__":
    main()
