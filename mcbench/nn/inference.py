"""Running a learned method's committed weights on render buffers.

Weights load through :func:`mcbench.io.weights.load_weights` (``torch.load(..., weights_only=True)``:
plain tensors and the architecture dict, no pickled code; any failure names the file). Inference
runs in float32 with ``torch.use_deterministic_algorithms(True)`` under ``torch.inference_mode``;
with the same thread count the same input gives bit-identical output (tested). A network that
provides ``fuse()`` (WSKPN's RepVGG blocks) is re-parameterised once after loading.

Every function takes the learned method's *module* (its declaration ``METHOD``,
:func:`mcbench.io.method_spec.method_spec`: ``network``, ``build_network``, ...), never its name:
core code does not import ``methods``.
"""

from __future__ import annotations

import sys

from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from types import ModuleType

import numpy as np
import torch

from mcbench import BenchError
from mcbench.io.buffers import BUFFER_SUFFIXES, Denoised, ImageBuffers, RenderBuffers, denoise_each_buffer
from mcbench.io.method_spec import method_spec
from mcbench.io.weights import check_learned_method, load_weights, method_name, weights_path


def load_network(module: ModuleType, path: str | Path | None = None) -> torch.nn.Module:
    """The network of learned method ``module`` with the weights in ``path`` (default
    :func:`mcbench.io.weights.weights_path` of its name), in eval mode; cached per process, module
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
        network = method_spec(module).build_network(**blob["arch"])
        network.load_state_dict(blob["state_dict"])
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise BenchError(f"{path}: cannot load weights of '{method_name(module)}' ({exc})") from exc
    network.eval()
    if hasattr(network, "fuse"):
        network.fuse()
    return network


def image_tensors(image: ImageBuffers) -> dict[str, torch.Tensor]:
    """One image's buffers as (1, C, H, W) float32 tensors keyed like :data:`mcbench.nn.crops.BUFFER_KEYS`."""
    return {"color": array_tensor(image.color), "variance": array_tensor(image.variance),
            "albedo": array_tensor(image.albedo), "normal": array_tensor(image.normal),
            "depth": array_tensor(image.depth)}


def set_deterministic_algorithms(mode: bool) -> None:
    """``torch.use_deterministic_algorithms(mode)`` without its import of ``torch._inductor`` (seconds
    per process, for a compiler mcbench never runs): torch 2.13's function sets the flag in
    ``torch._C`` and inductor's copy of it; the copy is set too when inductor is loaded already."""
    if "torch._inductor.config" in sys.modules:
        torch.use_deterministic_algorithms(mode)
    else:
        torch._C._set_deterministic_algorithms(mode)


@contextmanager
def deterministic_inference():
    """``torch.inference_mode`` with deterministic algorithms (the previous setting restored)."""
    previous = torch.are_deterministic_algorithms_enabled()
    set_deterministic_algorithms(True)
    try:
        with torch.inference_mode():
            yield
    finally:
        set_deterministic_algorithms(previous)


def tensor_image(tensor: torch.Tensor) -> np.ndarray:
    """The first image of an (N, C, H, W) tensor as an (H, W, C) float32 array."""
    return np.ascontiguousarray(tensor[0].permute(1, 2, 0).numpy(), dtype=np.float32)


def run_network(network: torch.nn.Module, image: ImageBuffers) -> np.ndarray:
    """Denoise one image: (H, W, 3) float32 linear radiance."""
    return run_network_on(network, image_tensors(image))


def denoise_with_network(module: ModuleType, buffers: RenderBuffers) -> Denoised:
    """Run the committed network of learned method ``module`` on the full buffer and on each half buffer."""
    network = load_network(module)
    return denoise_each_buffer(buffers, lambda image: run_network(network, image))


# ---------------------------------------------------------------------------------------------
# Combiners: networks whose forward also takes a base's result (and sub-buffers) of the image.

FEATURE_VARIANCES = ("albedo_variance", "normal_variance", "depth_variance")
COMBINER_KEYS = FEATURE_VARIANCES + ("correlated", "color_sub", "variance_sub", "correlated_sub")


def array_tensor(array: np.ndarray) -> torch.Tensor:
    """(H, W) or (H, W, C) array -> (1, C, H, W) float32 tensor."""
    array = np.asarray(array, dtype=np.float32)
    array = array[None] if array.ndim == 2 else np.moveaxis(array, 2, 0)
    return torch.from_numpy(np.ascontiguousarray(array))[None]


