"""Running a learned method's network on render buffers: the inference every learned plugin shares.

Weights load through :func:`mcbench.io.weights.load_weights` (``torch.load(..., weights_only=True)``:
plain tensors and the architecture dict, no pickled code; any failure names the file). Inference
runs in float32 with ``torch.use_deterministic_algorithms(True)`` under ``torch.inference_mode``;
with the same thread count the same input gives bit-identical output (tested). A network that
provides ``fuse()`` (WSKPN's RepVGG blocks) is re-parameterised once after loading.

Every function takes the learned method's declaration (``METHOD``, a
:class:`mcbench.contracts.method.MethodSpec` with ``learned``) and the weights file its runner
passed (``weights_file``, ``<weights_dir>/<name>.pt``), never its name: core code does not import
``methods``. A plugin's ``run`` is then one call: ``denoise_with_network(METHOD, buffers, weights_file)``
(a denoiser, each image on its own) or ``combine_with_network(METHOD, buffers, inputs, weights_file)``.
"""

from __future__ import annotations

import sys

from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from mcbench import BenchError
from mcbench.io.buffers import BUFFER_SUFFIXES, Denoised, ImageBuffers, RenderBuffers, denoise_each_buffer
from mcbench.contracts.method import MethodSpec
from mcbench.io.weights import load_weights


def load_network(spec: MethodSpec, weights_file: str | Path) -> torch.nn.Module:
    """The network of learned method ``spec`` with the weights in ``weights_file``
    (``<weights_dir>/<name>.pt``), in eval mode; cached per process, declaration and weights file
    (path and modification time)."""
    path = Path(weights_file)
    if spec.learned is None:
        raise BenchError(f"{path}: '{spec.label}' is not a learned method (its METHOD declares no learned=)")
    if not path.exists():
        raise BenchError(f"{path}: weights of '{path.stem}' are missing; train them with "
                         f"`snakemake --cores 2 train_{path.stem}` or fix weights_dir")
    return _cached_network(spec, str(path), path.stat().st_mtime_ns)


@lru_cache(maxsize=None)
def _cached_network(spec: MethodSpec, path: str, mtime_ns: int) -> torch.nn.Module:
    blob = load_weights(path)
    try:
        network = spec.learned.build_network(**blob["arch"])
        network.load_state_dict(blob["state_dict"])
    except (RuntimeError, KeyError, TypeError, ValueError) as exc:
        raise BenchError(f"{path}: cannot load weights of '{Path(path).stem}' ({exc})") from exc
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


def image_function(spec: MethodSpec, weights_file: str | Path) -> Callable[[ImageBuffers], np.ndarray]:
    """Learned denoiser ``spec`` with the weights ``weights_file`` as a function of one image ->
    (H, W, 3) float32 radiance (:func:`run_network`)."""
    network = load_network(spec, weights_file)
    return lambda image: run_network(network, image)


def denoise_with_network(spec: MethodSpec, buffers: RenderBuffers, weights_file: str | Path) -> Denoised:
    """Run the network of learned denoiser ``spec`` (weights ``weights_file``) on the full buffer
    and on each half buffer."""
    return denoise_each_buffer(buffers, image_function(spec, weights_file))


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


def combine_with_network(spec: MethodSpec, buffers: RenderBuffers, inputs: list[Denoised],
                         weights_file: str | Path | None = None, *,
                         network: torch.nn.Module | None = None) -> Denoised:
    """Run the combiner network of learned method ``spec`` (its ``inputs``, ``training_keys``) on
    the full image and on each half buffer, each from its own samples and ``inputs``' results on
    that image (:func:`combiner_image_tensors`). ``network`` defaults to the weights
    ``weights_file`` (:func:`load_network`, loaded only after every input is checked). The result
    is float32 and finite (a non-finite output is a :class:`BenchError` naming the method)."""
    name = Path(weights_file).stem if weights_file is not None else spec.label
    expected = spec.inputs or 1
    if len(inputs) != expected:
        raise BenchError(f"{name} combines exactly {expected} input(s), got {len(inputs)}")
    tensors = {which: combiner_image_tensors(buffers, inputs, which, spec.learned.training_keys)
               for which in BUFFER_SUFFIXES}
    network = load_network(spec, weights_file) if network is None else network
    results = {which: run_network_on(network, tensors[which]) for which in BUFFER_SUFFIXES}
    for which, result in results.items():
        if not np.isfinite(result).all():
            raise BenchError(f"{name}: non-finite output on image '{which}' of {buffers.source}")
    return Denoised(full=results["full"], a=results["a"], b=results["b"])
