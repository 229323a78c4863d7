"""CPU of a reference chunk's colour pass with and without the first-hit AOVs.

    python benchmarks/reference_colour_pass.py [--spp 256] [--repeats 3] [scene ...]

Per scene at 128², one render thread: the process CPU seconds of one ``spp``-sample pass of the
wrapped ``moment(aov(albedo, sh_normal, depth, <integrator>))`` (what a chunk rendered before) and
of ``moment(aov(<integrator>))`` with an empty AOV list (what it renders now,
:func:`mcbench.render.renderer.render_reference_chunk`), interleaved, the best of ``repeats``;
their ratio, and the largest difference between the two passes' colour (same seed: float32
rounding of the film's sums only). Prints the machine's load first.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mcbench.pipeline.registry import load_scene  # noqa: E402
from mcbench.render import renderer  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["cornell_box", "veach_ajar", "furball", "glass_caustics"])
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    renderer.set_threads(1)
    variant = renderer.pick_variant("auto")
    print(f"load average {os.getloadavg()}, variant {variant}")
    print("| scene | with the AOVs, CPU s | without | ratio | largest colour difference |")
    print("|---|---:|---:|---:|---:|")
    for name in args.scenes:
        module = load_scene(name)
        wrapped, _ = renderer._loaded_module(module, 128, 128, variant)
        bare, _ = renderer._loaded_module(module, 128, 128, variant, aovs=False)
        seconds = {"wrapped": [], "bare": []}
        images = {}
        for scene in (wrapped, bare):
            renderer._render_pass(scene, 16, 1)                       # compile / load the kernels
        for repeat in range(args.repeats):
            for key, scene in (("wrapped", wrapped), ("bare", bare)):
                start = time.process_time()
                images[key] = renderer._render_pass(scene, args.spp, 1000 + repeat)
                seconds[key].append(time.process_time() - start)
        colour_wrapped = images["wrapped"][..., renderer._channel_indices(wrapped)["color"][0]]
        colour_bare = images["bare"][..., renderer._channel_indices(bare, renderer.COLOUR_CHANNELS, None)["color"][0]]
        a, b = min(seconds["wrapped"]), min(seconds["bare"])
        print(f"| {name} | {a:.3f} | {b:.3f} | {b / a:.3f} | {np.abs(colour_wrapped - colour_bare).max():.2e} |",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
