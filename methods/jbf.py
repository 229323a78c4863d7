"""Joint (cross) bilateral filter guided by colour and features — a classical,
non-learned, feature-guided base denoiser (the JBF family of Kopf et al. 2007 and
McCool 1999 that Zheng et al. 2021 cite; not one of the paper's eight).

Kernel between pixels p and q of a square window (radius ``radius``)::

    κ(p, q) = exp(-|p-q|² / 2σs²) · exp(-D²(x_p, x_q) / 2σc²)
              · exp(-|a_p - a_q|² / 2σa²) · exp(-|n_p - n_q|² / 2σn²) · exp(-(d_p - d_q)² / 2σd²)

with D² the variance-normalised colour distance of Li et al. 2012 (mean over channels of
(x_p - x_q)² / (Var x_p + Var x_q)), albedo a, shading normal n, and depth d divided by the
image's median hit depth (so σd is relative). Each of the full, A and B images is filtered
with its own colour, variance and features.

Constants (radius 7 px, σs 4 px, σc 0.5, σa 1.0, σn 0.3, σd 1.0): no paper or public code gives
constants for this kernel on radiance (SBF's cross-bilateral filter, Li et al. 2012, fbksd-
package 3059e14 denoisers/SBF, divides feature distances by the features' variance
(CrossBilateralFilter.cpp:48), has no colour term (c_SigmaC = 0, sbf.cpp:52) and picks σs per
pixel by SURE), so they were chosen on training scenes, never on the test scenes: a grid search
(``nice -n 10 python tools/jbf_constants.py --table``, ~1.5 min on one core) over 8 procedural
training scenes (mcbench.training_data, object-family seeds 0-7) at 64 x 64 with 4, 16 and 64
spp, lowest mean relMSE against their 1024-spp targets (0.0727; the noisy inputs 0.632). The
albedo and depth terms barely matter there (σa 0.5-2 and σd 0.5-5 all within 2e-5 of the best).
The radius is not searched (7, as the ensemble's filter, Sec. 4.2).
The grid and its output: docs/methods.md (JBF).
"""

from __future__ import annotations

import numpy as np

from mcbench.filters.bilateral import cross_bilateral_filter
from mcbench.io.buffers import ImageBuffers, RenderBuffers
from methods import denoise_each_buffer
from mcbench.contracts.method import MethodSpec



def denoise_image(image: ImageBuffers, radius: int = 7, sigma_spatial: float = 4.0,
                  sigma_color: float = 0.5, sigma_albedo: float = 1.0, sigma_normal: float = 0.3,
                  sigma_depth: float = 1.0) -> np.ndarray:
    """Filter one noisy (H, W, 3) radiance image (the module docstring's kernel; radius and
    σs in pixels, σc unitless, σa and σn in the features' units, σd relative to the median hit
    depth); returns float32 (H, W, 3)."""
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
            sigma_color: float = 0.5, sigma_albedo: float = 1.0, sigma_normal: float = 0.3,
            sigma_depth: float = 1.0):
    """Joint bilateral filtering of the full buffer and of each half buffer."""
    params = dict(radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                  sigma_albedo=sigma_albedo, sigma_normal=sigma_normal, sigma_depth=sigma_depth)
    return denoise_each_buffer(buffers, lambda image: denoise_image(image, **params))


METHOD = MethodSpec(kind="denoiser", label="JBF (joint bilateral)", run=denoise, denoise_image=denoise_image,
                    image_quantities=("color", "variance", "albedo", "normal", "depth"))   # what denoise_image reads
