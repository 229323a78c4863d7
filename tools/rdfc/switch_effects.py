"""relMSE of methods.rdfc.denoise with each of its switches, for docs/fidelity_rdfc.md ("Measured
effects of the switches"): prints a Markdown table.

    NUMBA_NUM_THREADS=1 nice -n 10 .venv/bin/python tools/rdfc/switch_effects.py [--cache /tmp/rdfc]

Renders (one thread, seed 0, 128x128): ``render_buffers(load_scene(scene), spp, resolution=(128, 128),
seed=0, threads=1)`` for each scene and spp, and one reference chunk of ``--ref-spp`` samples
(``render_reference_chunk(scene, ref_spp, 0)`` merged by ``merge_reference_chunks``; not the study's
references, so absolute values differ from docs/measurements.md). With ``--cache`` the renders are
kept as .npz files there and reused. Metric: :func:`mcbench.analysis.metrics.relmse` of the full image.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mcbench.analysis.metrics import relmse
from mcbench.io.buffers import RenderBuffers
from methods import rdfc

RESOLUTION = (128, 128)
CASES = (("cornell_box", 4), ("cornell_box", 64), ("veach_ajar", 4), ("veach_ajar", 64),
         ("glass_caustics", 4), ("glass_caustics", 64))
#: (column title, keyword arguments of denoise)
SWITCHES = (("default", {}), ('`variance="raw"`', {"variance": "raw"}),
            ("`clamp_derivative=False`", {"clamp_derivative": False}), ("`index_bug=False`", {"index_bug": False}),
            ("`radius=20`", {"radius": 20}), ("`symmetric_weights=False`", {"symmetric_weights": False}))


def _cached(path: Path | None, make):
    if path is not None and path.exists():
        return dict(np.load(path))
    layers = {k: np.asarray(v) for k, v in make().items()}
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **layers)
    return layers


def noisy_buffers(scene: str, spp: int, cache: Path | None) -> RenderBuffers:
    from mcbench.pipeline.registry import load_scene
    from mcbench.render.renderer import render_buffers

    path = None if cache is None else cache / f"{scene}_{RESOLUTION[0]}_spp{spp}.npz"
    layers = _cached(path, lambda: render_buffers(load_scene(scene), spp, resolution=RESOLUTION, seed=0,
                                                  threads=1)[0])
    return RenderBuffers(layers=layers, spp=spp)


def reference(scene: str, ref_spp: int, cache: Path | None) -> np.ndarray:
    from mcbench.pipeline.registry import load_scene
    from mcbench.render.renderer import merge_reference_chunks, render_reference_chunk

    def make():
        chunk = render_reference_chunk(load_scene(scene), ref_spp, 0, resolution=RESOLUTION, seed=0, threads=1)
        return {"color": merge_reference_chunks([chunk])[0]["color"]}

    path = None if cache is None else cache / f"{scene}_{RESOLUTION[0]}_ref{ref_spp}.npz"
    return np.asarray(_cached(path, make)["color"], dtype=np.float64)


def _fmt(x: float) -> str:
    return f"{x:#.3g}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--cache", type=Path, default=None, help="folder for the renders (.npz), reused if present")
    ap.add_argument("--cases", default=",".join(f"{s}:{n}" for s, n in CASES),
                    help="comma-separated scene:spp (default: the six of the table)")
    args = ap.parse_args(argv)
    cases = [(c.split(":")[0], int(c.split(":")[1])) for c in args.cases.split(",")]
    rows = []
    refs = {}
    for scene, spp in cases:
        t = time.perf_counter()
        buffers = noisy_buffers(scene, spp, args.cache)
        if scene not in refs:
            refs[scene] = reference(scene, args.ref_spp, args.cache)
        ref = refs[scene]
        row = [f"{scene} {spp}", _fmt(relmse(buffers.layers["color"], ref))]
        for i, (_, kw) in enumerate(SWITCHES):
            value = _fmt(relmse(rdfc.denoise(buffers, **kw).full, ref))
            row.append(f"**{value}**" if i == 0 else value)
        rows.append(row)
        print(f"# {scene} {spp} spp: {time.perf_counter() - t:.0f} s", flush=True)
    print("| scene, spp | noisy | " + " | ".join(title for title, _ in SWITCHES) + " |")
    print("|---" * (2 + len(SWITCHES)) + "|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
