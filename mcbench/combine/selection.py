"""One-hot selection among candidate images by their estimated MSE (Zheng et al. 2021
Sec. 5.2.6, Eq. 36-37; the bandwidth selection of NFOR, Bitterli et al. 2016 Sec. 5.3).

All arrays are linear radiance, float64 internally, row-major: candidates ``(N, H, W, C)``,
images ``(H, W, C)``, features ``(H, W, 3)``.

MSE maps (per pixel and channel)
--------------------------------
With the candidates' half-buffer results y_i^A, y_i^B, the noisy halves x^A, x^B and their
variances of the mean Var[x^A], Var[x^B] (the renderer's ``variance_a``/``variance_b``)::

    MSE[y_i^A] ~ (y_i^A - x^B)^2 - Var[x^B]                                      (Eq. 36)
    MSE[y_i^B] ~ (y_i^B - x^A)^2 - Var[x^A]
    MSE[y_i]   ~ (MSE[y_i^A] + MSE[y_i^B]) / 2 - Var[y_i]                        (Eq. 37)

The paper leaves Var[y_i], the variance of the full-buffer result, unspecified; we estimate it
as NFOR does (and as ``methods/nfor.py`` does) by the variance of the mean of the two half
results, Var[y_i] ~ (y_i^A - y_i^B)^2 / 4: if y_i^A, y_i^B are independent with variance v,
E[(y_i^A - y_i^B)^2] / 4 = v / 2, so Eq. 37 gives bias^2 + v / 2, the MSE of a full result
with half the half-buffer variance. The estimates are unbiased but noisy and may be negative;
they are only compared, never rooted.

Since Var[x^B] is the same for every candidate, it never changes which candidate Eq. 36
selects (nor after a pre-filter: the filters below are linear in the filtered values); Var[y_i]
differs per candidate and does matter in Eq. 37.

Pre-filters of the MSE maps (optional)
--------------------------------------
* :func:`prefilter_mse_nl_means` -- NFOR's MSE filter (Bitterli et al. 2016 Sec. 5.3): NL-means
  of :mod:`mcbench.filters.nlmeans` guided by the noisy full colour and its variance, 19 x 19 window,
  3 x 3 patches, k = 1, alpha = 1 (:data:`NFOR_MSE_FILTER`, the constants of ``methods/nfor.py``).
* :func:`prefilter_mse_bilateral` -- the cross-bilateral filter of SBF (Li et al. 2012): the
  kernel of :mod:`mcbench.filters.bilateral` (spatial x variance-normalised colour distance, Eq. 33,
  which Zheng et al. take from Li et al., x features) guided by the *noisy* full colour with its
  variance and the albedo and normal. Neither Zheng et al. nor our reading of SBF give numbers
  for filtering MSE maps, so :data:`SBF_MSE_FILTER` takes the Sec. 4.2 values (radius 7,
  sigma_s 3, sigma_colour 2, sigma_albedo 0.25, sigma_normal 0.15): our choice.

Selection and blending
----------------------
:func:`one_hot_selection` picks per pixel *and channel* the candidate of lowest MSE (channel-wise
like the ensemble's weights, Sec. 5.2.3, and like ``methods/nfor.py``'s selection map). Ties go
to the **lowest candidate index** (the first in the combiner's input list), so identical inputs
always select input 0. :func:`filter_selection_maps` is the "Post" variant: the ensemble's Sec. 4.2 weight filter
(Eq. 32-34, :func:`mcbench.combine.weight_filter.filter_weights`, the paper's filter alone) of the
one-hot maps, guided by the raw combined images; a convex combination of one-hot vectors stays
on the simplex. :func:`blend` is Eq. 3 / 35 (:func:`mcbench.combine.blending.combine_with`).
"""

from __future__ import annotations

import numpy as np

from mcbench.combine.blending import combine_with
from mcbench.combine.weight_filter import FILTER_PARAMETERS, PAPER_FILTER, filter_weights
from mcbench.filters.bilateral import cross_bilateral_filter
from mcbench.filters.nlmeans import nl_means_filter

__all__ = ["NFOR_MSE_FILTER", "SBF_MSE_FILTER", "POST_FILTER", "half_buffer_mse", "full_buffer_mse",
           "estimate_mse_maps", "prefilter_mse_nl_means", "prefilter_mse_bilateral",
           "one_hot_selection", "filter_selection_maps", "blend", "check_finite_arrays"]

# NFOR's MSE filter (Bitterli et al. 2016 Sec. 5.3; keep equal to methods/nfor.py's MSE_FILTER,
# NLM_ALPHA and NLM_EPSILON -- tests/combine/test_selection.py checks it)
NFOR_MSE_FILTER = dict(radius=9, patch_radius=1, k=1.0, alpha=1.0, epsilon=1e-10)
# SBF-style cross-bilateral pre-filter of the MSE maps: Sec. 4.2's numbers (our choice, see above)
SBF_MSE_FILTER = dict(radius=7, sigma_spatial=3.0, sigma_color=2.0, sigma_albedo=0.25, sigma_normal=0.15)
# Sec. 4.2's weight filter, applied to the one-hot maps by the "Post" variant (the paper's values)
POST_FILTER = dict(FILTER_PARAMETERS)


