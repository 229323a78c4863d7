"""Render buffers shared by every method: the noisy full image, the two independent
half-sample buffers A and B, their per-pixel variances and the auxiliary features.

Conventions (all arrays float32, linear HDR radiance, row-major (H, W[, 3])):

* ``color = (color_a + color_b) / 2``; A and B hold spp/2 disjoint samples each.
* ``variance*`` is the per-pixel, per-channel variance *of the mean* (sample variance / n).
* ``albedo`` (H, W, 3) in [0, 1], ``normal`` (H, W, 3) shading normal in [-1, 1] (zero where
  no surface was hit), ``depth`` (H, W) distance along the camera ray (zero where no hit).
* Features come in full/A/B versions too, so a half-buffer denoise sees only its own samples
  (the dual-buffer estimate of the ensemble, Zheng et al. 2021 Eq. 10, assumes it).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from mcbench.exr import check_finite, read_layers, read_metadata

BUFFER_SUFFIXES = {"full": "", "a": "_a", "b": "_b"}
QUANTITIES = ("color", "variance", "albedo", "normal", "depth",
              "albedo_variance", "normal_variance", "depth_variance")
# Layers every render must hold (the list); the rest are optional extras.
REQUIRED_LAYERS = ("color", "color_a", "color_b", "variance", "variance_a", "variance_b",
                   "albedo", "normal", "depth")
ALL_LAYERS = tuple(q + s for q in QUANTITIES for s in BUFFER_SUFFIXES.values())


@dataclass(frozen=True)
class ImageBuffers:
    """One noisy image (full, A or B) with its variance and features."""

    color: np.ndarray      # (H, W, 3)
    variance: np.ndarray   # (H, W, 3) variance of the mean
    albedo: np.ndarray     # (H, W, 3)
    normal: np.ndarray     # (H, W, 3)
    depth: np.ndarray      # (H, W)
    spp: float             # samples behind this image

    @property
    def shape(self) -> tuple[int, int]:
        return self.color.shape[:2]


@dataclass(frozen=True)
class RenderBuffers:
    """All layers of one (scene, spp) render; ``layers`` maps layer name to array."""

    layers: dict
    spp: int
    source: str = "<memory>"

    def __getattr__(self, name):  # buffers.color_a, buffers.variance, ...
        layers = self.__dict__.get("layers", {})
        if name in layers:
            return layers[name]
        raise AttributeError(name)

    @property
    def shape(self) -> tuple[int, int]:
        return self.layers["color"].shape[:2]

    def image(self, which: str) -> ImageBuffers:
        """The full (``"full"``) or half (``"a"``/``"b"``) image with its own features.

        Half-buffer features fall back to the full-buffer ones when the render lacks them.
        """
        suffix = BUFFER_SUFFIXES[which]

        def get(q):
            return self.layers.get(q + suffix, self.layers[q])

        return ImageBuffers(color=get("color"), variance=get("variance"), albedo=get("albedo"),
                            normal=get("normal"), depth=get("depth"),
                            spp=self.spp if which == "full" else self.spp / 2)

    @classmethod
    def load(cls, path: str | Path) -> "RenderBuffers":
        """Read a render EXR, refusing missing layers or NaN/Inf pixels (errors name the file)."""
        path = Path(path)
        layers = read_layers(path)
        missing = [n for n in REQUIRED_LAYERS if n not in layers]
        if missing:
            from mcbench.exr import ExrError
            raise ExrError(f"{path}: not a render file, missing layer(s) {missing}")
        check_finite(path, layers)
        meta = read_metadata(path)
        spp = int(meta.get("spp", 0))
        return cls(layers=layers, spp=spp, source=str(path))


@dataclass(frozen=True)
class Denoised:
    """A method's output: denoised full image and the denoised half buffers A and B."""

    full: np.ndarray  # (H, W, 3)
    a: np.ndarray
    b: np.ndarray
    extras: dict | None = None  # optional named layers (weight maps, selection maps, ...)

    def layers(self) -> dict[str, np.ndarray]:
        out = {"color": self.full, "color_a": self.a, "color_b": self.b}
        out.update(self.extras or {})
        return out

    @classmethod
    def load(cls, path: str | Path) -> "Denoised":
        path = Path(path)
        layers = read_layers(path, ["color", "color_a", "color_b"])
        check_finite(path, layers)
        return cls(full=layers["color"], a=layers["color_a"], b=layers["color_b"])


def denoise_each_buffer(buffers: RenderBuffers,
                        denoise_image: Callable[[ImageBuffers], np.ndarray]) -> Denoised:
    """Run a single-image denoiser on the full buffer and on each half buffer.

    Each half buffer is denoised with its own features and variance only, keeping
    y^A independent of x^B as the dual-buffer estimate assumes (Zheng et al. Eq. 10).
    """
    return Denoised(full=denoise_image(buffers.image("full")),
                    a=denoise_image(buffers.image("a")),
                    b=denoise_image(buffers.image("b")))
