"""Image error metrics, one pure function each, as used by Zheng et al. 2021 (Sec. 5.3.2).

All take ``image`` and ``reference`` of shape (H, W, 3): linear HDR radiance, float.
Accumulation is in float64; the result is a Python float. ``image`` must be finite
(callers validate inputs); the denominators below are guarded by their 0.01 terms.
FLIP (HDR-FLIP of Andersson et al. 2021, as NVIDIA's ``flip-evaluator`` computes it, in float64 by
:mod:`mcbench.analysis.hdr_flip`) keeps the reference's side of the last reference it saw.
The per-pixel maps (``relmse_map``, ``flip_map``) are for the report's viewer. Which metrics a
study computes, their labels and maps are declared by the plugins of ``metrics/`` (one file per
metric, :class:`mcbench.contracts.metric.MetricSpec`), which point to these functions.
"""

from __future__ import annotations

import numpy as np
from skimage.metrics import structural_similarity

from mcbench.analysis.hdr_flip import ACES

__all__ = ["relmse", "relmse_map", "relmse_corrected", "relmse_corrected_map", "smape", "dssim", "flip", "flip_map",
           "flip_with_map", "flip_exposure_range", "aces_filmic", "srgb_encode", "tonemap", "DSSIM_MIN_SIZE",
           "FLIP_MIN_LUMINANCE"]

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


def _relmse_terms(image, reference) -> np.ndarray:
    y, r = _pair(image, reference)
    return (y - r) ** 2 / (r * r + RELMSE_EPSILON)


def relmse_map(image, reference) -> np.ndarray:
    """Per-pixel relative MSE, (H, W) float64: mean over the 3 channels of (y - r)² / (r² + 0.01).

    The terms of :func:`relmse` before the mean over pixels (its mean is ``relmse``).
    """
    return np.mean(_relmse_terms(image, reference), axis=-1)


def relmse(image, reference) -> float:
    """Relative MSE: mean over pixels and channels of (y - r)² / (r² + 0.01).

    The relMSE of Rousselle et al. 2011 as used by KPCN (Bako et al. 2017) and
    Zheng et al. 2021 (Sec. 5.3.2), computed on linear HDR values without tone mapping.
    """
    return float(np.mean(_relmse_terms(image, reference)))


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


# --- HDR-FLIP -------------------------------------------------------------------------------
# Rec. 709 luminance weights and (hdr_flip.ACES) the ACES of FLIP's exposure range (Andersson et al.
# 2021, "Visualizing Errors in Rendered High Dynamic Range Images", Sec. 4): FLIP's ACES is
# Narkowicz's fit with a 0.6 pre-exposure, tm(x) = (a2 x² + a1 x) / (b2 x² + b1 x + b0).
FLIP_LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
# The tone-mapped value the exposure range aims at: c_start brings the brightest pixel of the
# reference to 0.85, c_stop brings its median pixel there.
FLIP_TARGET = 0.85
# FLIP clamps the median luminance from below at float32's machine epsilon before the log.
FLIP_MEDIAN_FLOOR = float(np.finfo(np.float32).eps)
# Below this maximum luminance an image is "black" for HDR-FLIP's automatic exposure range:
# the package's own range (from the reference) is reversed when the reference's maximum
# luminance is under FLIP_MEDIAN_FLOOR, and its C++ core then calls exit(). 2^-20 leaves a
# factor 8 of margin over that floor (float32 rounding of the package's luminance).
FLIP_MIN_LUMINANCE = 2.0 ** -20


def _flip_exposure_of(luminance_max: float, luminance_median: float) -> tuple[float, float]:
    a2, a1, b2, b1, b0 = ACES
    a = a2 - FLIP_TARGET * b2
    b = a1 - FLIP_TARGET * b1
    c = -FLIP_TARGET * b0
    # larger root of a x² + b x + c = 0: the radiance that tone-maps to FLIP_TARGET
    x_target = (-b + np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a) if a != 0.0 else -c / b
    start = float(np.log2(x_target / luminance_max))
    stop = float(np.log2(x_target / max(luminance_median, FLIP_MEDIAN_FLOOR)))
    return start, stop