def check_finite_arrays(named: dict, *, what: str) -> None:
    """Raise ValueError naming every array of ``named`` ({name: array}) holding NaN/Inf, with the
    count of bad values; ``what`` says whose inputs they are (e.g. ``"one-hot selection"``)."""
    bad = {name: int(np.count_nonzero(~np.isfinite(array))) for name, array in named.items()}
    bad = {name: count for name, count in bad.items() if count}
    if bad:
        detail = ", ".join(f"{name}: {count}" for name, count in bad.items())
        raise ValueError(f"non-finite (NaN/Inf) values in the inputs of {what} ({detail})")


def _candidates(name: str, array) -> np.ndarray:
    stack = np.asarray(array, np.float64)
    if stack.ndim != 4 or stack.shape[0] < 1:
        raise ValueError(f"{name} must be (N, H, W, C) with N >= 1, got shape {stack.shape}")
    return stack


def half_buffer_mse(denoised_half, other_color, other_variance) -> np.ndarray:
    """Eq. 36: MSE[y_i^A] ~ (y_i^A - x^B)^2 - Var[x^B] for every candidate i.

    denoised_half : (N, H, W, C) candidates' results on one half buffer (y^A).
    other_color, other_variance : (H, W, C) the *other* half x^B and its variance of the mean
        (clamped at 0).
    Returns (N, H, W, C) float64, in squared radiance units; may be negative.
    """
    y = _candidates("denoised_half", denoised_half)
    x = np.asarray(other_color, np.float64)
    var = np.maximum(np.asarray(other_variance, np.float64), 0.0)
    if x.shape != y.shape[1:] or var.shape != x.shape:
        raise ValueError(f"other_color {x.shape} and other_variance {var.shape} must be the "
                         f"candidates' image shape {y.shape[1:]}")
    return (y - x) ** 2 - var


def full_buffer_mse(mse_a, mse_b, denoised_a, denoised_b) -> np.ndarray:
    """Eq. 37: MSE[y_i] ~ (MSE[y_i^A] + MSE[y_i^B]) / 2 - Var[y_i], Var[y_i] ~ (y_i^A - y_i^B)^2 / 4.

    All arguments (N, H, W, C); returns (N, H, W, C) float64.
    """
    ya = _candidates("denoised_a", denoised_a)
    yb = _candidates("denoised_b", denoised_b)
    return 0.5 * (np.asarray(mse_a, np.float64) + np.asarray(mse_b, np.float64)) - 0.25 * (ya - yb) ** 2


def estimate_mse_maps(color_a, color_b, variance_a, variance_b, denoised_a, denoised_b) -> dict:
    """The MSE maps of all candidates for the full image and both halves (Eq. 36-37).

    color_a, color_b, variance_a, variance_b : (H, W, C) noisy halves and their variances of the mean.
    denoised_a, denoised_b : (N, H, W, C) candidates' half-buffer results.
    Returns ``{"full": MSE[y_i], "a": MSE[y_i^A], "b": MSE[y_i^B]}``, each (N, H, W, C) float64.
    """
    mse_a = half_buffer_mse(denoised_a, color_b, variance_b)
    mse_b = half_buffer_mse(denoised_b, color_a, variance_a)
    return {"full": full_buffer_mse(mse_a, mse_b, denoised_a, denoised_b), "a": mse_a, "b": mse_b}


def _as_channels(maps: list[np.ndarray]) -> tuple[np.ndarray, tuple]:
    """Stack a list of (N, H, W, C) maps into (H, W, K) channels, K = sum of N*C."""
    arrays = [_candidates(f"maps[{j}]", m) for j, m in enumerate(maps)]
    if not arrays or any(a.shape[1:3] != arrays[0].shape[1:3] for a in arrays):
        raise ValueError(f"maps must be one or more (N, H, W, C) arrays of one image size, got "
                         f"shapes {[a.shape for a in arrays]}")
    channels = [np.moveaxis(a, 0, 2).reshape(a.shape[1], a.shape[2], -1) for a in arrays]
    return np.concatenate(channels, axis=2), [a.shape for a in arrays]


def _from_channels(stacked: np.ndarray, shapes: list[tuple]) -> list[np.ndarray]:
    """Inverse of :func:`_as_channels`."""
    out, start = [], 0
    for n, h, w, c in shapes:
        block = stacked[:, :, start:start + n * c].reshape(h, w, n, c)
        out.append(np.ascontiguousarray(np.moveaxis(block, 2, 0)))
        start += n * c
    return out


