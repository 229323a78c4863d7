"""Image error metrics, one pure function each, as used by Zheng et al. 2021 (Sec. 5.3.2).

All take ``image`` and ``reference`` of shape (H, W, 3): linear HDR radiance, float.
Accumulation is in float64; the result is a Python float. ``image`` must be finite
(callers validate inputs); the denominators below are guarded by their 0.01 terms.
"""

from __future__ import annotations

import numpy as np
from skimage.metrics import structural_similarity

__all__ = ["relmse", "smape", "dssim", "aces_filmic", "srgb_encode", "tonemap", "METRICS", "DSSIM_MIN_SIZE"]

RELMSE_EPSILON = 0.01
SMAPE_EPSILON = 0.01
DSSIM_SIGMA = 1.5
# Side of DSSIM's Gaussian window, 2 * round(3.5 sigma) + 1 = 11 (scikit-image truncates the
# Gaussian at 3.5 sigma, radius int(3.5 sigma + 0.5)): the smallest image DSSIM is defined on. The config schema's minimum
# `resolution` is this number (a test checks that both agree).
DSSIM_MIN_SIZE = 2 * int(3.5 * DSSIM_SIGMA + 0.5) + 1


def _pair(image, reference):
    image = np.asarray(image, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if image.shape != reference.shape:
        raise ValueError(f"image shape {image.shape} differs from reference shape {reference.shape}")
    return image, reference


def relmse(image, reference) -> float:
    """Relative MSE: mean over pixels and channels of (y - r)² / (r² + 0.01).

    The relMSE of Rousselle et al. 2011 as used by KPCN (Bako et al. 2017) and
    Zheng et al. 2021 (Sec. 5.3.2), computed on linear HDR values without tone mapping.
    """
    y, r = _pair(image, reference)
    return float(np.mean((y - r) ** 2 / (r * r + RELMSE_EPSILON)))


def smape(image, reference) -> float:
    """Symmetric mean absolute percentage error: mean of |y - r| / (|y| + |r| + 0.01).

    As in Vogels et al. 2018 and Back et al. 2020, on linear HDR values.
    """
    y, r = _pair(image, reference)
    return float(np.mean(np.abs(y - r) / (np.abs(y) + np.abs(r) + SMAPE_EPSILON)))


def aces_filmic(x):
    """Narkowicz's fit of the ACES filmic curve: x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14),
    clamped to [0, 1]. Applied to linear radiance without pre-exposure (our choice; the paper
    cites ACES [Cooper et al. 2017] without giving exposure). Negative inputs map to 0."""
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def srgb_encode(x):
    """sRGB opto-electronic transfer function (IEC 61966-2-1) on [0, 1] values."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def tonemap(x):
    """ACES filmic (Narkowicz) then sRGB encoding: linear HDR -> display values in [0, 1]."""
    return srgb_encode(aces_filmic(x))


def dssim(image, reference) -> float:
    """Structural dissimilarity 1 - SSIM on tone-mapped images (Zheng et al. Sec. 5.3.2).

    SSIM is scikit-image's ``structural_similarity`` with the settings of Wang et al. 2004:
    11×11 Gaussian window of sigma 1.5, population covariances, K1 = 0.01, K2 = 0.03,
    data range 1, averaged over RGB channels and pixels.
    """
    y, r = _pair(image, reference)
    if min(y.shape[:2]) < DSSIM_MIN_SIZE:
        raise ValueError(f"DSSIM needs images of at least {DSSIM_MIN_SIZE}x{DSSIM_MIN_SIZE} pixels "
                         f"(its Gaussian window), got {y.shape[1]}x{y.shape[0]}")
    ssim = structural_similarity(tonemap(y), tonemap(r), channel_axis=2, data_range=1.0,
                                 gaussian_weights=True, sigma=DSSIM_SIGMA, use_sample_covariance=False)
    return float(1.0 - ssim)


METRICS = {"relmse": relmse, "smape": smape, "dssim": dssim}
