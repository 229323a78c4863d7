"""Inference time of the learned denoisers per image, as a ratio to OIDN measured in the same run.

Renders (or reads) one test scene at 64 spp, then times one image (the full buffer) per method:
OIDN (the baseline), KPCN, MCGAN, the OptiX-stand-in autoencoder and WSKPN, at the given sizes
and thread counts. Network weights are loaded once before timing (load time excluded), and the
best of ``--repeats`` runs is kept (these machines are shared and noisy). ``--threads`` sets
PyTorch's threads; OIDN (``pyoidn.denoise``) always uses its own pool over all cores.

    .venv/bin/python benchmarks/bench_learned.py [--sizes 128 256] [--threads 1 2] [--repeats 3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import torch  # noqa: E402

from mcbench.io.buffers import RenderBuffers  # noqa: E402
from mcbench.io.weights import COMMITTED_WEIGHTS, weights_path  # noqa: E402
from mcbench.nn.inference import load_network, run_network  # noqa: E402
from mcbench.render.renderer import render_buffers  # noqa: E402
from methods import load_method, oidn  # noqa: E402
from scenes import load_scene  # noqa: E402
from timing import timed  # noqa: E402

NETWORKS = ["kpcn", "mcgan", "optix_ae", "wskpn"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="cornell_box")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    networks = {name: load_network(load_method(name).METHOD, weights_path(COMMITTED_WEIGHTS, name)) for name in NETWORKS}
    print(f"{'size':>5} {'threads':>7} {'method':>9} {'seconds':>9} {'vs OIDN':>8}")
    for size in args.sizes:
        layers, _ = render_buffers(load_scene(args.scene), args.spp, resolution=(size, size))
        image = RenderBuffers(layers=layers, spp=args.spp).image("full")
        for threads in args.threads:
            torch.set_num_threads(threads)
            run_network(networks["kpcn"], image)  # warm-up of oneDNN primitives
            baseline, _ = timed(lambda: oidn.denoise_image(image), args.repeats)
            print(f"{size:>5} {threads:>7} {'oidn':>9} {baseline:>9.3f} {1.0:>8.2f}", flush=True)
            for name, network in networks.items():
                seconds, _ = timed(lambda: run_network(network, image), args.repeats)
                print(f"{size:>5} {threads:>7} {name:>9} {seconds:>9.3f} {seconds / baseline:>8.2f}", flush=True)


if __name__ == "__main__":
    main()
