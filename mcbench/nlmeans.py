"""Non-local means with variance cancellation (Rousselle, Knaus and Zwicker 2012), the
filter NFOR and RDFC use to prefilter features and to weight colours.

For pixels p and q = p + o and a patch P of radius ``patch_radius`` the distance is

    d²(p, q) = mean over n in P and channels c of
               [(u(p+n) - u(q+n))² - α (Var(p+n) + min(Var(p+n), Var(q+n)))]
               / (ε + k² (Var(p+n) + Var(q+n)))                                  (RKZ12 Eq. 5-6)

and the weight is w(p, q) = exp(-max(0, d²)). The filtered value is the w-weighted mean over
the (2·radius + 1)² window, clipped at image borders. ``guide`` may differ from the filtered
``values`` (cross filtering, e.g. weights from buffer B applied to buffer A).

Vectorised over the image, one window offset at a time; patch sums use
``scipy.ndimage.uniform_filter`` (edge mode "nearest"). Accumulation in float64.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

__all__ = ["nl_means_filter", "nl_means_weight_maps"]


def _shifted(array: np.ndarray, dy: int, dx: int) -> tuple[np.ndarray, np.ndarray]:
    """``array`` sampled at (y + dy, x + dx) with edge replication, and the validity mask."""
    h, w = array.shape[:2]
    ys = np.clip(np.arange(h) + dy, 0, h - 1)
    xs = np.clip(np.arange(w) + dx, 0, w - 1)
    valid = ((np.arange(h) + dy >= 0) & (np.arange(h) + dy < h))[:, None] & \
            ((np.arange(w) + dx >= 0) & (np.arange(w) + dx < w))[None, :]
    return array[ys][:, xs], valid


def nl_means_weight_maps(guide: np.ndarray, guide_variance: np.ndarray, radius: int, patch_radius: int,
                         k: float, alpha: float = 1.0, epsilon: float = 1e-10):
    """Yield ``(dy, dx, weight, valid)`` for every window offset: weight (H, W) = w(p, p + o).

    guide, guide_variance: (H, W, C) float arrays; the variance is per pixel and channel.
    """
    guide = np.asarray(guide, dtype=np.float64)
    variance = np.maximum(np.asarray(guide_variance, dtype=np.float64), 0.0)
    if guide.ndim == 2:
        guide, variance = guide[..., None], variance[..., None]
    if guide.shape != variance.shape:
        raise ValueError(f"guide {guide.shape} and guide_variance {variance.shape} differ in shape")
    size = 2 * patch_radius + 1
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            shifted, valid = _shifted(guide, dy, dx)
            shifted_variance, _ = _shifted(variance, dy, dx)
            numerator = (guide - shifted) ** 2 - alpha * (variance + np.minimum(variance, shifted_variance))
            distance = (numerator / (epsilon + k * k * (variance + shifted_variance))).mean(axis=2)
            if patch_radius > 0:
                distance = uniform_filter(distance, size=size, mode="nearest")
            weight = np.exp(-np.maximum(distance, 0.0))
            weight[~valid] = 0.0
            yield dy, dx, weight, valid


def nl_means_filter(values: np.ndarray, guide: np.ndarray, guide_variance: np.ndarray, radius: int = 5,
                    patch_radius: int = 3, k: float = 0.5, alpha: float = 1.0, epsilon: float = 1e-10) -> np.ndarray:
    """NL-means filter ``values`` (H, W, K) or (H, W) with weights computed on ``guide``.

    Returns float64 of the same shape as ``values``. The centre weight is 1, so the
    normalisation never divides by zero.
    """
    values = np.asarray(values, dtype=np.float64)
    squeeze = values.ndim == 2
    if squeeze:
        values = values[..., None]
    if values.shape[:2] != np.shape(guide)[:2]:
        raise ValueError(f"values {values.shape[:2]} and guide {np.shape(guide)[:2]} differ in size")
    total = np.zeros_like(values)
    weight_sum = np.zeros(values.shape[:2])
    for dy, dx, weight, _ in nl_means_weight_maps(guide, guide_variance, radius, patch_radius, k, alpha, epsilon):
        shifted, _ = _shifted(values, dy, dx)
        total += weight[..., None] * shifted
        weight_sum += weight
    out = total / weight_sum[..., None]
    return out[..., 0] if squeeze else out
