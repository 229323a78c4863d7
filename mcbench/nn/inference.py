"""Running a learned method's committed weights on render buffers.

Weights load with ``torch.load(..., weights_only=True)`` (plain tensors and the architecture
dict, no pickled code). Inference runs in float32 with
``torch.use_deterministic_algorithms(True)`` under ``torch.inference_mode``; with the same
thread count the same input gives bit-identical output (tested). A network that provides
``fuse()`` (WSKPN's RepVGG blocks) is re-parameterised once after loading.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch

from mcbench import BenchError
from mcbench.buffers import Denoised, ImageBuffers, RenderBuffers


def load_network(name: str) -> torch.nn.Module:
    """The network of ``methods/<name>.py`` with its weights (:func:`mcbench.nn.train.weights_path`),
    in eval mode; cached per process and weights file."""
    from mcbench.nn.train import weights_path

    return _load_network(name, str(weights_path(name)))


@lru_cache(maxsize=None)
def _load_network(name: str, path: str) -> torch.nn.Module:
    from pathlib import Path

    from mcbench.nn.train import learned_method

    module = learned_method(name)
    path = Path(path)
    if not path.exists():
        raise BenchError(f"{path}: weights of '{name}' are missing; train them with "
                         f"`snakemake --cores 2 train_{name}`")
    try:
        blob = torch.load(path, weights_only=True, map_location="cpu")
        network = module.build_network(**blob["arch"])
        network.load_state_dict(blob["state_dict"])
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise BenchError(f"{path}: cannot load weights of '{name}' ({exc})") from exc
    network.eval()
    if hasattr(network, "fuse"):
        network.fuse()
    return network


def image_tensors(image: ImageBuffers) -> dict[str, torch.Tensor]:
    """One image's buffers as (1, C, H, W) float32 tensors keyed like :data:`mcbench.nn.data.BUFFER_KEYS`."""
    def tensor(array):
        array = np.asarray(array, dtype=np.float32)
        array = array[None] if array.ndim == 2 else np.moveaxis(array, 2, 0)
        return torch.from_numpy(np.ascontiguousarray(array))[None]

    return {"color": tensor(image.color), "variance": tensor(image.variance), "albedo": tensor(image.albedo),
            "normal": tensor(image.normal), "depth": tensor(image.depth)}


def run_network(network: torch.nn.Module, image: ImageBuffers) -> np.ndarray:
    """Denoise one image: (H, W, 3) float32 linear radiance."""
    previous = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True)
    try:
        with torch.inference_mode():
            output = network(image_tensors(image))
    finally:
        torch.use_deterministic_algorithms(previous)
    return np.ascontiguousarray(output[0].permute(1, 2, 0).numpy(), dtype=np.float32)


def denoise_with_network(name: str, buffers: RenderBuffers) -> Denoised:
    """Run the committed network ``name`` on the full buffer and on each half buffer."""
    from methods import denoise_each_buffer

    network = load_network(name)
    return denoise_each_buffer(buffers, lambda image: run_network(network, image))
