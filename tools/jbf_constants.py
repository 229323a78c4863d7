"""The JBF base denoiser's constants (methods/jbf.py), chosen on training scenes.

    nice -n 10 python tools/jbf_constants.py [--scenes 8] [--table]

Renders ``--scenes`` procedural training scenes (mcbench.training_data: object-family seeds
0 .. scenes - 1, render base seed 7; none is a test scene) at 64 x 64 with 4, 16 and 64 spp and a
1024-spp target each, then filters every noisy full image with ``methods.jbf.denoise_image`` for
each point of :data:`GRID` (window radius fixed at :data:`RADIUS`) and prints the point with the
lowest mean relMSE over the scenes and spp levels (relMSE as ``mcbench.analysis.metrics.relmse``,
against the target), the constants as a Python dict, and with ``--table`` the best few points.
The numba filter runs on one thread (NUMBA_NUM_THREADS=1): about 2 minutes on one core.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mcbench.analysis.metrics import relmse  # noqa: E402
from mcbench.io.buffers import ImageBuffers  # noqa: E402
from mcbench.training_data import training_example  # noqa: E402

RADIUS = 7
SPP_LEVELS = (4, 16, 64)
TARGET_SPP = 1024
RESOLUTION = (64, 64)
#: a few values per constant. Coarser grids came first (sigma_spatial 2-5, sigma_color 0.25-4,
#: sigma_albedo 0.05-2, sigma_normal 0.1-0.4, sigma_depth 0.05-25; docs/methods.md); this one
#: refines around their best points, each best value inside its range
GRID = {"sigma_spatial": (3.0, 4.0, 5.0),
        "sigma_color": (0.35, 0.5, 0.7),
        "sigma_albedo": (0.5, 1.0, 2.0),
        "sigma_normal": (0.2, 0.3, 0.4, 0.6),
        "sigma_depth": (0.5, 1.0, 5.0)}


def images(scenes: int):
    """[(ImageBuffers of one noisy full image, target (H, W, 3))] for every scene and spp level."""
    out = []
    for seed in range(scenes):
        (layers, _), = training_example(seed, SPP_LEVELS, TARGET_SPP, RESOLUTION, RESOLUTION[0], 1)
        for spp in SPP_LEVELS:
            out.append((ImageBuffers(color=layers[f"color_spp{spp}"], variance=layers[f"variance_spp{spp}"],
                                     albedo=layers[f"albedo_spp{spp}"], normal=layers[f"normal_spp{spp}"],
                                     depth=layers[f"depth_spp{spp}"], spp=spp),
                        np.asarray(layers["target"], np.float64)))
    return out


def main(argv=None) -> None:
    from methods.jbf import denoise_image

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--table", action="store_true", help="also print the ten best grid points")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    cases = images(args.scenes)
    rendered = time.perf_counter() - start
    keys = list(GRID)
    scores = []
    for values in itertools.product(*(GRID[k] for k in keys)):
        params = dict(zip(keys, values), radius=RADIUS)
        errors = [relmse(denoise_image(image, **params), target) for image, target in cases]
        scores.append((float(np.mean(errors)), params, errors))
    scores.sort(key=lambda s: s[0])
    noisy = float(np.mean([relmse(image.color, target) for image, target in cases]))
    print(f"{len(cases)} images ({args.scenes} training scenes x spp {SPP_LEVELS}, {RESOLUTION[0]}x"
          f"{RESOLUTION[1]}, target {TARGET_SPP} spp); {len(scores)} grid points; render "
          f"{rendered:.0f} s, total {time.perf_counter() - start:.0f} s")
    print(f"noisy input: mean relMSE {noisy:.5f}")
    if args.table:
        print("| rank | " + " | ".join(keys) + " | mean relMSE | " + " | ".join(f"spp {s}" for s in SPP_LEVELS) + " |")
        print("|---|" + "---|" * (len(keys) + 1 + len(SPP_LEVELS)))
        for rank, (score, params, errors) in enumerate(scores[:10], 1):
            per_spp = [np.mean(errors[i::len(SPP_LEVELS)]) for i in range(len(SPP_LEVELS))]
            print(f"| {rank} | " + " | ".join(f"{params[k]:g}" for k in keys) + f" | {score:.5f} | "
                  + " | ".join(f"{e:.5f}" for e in per_spp) + " |")
    best = scores[0][1]
    print("chosen:", {"radius": RADIUS, **{k: best[k] for k in keys}})


if __name__ == "__main__":
    main()
