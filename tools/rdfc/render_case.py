"""Render one scene's 4-spp buffers and a reference for the RDFC investigation (docs/fidelity_rdfc.md).

    .venv/bin/python tools/rdfc/render_case.py glass_caustics --spp 4 --ref-spp 4096 --out /tmp/rdfc

Writes OUT/{scene}_spp{N}.npz (every render layer, float32) and OUT/{scene}_ref{M}.npz (reference
colour and its per-pixel variance of the mean) unless they exist. One thread, seed 0, the scene's
resolution (128x128 for the default scenes).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def case_arguments(description: str) -> argparse.ArgumentParser:
    """The case's arguments shared by the RDFC tools: scene, --spp, --ref-spp, --out."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("scene")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--out", type=Path, default=Path("/tmp/rdfc"))
    return ap


def main(argv=None):
    args = case_arguments(__doc__.splitlines()[0]).parse_args(argv)
    from mcbench.pipeline.registry import load_scene
    from mcbench.render.renderer import render_buffers, render_reference_chunk

    args.out.mkdir(parents=True, exist_ok=True)
    noisy = args.out / f"{args.scene}_spp{args.spp}.npz"
    ref = args.out / f"{args.scene}_ref{args.ref_spp}.npz"
    if not noisy.exists():
        t = time.perf_counter()
        layers, _ = render_buffers(load_scene(args.scene), args.spp, seed=0, threads=1)
        np.savez_compressed(noisy, **{k: np.asarray(v) for k, v in layers.items()})
        print(f"{noisy}: {time.perf_counter() - t:.1f} s")
    if not ref.exists():
        t = time.perf_counter()
        layers, _ = render_reference_chunk(load_scene(args.scene), args.ref_spp, 0, seed=0, threads=1)
        color = np.asarray(layers["color"], dtype=np.float64)
        var = np.maximum(np.asarray(layers["color_m2"], dtype=np.float64) - color ** 2, 0) / args.ref_spp
        np.savez_compressed(ref, color=color.astype(np.float32), variance=var.astype(np.float32))
        print(f"{ref}: {time.perf_counter() - t:.1f} s")


if __name__ == "__main__":
    main()
