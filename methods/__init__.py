"""Method registry: one module per base denoiser or combiner.

A method module declares

* ``KIND``: ``"denoiser"`` or ``"combiner"``;
* ``LABEL``: the name shown in tables (a stand-in says so, e.g. ``"OptiX† (our autoencoder)"``);
* a denoiser: ``denoise(buffers: RenderBuffers, **params) -> Denoised`` returning the denoised
  full image and the two denoised half buffers. Methods that denoise each image on its own use
  :func:`denoise_each_buffer`; methods that compute half-buffer results internally (NFOR, RDFC)
  return them directly.
* a combiner: ``combine(buffers: RenderBuffers, inputs: list[Denoised], **params) -> Denoised``;
  its output may feed another combiner like any base denoiser output.

Adding a method is one new file here plus one line in ``config.yaml``.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType
from typing import Callable

import numpy as np

from mcbench import BenchError
from mcbench.buffers import Denoised, ImageBuffers, RenderBuffers

KINDS = {"denoiser": "denoise", "combiner": "combine"}


class UnknownMethodError(BenchError):
    """A config key names a method that has no module in ``methods/``."""


def available_methods() -> list[str]:
    """Names of the method modules in this package."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def load_method(name: str, kind: str | None = None, config_key: str = "config") -> ModuleType:
    """Import ``methods.<name>`` and check it exposes the interface of ``kind``.

    ``config_key`` is named in the error (e.g. ``"denoisers[2]"``) so a typo in
    ``config.yaml`` is reported where it is.
    """
    if name not in available_methods():
        raise UnknownMethodError(
            f"{config_key}: unknown method '{name}'; available: {', '.join(available_methods())}")
    module = importlib.import_module(f"{__name__}.{name}")
    module_kind = getattr(module, "KIND", None)
    if module_kind not in KINDS:
        raise UnknownMethodError(f"{config_key}: methods/{name}.py declares no valid KIND")
    if kind is not None and module_kind != kind:
        raise UnknownMethodError(f"{config_key}: '{name}' is a {module_kind}, not a {kind}")
    if not callable(getattr(module, KINDS[module_kind], None)):
        raise UnknownMethodError(f"{config_key}: methods/{name}.py lacks {KINDS[module_kind]}()")
    return module


def denoise_each_buffer(buffers: RenderBuffers,
                        denoise_image: Callable[[ImageBuffers], np.ndarray]) -> Denoised:
    """Run a single-image denoiser on the full buffer and on each half buffer.

    Each half buffer is denoised with its own features and variance only, keeping
    y^A independent of x^B as the dual-buffer estimate assumes (Zheng et al. Eq. 10).
    """
    return Denoised(full=denoise_image(buffers.image("full")),
                    a=denoise_image(buffers.image("a")),
                    b=denoise_image(buffers.image("b")))