def prefilter_mse_nl_means(maps: list, color, variance, *, radius: int = NFOR_MSE_FILTER["radius"],
                           patch_radius: int = NFOR_MSE_FILTER["patch_radius"],
                           k: float = NFOR_MSE_FILTER["k"], alpha: float = NFOR_MSE_FILTER["alpha"],
                           epsilon: float = NFOR_MSE_FILTER["epsilon"]) -> list[np.ndarray]:
    """NFOR's MSE pre-filter: NL-means (:func:`mcbench.filters.nlmeans.nl_means_filter`) of every map in
    ``maps`` (each (N, H, W, C)) with one set of weights from ``color`` (H, W, C) and its
    ``variance``. Defaults: :data:`NFOR_MSE_FILTER`. Returns the filtered maps, float64."""
    stacked, shapes = _as_channels(list(maps))
    filtered = nl_means_filter(stacked, color, variance, radius=radius, patch_radius=patch_radius,
                               k=k, alpha=alpha, epsilon=epsilon)
    return _from_channels(filtered, shapes)


def prefilter_mse_bilateral(maps: list, color, variance, albedo, normal, *,
                            radius: int = SBF_MSE_FILTER["radius"],
                            sigma_spatial: float = SBF_MSE_FILTER["sigma_spatial"],
                            sigma_color: float = SBF_MSE_FILTER["sigma_color"],
                            sigma_albedo: float = SBF_MSE_FILTER["sigma_albedo"],
                            sigma_normal: float = SBF_MSE_FILTER["sigma_normal"]) -> list[np.ndarray]:
    """SBF-style MSE pre-filter: one cross-bilateral kernel per pixel
    (:func:`mcbench.filters.bilateral.cross_bilateral_filter`, Eq. 32-33) guided by the noisy ``color``
    (H, W, C) with its ``variance`` and by ``albedo``, ``normal`` (H, W, 3), applied to every map
    in ``maps`` (each (N, H, W, C)). Defaults: :data:`SBF_MSE_FILTER`. Returns float64 maps."""
    stacked, shapes = _as_channels(list(maps))
    filtered = cross_bilateral_filter(np.moveaxis(stacked, 2, 0), color, variance, [albedo, normal],
                                      [sigma_albedo, sigma_normal], sigma_spatial, sigma_color, radius)
    return _from_channels(np.moveaxis(filtered, 0, 2), shapes)


def one_hot_selection(mse) -> np.ndarray:
    """Per pixel and channel, 1 for the candidate of lowest ``mse`` (N, H, W, C), 0 elsewhere.

    Ties (equal MSE) go to the lowest candidate index. Returns (N, H, W, C) float64 one-hot maps.
    """
    values = _candidates("mse", mse)
    check_finite_arrays({"mse": values}, what="one-hot selection")
    best = np.argmin(values, axis=0)            # first minimum: the lowest index wins a tie
    return (np.arange(values.shape[0])[:, None, None, None] == best[None]).astype(np.float64)


def blend(weights, denoised) -> np.ndarray:
    """Eq. 3 / 35: sum_i w_i y_i per pixel and channel; (N, H, W, C) x (N, H, W, C) -> (H, W, C)
    float64 (:func:`mcbench.combine.blending.combine_with`)."""
    return combine_with(weights, denoised)


def filter_selection_maps(selection, denoised_full, denoised_a, denoised_b, albedo, normal, *,
                          radius: int = POST_FILTER["radius"],
                          sigma_spatial: float = POST_FILTER["sigma_spatial"],
                          sigma_color: float = POST_FILTER["sigma_color"],
                          sigma_albedo: float = POST_FILTER["sigma_albedo"],
                          sigma_normal: float = POST_FILTER["sigma_normal"]) -> np.ndarray:
    """The "Post" variant: Sec. 4.2's cross-bilateral filter (Eq. 32-34) of selection maps, the
    ensemble's weight filter alone (:func:`mcbench.combine.weight_filter.filter_weights` with
    :data:`mcbench.combine.weight_filter.PAPER_FILTER`, float64).

    selection, denoised_full, denoised_a, denoised_b : (N, H, W, C); albedo, normal (H, W, 3).
    Guide: the raw combined image z = sum_i s_i y_i with Var[z] ~ (z^A - z^B)^2 / 2, z^A, z^B the
    same maps applied to the half results, plus albedo and normal; all N x C maps share one kernel
    per pixel. Defaults: :data:`POST_FILTER` (the paper's). Returns (N, H, W, C) float64 soft maps,
    each pixel-channel on the simplex (w >= 0, sum 1).
    """
    return filter_weights(_candidates("selection", selection), denoised_full, denoised_a, denoised_b,
                          albedo, normal, radius, sigma_spatial, sigma_color, sigma_albedo,
                          sigma_normal, **PAPER_FILTER)