def flip_exposure_range(image) -> tuple[float, float]:
    """HDR-FLIP's exposure range (c_start, c_stop) in stops, computed from ``image`` (H, W, 3).

    Andersson et al. 2021 (Sec. 4): with Y the Rec. 709 luminance, Y_max its maximum and Y_med
    its median (the element at index N // 2 of the sorted values, as FLIP does), and x* the
    radiance that FLIP's ACES maps to 0.85, c_start = log2(x* / Y_max) and
    c_stop = log2(x* / max(Y_med, eps_float32)). FLIP evaluates its LDR metric at
    max(2, ceil(c_stop - c_start)) exposures evenly spaced in [c_start, c_stop] and keeps the
    per-pixel maximum. Raises ``ValueError`` when Y_max < FLIP_MIN_LUMINANCE (no range exists).
    """
    luminance = np.maximum(np.asarray(image, dtype=np.float64), 0.0) @ FLIP_LUMINANCE_WEIGHTS
    values = luminance.ravel()
    luminance_max = float(values.max()) if values.size else 0.0
    if not luminance_max >= FLIP_MIN_LUMINANCE:
        raise ValueError(f"no HDR-FLIP exposure range for an image whose maximum luminance "
                         f"{luminance_max:.3g} is below {FLIP_MIN_LUMINANCE:.3g}")
    median = float(np.partition(values, values.size // 2)[values.size // 2])
    return _flip_exposure_of(luminance_max, median)


def _flip_inputs(image, reference) -> tuple[np.ndarray, np.ndarray]:
    """Validated float64 (H, W, 3) copies, negatives clamped to 0."""
    y, r = _pair(image, reference)
    if y.ndim != 3 or y.shape[2] != 3 or y.shape[0] < 1 or y.shape[1] < 1:
        raise ValueError(f"FLIP needs (H, W, 3) images with H, W >= 1, got shape {y.shape}")
    for name, value in (("image", y), ("reference", r)):
        if not np.all(np.isfinite(value)):
            raise ValueError(f"FLIP: {name} holds NaN or Inf values")
    # HDR-FLIP is defined on non-negative linear radiance: negative values (denoiser
    # undershoot) are clamped to 0, as the tone mapping of DSSIM does.
    return np.maximum(y, 0.0), np.maximum(r, 0.0)


def _flip_range(image, reference) -> tuple[float, float]:
    """The exposure range of a validated pair: the reference's own (:func:`flip_exposure_range`)
    when the reference is not black (maximum luminance >= FLIP_MIN_LUMINANCE). Degenerate cases,
    documented choices: a black reference with a non-black image takes the range from the image;
    two black images are given the range of a uniform image of luminance FLIP_MIN_LUMINANCE
    (start = stop, 2 exposures), so identical black images score 0 and any difference is seen at an
    exposure that makes FLIP_MIN_LUMINANCE bright (0.85 after tone mapping)."""
    for source in (reference, image):
        try:
            return flip_exposure_range(source)
        except ValueError:
            pass
    return _flip_exposure_of(FLIP_MIN_LUMINANCE, FLIP_MIN_LUMINANCE)


# The prepared reference kept (mcbench.analysis.hdr_flip.FlipReference): a case compares each of
# its entries with one reference, which is then prepared once. One, since a prepared reference
# takes about 40 bytes per pixel and exposure (330 MB at 1280x720 with 9 exposures).
_PREPARED_REFERENCES: dict = {}
_PREPARED_KEPT = 1


def _prepared_reference(reference, start: float, stop: float):
    """The reference's side of HDR-FLIP over [start, stop], from :data:`_PREPARED_REFERENCES`
    when a reference of the same content (BLAKE2b of its bytes) and range was prepared before."""
    import hashlib

    from mcbench.analysis.hdr_flip import prepare_flip_reference

    key = (reference.shape, start, stop, hashlib.blake2b(reference.tobytes(), digest_size=16).digest())
    prepared = _PREPARED_REFERENCES.pop(key, None)
    if prepared is None:
        prepared = prepare_flip_reference(reference, start=start, stop=stop)
    _PREPARED_REFERENCES[key] = prepared
    while len(_PREPARED_REFERENCES) > _PREPARED_KEPT:
        _PREPARED_REFERENCES.pop(next(iter(_PREPARED_REFERENCES)))
    return prepared


def _flip_evaluate(image, reference) -> tuple[np.ndarray, float]:
    """(per-pixel HDR-FLIP (H, W) float64, its mean) for a pair, through
    :mod:`mcbench.analysis.hdr_flip` over the range of :func:`_flip_range`."""
    from mcbench.analysis.hdr_flip import hdr_flip_map

    y, r = _flip_inputs(image, reference)
    start, stop = _flip_range(y, r)
    error_map = hdr_flip_map(y, _prepared_reference(r, start, max(stop, start)))
    if not np.all(np.isfinite(error_map)):
        raise ValueError("FLIP gave a non-finite error")
    return error_map, float(np.mean(error_map))


def flip_map(image, reference) -> np.ndarray:
    """Per-pixel HDR-FLIP error, (H, W) float64 in [0, 1], no colour map applied.

    HDR-FLIP (Andersson et al. 2021) as NVIDIA's ``flip_evaluator.evaluate(reference, image,
    "HDR")`` computes it with its defaults (ACES tone mapping, 67 pixels per degree, the exposure
    range from the reference; :func:`_flip_range` for black images), in float64 by
    :mod:`mcbench.analysis.hdr_flip` (its departure: the package's float32 rounding). Negative
    radiance is clamped to 0; NaN/Inf raise ``ValueError``.
    """
    return _flip_evaluate(image, reference)[0]


def flip_with_map(image, reference) -> tuple[np.ndarray, float]:
    """``(flip_map(image, reference), flip(image, reference))`` from one FLIP evaluation."""
    return _flip_evaluate(image, reference)


def flip(image, reference) -> float:
    """Mean HDR-FLIP error over pixels (the float64 mean of :func:`flip_map`), in [0, 1].

    0 for identical images; perceptual, on linear HDR radiance (Andersson et al. 2021).
    """
    return _flip_evaluate(image, reference)[1]


def relmse_corrected_map(image, reference, reference_variance) -> np.ndarray:
    """Per-pixel reference-noise-corrected relative MSE, (H, W) float64 (mean over channels).

    Terms of :func:`relmse_corrected` before the mean over pixels; see there. Negative where the
    image is closer to the reference than the reference's own noise (an unbiased estimate of a
    small non-negative number may be negative).
    """
    y, r = _pair(image, reference)
    v = np.asarray(reference_variance, dtype=np.float64)
    if v.shape != r.shape:
        raise ValueError(f"reference variance shape {v.shape} differs from reference shape {r.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError("reference variance holds NaN or Inf values")
    v = np.maximum(v, 0.0)
    numerator = (y - r) ** 2 - v
    denominator = np.maximum(r * r - v, 0.0) + RELMSE_EPSILON
    return np.mean(numerator / denominator, axis=-1)


def relmse_corrected(image, reference, reference_variance) -> float:
    """Relative MSE corrected for the reference's own Monte Carlo noise.

    ``reference_variance`` (H, W, 3): the per-pixel, per-channel variance of the reference's
    mean (the ``variance`` layer the references store). With μ the true radiance, the reference
    r = μ + e with E[e] = 0 and Var[e] = v, and the image y independent of r (the references use
    seeds of their own, ``mcbench.render.seeds``):

    * E[(y − r)² | y] = (y − μ)² + v, so (y − r)² − v is an unbiased estimate of the numerator
      (y − μ)² that :func:`relmse` means;
    * E[r²] = μ² + v, so r² − v is an unbiased estimate of μ² in the denominator μ² + 0.01.

    Per pixel-channel: ((y − r)² − v) / (max(r² − v, 0) + 0.01), then the mean over pixels and
    channels. The numerator is exactly unbiased; the denominator's correction removes the
    first-order bias v / (μ² + 0.01) of the raw ratio. What remains comes from dividing two
    estimates: with Var[r²] ≈ 4 μ² v it is about 4 · relMSE(y, μ) · v / μ² per pixel, the raw
    bias times four times the candidate's own relMSE (a few per cent of it for a good
    candidate; tested). The clamp at 0 only acts where the reference's noise exceeds its value,
    where no metric can see the truth. The raw relMSE against a noisy
    reference overstates every candidate's error by about mean(v / (μ² + 0.01)), the reference's
    noise floor (``mcbench.analysis.scene_summary.reference_relmse_floor``), which at high spp can exceed the
    candidates' own errors and reorders them; the corrected one does not. Not clamped at 0: a
    candidate better than the reference's noise floor may score slightly below 0 (clamping would
    bias it upwards). tests/analysis/test_metrics.py checks the unbiasedness on synthetic data.
    """
    return float(np.mean(relmse_corrected_map(image, reference, reference_variance)))

