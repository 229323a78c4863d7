"""Intel Open Image Denoise (#6 OIDN in Zheng et al. 2021), through ``pyoidn``.

The ``RT`` filter in HDR mode with albedo and normal auxiliary images. Our features are
per-pixel sample means, noisy where the first hit is (depth of field, glass), so OIDN is
told they are not clean (``clean_aux=False``) and prefilters them itself. Each of the full,
A and B images is denoised with its own features, as the paper runs OIDN three times.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from mcbench.io.buffers import ImageBuffers, RenderBuffers
from methods import denoise_each_buffer
from mcbench.contracts.method import MethodSpec

Quality = Literal["high", "balanced", "fast", "default"]   # OIDN's filter qualities


def denoise_image(image: ImageBuffers, *, quality: Quality = "high") -> np.ndarray:
    """Denoise one (H, W, 3) HDR image with OIDN's RT filter; returns float32 (H, W, 3)."""
    import pyoidn

    color = np.ascontiguousarray(np.maximum(image.color, 0.0), dtype=np.float32)
    albedo = np.ascontiguousarray(np.clip(image.albedo, 0.0, 1.0), dtype=np.float32)
    normal = np.ascontiguousarray(np.clip(image.normal, -1.0, 1.0), dtype=np.float32)
    return pyoidn.denoise(color, albedo=albedo, normal=normal, hdr=True, quality=quality)


def denoise(buffers: RenderBuffers, *, quality: Quality = "high"):
    """OIDN on the full buffer and on each half buffer."""
    return denoise_each_buffer(buffers, lambda image: denoise_image(image, quality=quality))


METHOD = MethodSpec(kind="denoiser", label="#6 OIDN", run=denoise, denoise_image=denoise_image,
                    image_quantities=("color", "albedo", "normal"))   # what denoise_image reads of each image
