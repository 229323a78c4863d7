"""Running a learned method's committed weights on render buffers.

Weights load through :func:`mcbench.weights.load_weights` (``torch.load(..., weights_only=True)``:
plain tensors and the architecture dict, no pickled code; any failure names the file). Inference
runs in float32 with ``torch.use_deterministic_algorithms(True)`` under ``torch.inference_mode``;
with the same thread count the same input gives bit-identical output (tested). A network that
provides ``fuse()`` (WSKPN's RepVGG blocks) is re-parameterised once after loading.

Every function takes the learned method's *module* (``NETWORK``, ``TRAINING``,
``build_network``), never its name: core code does not import ``methods``.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from types import ModuleType

import numpy as np
import torch

from mcbench import BenchError
from mcbench.buffers import Denoised, ImageBuffers, RenderBuffers, denoise_each_buffer
from mcbench.weights import check_learned_method, load_weights, method_name, weights_path


def load_network(module: ModuleType, path: str | Path | None = None) -> torch.nn.Module:
    """The network of learned method ``module`` with the weights in ``path`` (default
    :func:`mcbench.weights.weights_path` of its name), in eval mode; cached per process, module
    and weights file (path and modification time)."""
    check_learned_method(module)
    path = Path(path) if path is not None else weights_path(method_name(module))
    if not path.exists():
        name = method_name(module)
        raise BenchError(f"{path}: weights of '{name}' are missing; train them with "
                         f"`snakemake --cores 2 train_{name}`")
    return _cached_network(module, str(path), path.stat().st_mtime_ns)


@lru_cache(maxsize=None)
def _cached_network(module: ModuleType, path: str, mtime_ns: int) -> torch.nn.Module:
    blob = load_weights(path)
    try:
        network = module.build_network(**blob["arch"])
        network.load_state_dict(blob["state_dict"])
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise BenchError(f"{path}: cannot load weights of '{method_name(module)}' ({exc})") from exc
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


def denoise_with_network(module: ModuleType, buffers: RenderBuffers) -> Denoised:
    """Run the committed network of learned method ``module`` on the full buffer and on each half buffer."""
    network = load_network(module)
    return denoise_each_buffer(buffers, lambda image: run_network(network, image))
