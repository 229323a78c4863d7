"""Joint (cross) bilateral filter guided by colour and features — a classical,
non-learned, feature-guided base denoiser (the JBF family of Kopf et al. 2007 and
McCool 1999 that Zheng et al. 2021 cite; not one of the paper's eight).

Kernel between pixels p and q of a square window (radius ``radius``)::

    κ(p, q) = exp(-|p-q|² / 2σs²) · exp(-D²(x_p, x_q) / 2σc²)
              · exp(-|a_p - a_q|² / 2σa²) · exp(-|n_p - n_q|² / 2σn²) · exp(-(d_p - d_q)² / 2σd²)

with D² the variance-normalised colour distance of Li et al. 2012 (mean over channels of
(x_p - x_q)² / (Var x_p + Var x_q)), albedo a, shading normal n, and depth d divided by the
image's median hit depth (so σd is relative). Each of the full, A and B images is filtered
with its own colour, variance and features. Parameter values are ours (chosen on the
Cornell box at 16-256 spp), not from a paper.
"""

from __future__ import annotations

import numpy as np

from mcbench.filters.bilateral import cross_bilateral_filter
from mcbench.io.buffers import ImageBuffers, RenderBuffers
from methods import denoise_each_buffer
from mcbench.io.method_spec import MethodSpec



def denoise_image(image: ImageBuffers, radius: int = 7, sigma_spatial: float = 4.0,
                  sigma_color: float = 2.0, sigma_albedo: float = 0.1, sigma_normal: float = 0.2,
                  sigma_depth: float = 0.05) -> np.ndarray:
    """Filter one noisy (H, W, 3) radiance image; returns float32 (H, W, 3)."""
    depth = np.asarray(image.depth, dtype=np.float64)
    hits = depth[depth > 0]
    depth_scale = float(np.median(hits)) if hits.size else 1.0
    values = np.moveaxis(np.asarray(image.color, dtype=np.float64), 2, 0)  # (3, H, W)
    filtered = cross_bilateral_filter(
        values, np.asarray(image.color, dtype=np.float64), np.asarray(image.variance, dtype=np.float64),
        [np.asarray(image.albedo, dtype=np.float64), np.asarray(image.normal, dtype=np.float64),
         depth[..., None] / max(depth_scale, 1e-12)],
        [sigma_albedo, sigma_normal, sigma_depth], sigma_spatial, sigma_color, radius)
    return np.moveaxis(filtered, 0, 2).astype(np.float32)


def denoise(buffers: RenderBuffers, *, radius: int = 7, sigma_spatial: float = 4.0,
            sigma_color: float = 2.0, sigma_albedo: float = 0.1, sigma_normal: float = 0.2,
            sigma_depth: float = 0.05):
    """Joint bilateral filtering of the full buffer and of each half buffer."""
    params = dict(radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                  sigma_albedo=sigma_albedo, sigma_normal=sigma_normal, sigma_depth=sigma_depth)
    return denoise_each_buffer(buffers, lambda image: denoise_image(image, **params))


METHOD = MethodSpec(kind="denoiser", label="JBF (joint bilateral)", run=denoise, denoise_image=denoise_image,
                    image_quantities=("color", "variance", "albedo", "normal", "depth"))   # what denoise_image reads