def combiner_image_tensors(buffers: RenderBuffers, inputs: list[Denoised], which: str,
                           keys: dict[str, int]) -> dict[str, torch.Tensor]:
    """The tensors a combiner network needs on image ``which`` (``"full"``, ``"a"``, ``"b"``):
    :func:`image_tensors` of ``buffers.image(which)`` plus each of ``keys`` (name -> channels,
    a declaration's ``training_keys``; names in :data:`COMBINER_KEYS`), all (1, C, H, W) float32:

    * ``correlated`` -- ``inputs[0].image(which)``, the base's result on this image;
    * ``albedo_variance``, ``normal_variance``, ``depth_variance`` -- the render's layers of this
      image (suffix ``""``, ``"_a"``, ``"_b"``);
    * ``color_sub``, ``variance_sub`` -- the image's two sub-buffers
      (:meth:`RenderBuffers.sub_images`) concatenated along channels;
    * ``correlated_sub`` -- the base's results on them (:meth:`Denoised.sub_outputs`), concatenated.

    Only this image's samples enter: A's tensors come from A's layers and A's results alone.
    Errors (:class:`BenchError`) name the file: a missing layer, bins or sub-buffer results, an
    input of another size, a key that is unknown or has another channel count.
    """
    image = buffers.image(which)
    tensors = image_tensors(image)
    for key, channels in keys.items():
        arrays, source = _combiner_arrays(buffers, inputs, which, key)
        for array in arrays:
            if np.shape(array)[:2] != image.shape:
                raise BenchError(f"{source}: '{key}' of image '{which}' is {np.shape(array)}, but the render "
                                 f"{buffers.source} is {image.shape}")
        tensor = torch.cat([array_tensor(array) for array in arrays], dim=1)
        if tensor.shape[1] != channels:
            raise BenchError(f"{source}: '{key}' of image '{which}' has {tensor.shape[1]} channels, "
                             f"the network expects {channels}")
        tensors[key] = tensor
    return tensors


def _combiner_arrays(buffers: RenderBuffers, inputs: list[Denoised], which: str,
                     key: str) -> tuple[list[np.ndarray], str]:
    """The (H, W[, C]) arrays behind combiner input ``key`` of image ``which`` and the file they come from."""
    if key in ("correlated", "correlated_sub"):
        if not inputs:
            raise BenchError(f"combiner input '{key}' needs a base denoiser's result; got no inputs")
        base = inputs[0]
        return ([base.image(which)] if key == "correlated" else list(base.sub_outputs(which))), base.source
    if key in FEATURE_VARIANCES:
        layer = key + BUFFER_SUFFIXES[which]
        if layer not in buffers.layers:
            raise BenchError(f"{buffers.source}: no layer '{layer}' (feature variances are written by "
                             f"mcbench.render.renderer; re-render this file)")
        return [buffers.layers[layer]], buffers.source
    if key in ("color_sub", "variance_sub"):
        part = 0 if key == "color_sub" else 1
        return [sub[part] for sub in buffers.sub_images(which)], buffers.source
    raise BenchError(f"unknown combiner input '{key}'; known: {', '.join(COMBINER_KEYS)}")


def run_network_on(network: torch.nn.Module, tensors: dict[str, torch.Tensor]) -> np.ndarray:
    """``network(tensors)`` of one image (batch of 1), deterministic like :func:`run_network`:
    (H, W, 3) float32 linear radiance."""
    with deterministic_inference():
        return tensor_image(network(tensors))


def combine_with_network(module: ModuleType, buffers: RenderBuffers, inputs: list[Denoised], *,
                         network: torch.nn.Module | None = None) -> Denoised:
    """Run the combiner network of learned method ``module`` (its ``inputs``, ``training_keys``) on
    the full image and on each half buffer, each from its own samples and ``inputs``' results on
    that image (:func:`combiner_image_tensors`). ``network`` defaults to the committed weights
    (:func:`load_network`, loaded only after every input is checked). The result is float32 and
    finite (a non-finite output is a :class:`BenchError` naming the method)."""
    name = method_name(module)
    spec = method_spec(module)
    expected = spec.inputs or 1
    if len(inputs) != expected:
        raise BenchError(f"{name} combines exactly {expected} input(s), got {len(inputs)}")
    tensors = {which: combiner_image_tensors(buffers, inputs, which, spec.training_keys)
               for which in BUFFER_SUFFIXES}
    network = load_network(module) if network is None else network
    results = {which: run_network_on(network, tensors[which]) for which in BUFFER_SUFFIXES}
    for which, result in results.items():
        if not np.isfinite(result).all():
            raise BenchError(f"{name}: non-finite output on image '{which}' of {buffers.source}")
    return Denoised(full=results["full"], a=results["a"], b=results["b"])
