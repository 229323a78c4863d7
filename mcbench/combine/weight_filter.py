"""The ensemble's weight filter (Zheng et al. 2021 Sec. 4.2) and the passes the authors' public
code puts around it.

From raw weights w (N, H, W, C, one simplex vector per pixel-channel) and the base outputs
y_i, y_i^A, y_i^B: the raw combined images z = sum_i w_i y_i (Eq. 35), z^A, z^B and
Var[z] ~ (z^A - z^B)^2 / 2 guide a cross-bilateral filter (Eq. 32-34,
:mod:`mcbench.filters.bilateral`) of all N x C weight maps with one kernel per pixel, guided by
z / Var[z] (Eq. 33), albedo and normal; the paper's kernel parameters are
:data:`FILTER_PARAMETERS` (radius 7 px, sigma_s 3, sigma_z 2, sigma_albedo 0.25, sigma_normal
0.15). A convex combination of simplex vectors stays on the simplex; the result is projected
back onto it against rounding (onto sum one for unconstrained weights, Sec. 5.2.1, without
clipping).

**Departures: the public code's passes** (LuisaGroup/Ensemble-Denoising, ``filter.h`` /
``main.cpp``), each a switch of :func:`filter_weights` and of the ensemble's combine():
``guide_variance_blur="gaussian9"``: Var[z] blurred with a 9 x 9 Gaussian (OpenCV's sigma-0
rule, sigma = 1.7, borders reflected) before the filter; ``outlier_removal=True``: after the
filter, each weight map's values further than 2.5 standard deviations from the mean of the
other pixels of their 7 x 7 window are replaced by that mean
(:func:`mcbench.filters.bilateral.remove_outliers`, :data:`OUTLIER_RADIUS`,
:data:`OUTLIER_THRESHOLD`), then the weights are projected back onto the simplex (onto sum one
when unconstrained; a pixel-channel left with all weights 0 keeps its filtered ones);
``colour_distance="sum"``: Eq. 33 summed over the channels instead of averaged. The ensemble
blurs and removes outliers by default (``mcbench.combine.ensemble_weights.ENSEMBLE_DEFAULTS``,
the best variant measured with ``benchmarks/bench_postprocess.py``); :func:`filter_weights`
keeps the paper's filter alone by default, and :data:`PAPER_FILTER` names those options.

Precision and memory: the filter works in bands of :data:`FILTER_BLOCK_PIXELS` output pixels
(:func:`filter_band`), each from a tile of the rows it needs (:func:`tile_rows`: the filter's,
the blur's and the outlier window's halos). The filter and the blur give every row of a tile
the whole image's result bit for bit, the outlier pass to rounding of its float64 window sums.
The working precision ``dtype`` is float64 or float32 (the ensemble's: relative rounding 1e-7,
far below what a weight map shows); the guide z, Var[z] and the filter's colour term stay
float64 (:mod:`mcbench.filters.bilateral`).
"""

from __future__ import annotations

import numpy as np

from mcbench.combine.blending import combine_with
from mcbench.combine.ensemble_weights import check_choices
from mcbench.filters.bilateral import cross_bilateral_filter_vectors, gaussian_blur, remove_outliers

__all__ = ["FILTER_PARAMETERS", "PAPER_FILTER", "OUTLIER_RADIUS", "OUTLIER_THRESHOLD",
           "FILTER_BLOCK_PIXELS", "filter_weights", "filter_band", "tile_rows", "planar64"]

#: Sec. 4.2's kernel parameters (the paper's): window radius (px), sigma_s, sigma_z (Eq. 33),
#: sigma_albedo, sigma_normal
FILTER_PARAMETERS = {"radius": 7, "sigma_spatial": 3.0, "sigma_color": 2.0, "sigma_albedo": 0.25,
                     "sigma_normal": 0.15}
#: the options of the paper's filter alone, without the public code's passes
PAPER_FILTER = {"guide_variance_blur": "none", "outlier_removal": False, "colour_distance": "mean"}
OUTLIER_RADIUS = 3         # the public code's 7 x 7 window
OUTLIER_THRESHOLD = 2.5    # ... and its 2.5 standard deviations
FILTER_BLOCK_PIXELS = 1 << 17   # output pixels per band of the tiled weight filter (memory bound)

_SIMPLEX_TOL = {np.dtype(np.float64): 1e-6, np.dtype(np.float32): 1e-4}  # |sum - 1| after filtering


def _onto_constraint(weights, *, nonnegative, check, fallback=None):
    """In place: filtered (N, H, W, C) weights back onto the simplex (clip at 0, divide by the
    sum; with ``check`` first assert that the sum stayed within rounding of 1) or, for
    unconstrained weights, onto sum one (add (1 - sum) / N). A pixel-channel whose clipped
    weights are all 0 (possible after the per-map outlier removal) takes ``fallback``'s."""
    n = weights.shape[0]
    total = weights.sum(axis=0)
    if not nonnegative:
        weights += (1.0 - total) / n
        return
    if check:
        assert np.all(np.abs(total - 1.0) < _SIMPLEX_TOL[weights.dtype]), \
            "filtered weights left the simplex"
    np.maximum(weights, 0.0, out=weights)
    total = weights.sum(axis=0)
    empty = ~(total > 0)
    if empty.any():
        weights[:, empty] = fallback[:, empty]
        total[empty] = 1.0
    weights /= total



def tile_rows(y0, y1, height, *, radius, blur, outliers):
    """The rows each stage needs for the final weights of rows y0 .. y1 - 1 (half-open ranges,
    clipped to the image): (o0, o1) the filtered rows the outlier pass reads (its window's
    radius :data:`OUTLIER_RADIUS` around them), (f0, f1) the rows of raw weights, z and
    features the filter reads for those (``radius`` around), (v0, v1) the rows of Var[z] the
    9 x 9 blur reads for those (4 around)."""
    r_out = OUTLIER_RADIUS if outliers else 0
    r_blur = 4 if blur else 0
    o0, o1 = max(0, y0 - r_out), min(height, y1 + r_out)
    f0, f1 = max(0, o0 - radius), min(height, o1 + radius)
    return (o0, o1), (f0, f1), (max(0, f0 - r_blur), min(height, f1 + r_blur))


def filter_band(values, y0, y1, guide, guide_variance, v0, albedo, normal, *, radius,
                 sigma_spatial, sigma_color, sigma_albedo, sigma_normal, nonnegative,
                 guide_variance_blur, outlier_removal, colour_distance, dtype):
    """Sec. 4.2 plus the public code's optional passes for the rows y0 .. y1 - 1 of an image of
    H rows, from a tile with its halo (:func:`tile_rows`): ``values`` (N, H, W, C) raw weights
    (whole, or any array-like read by rows), ``guide`` and ``guide_variance`` planar (C, T, W)
    float64 holding the rows v0 .. v0 + T - 1 of z and Var[z] (at least (v0, v1) of
    :func:`tile_rows`), ``albedo``, ``normal`` (H, W, 3) read by rows. Returns the final weights
    (N, y1 - y0, W, C) of ``dtype``.

    Each stage works on the rows it needs only; the filter and the blur give every row exactly
    the whole image's result (:func:`mcbench.filters.bilateral.cross_bilateral_filter_vectors`,
    :func:`mcbench.filters.bilateral.gaussian_blur`: same sums in the same order), the outlier pass's
    window statistics start their running sums at the tile (float64; differences ~1e-16
    relative, tests/combine/test_ensemble.py)."""
    height = values.shape[1]
    (o0, o1), (f0, f1), (vv0, vv1) = tile_rows(
        y0, y1, height, radius=radius, blur=guide_variance_blur == "gaussian9",
        outliers=outlier_removal)
    z = np.moveaxis(guide[:, f0 - v0:f1 - v0], 0, 2)
    if guide_variance_blur == "gaussian9":
        var = gaussian_blur(np.moveaxis(guide_variance[:, vv0 - v0:vv1 - v0], 0, 2),
                            kernel_size=9, rows=(f0, f1), first_row=vv0, height=height)
    else:
        var = np.moveaxis(guide_variance[:, f0 - v0:f1 - v0], 0, 2)
    out = cross_bilateral_filter_vectors(values[:, f0:f1], z, var, [albedo[f0:f1], normal[f0:f1]],
                                         [sigma_albedo, sigma_normal], sigma_spatial, sigma_color,
                                         radius, colour_distance=colour_distance, dtype=dtype,
                                         rows=(o0 - f0, o1 - f0))
    _onto_constraint(out, nonnegative=nonnegative, check=True)
    if not outlier_removal:
        return out
    keep = slice(y0 - o0, y1 - o0)
    cleaned = remove_outliers(out, radius=OUTLIER_RADIUS, threshold=OUTLIER_THRESHOLD)[:, keep]
    _onto_constraint(cleaned, nonnegative=nonnegative, check=False, fallback=out[:, keep])
    return cleaned


def _filter_all(values, guide, guide_variance, albedo, normal, *, dtype, **options):
    """:func:`filter_band` over the bands of :data:`FILTER_BLOCK_PIXELS` pixels of whole
    arrays: values (N, H, W, C), guide and guide_variance planar (C, H, W) float64. Returns
    (N, H, W, C) of ``dtype``."""
    n, h, wd, c = values.shape
    out = np.empty((n, h, wd, c), dtype)
    step = max(1, FILTER_BLOCK_PIXELS // max(wd, 1))
    for y0 in range(0, h, step):
        y1 = min(h, y0 + step)
        out[:, y0:y1] = filter_band(values, y0, y1, guide, guide_variance, 0, albedo, normal,
                                     dtype=dtype, **options)
    return out


def filter_weights(weights, denoised_full, denoised_a, denoised_b, albedo, normal,
                   radius=FILTER_PARAMETERS["radius"],
                   sigma_spatial=FILTER_PARAMETERS["sigma_spatial"],
                   sigma_color=FILTER_PARAMETERS["sigma_color"],
                   sigma_albedo=FILTER_PARAMETERS["sigma_albedo"],
                   sigma_normal=FILTER_PARAMETERS["sigma_normal"], *, nonnegative=True,
                   guide_variance_blur=PAPER_FILTER["guide_variance_blur"],
                   outlier_removal=PAPER_FILTER["outlier_removal"],
                   colour_distance=PAPER_FILTER["colour_distance"], dtype=np.float64):
    """Cross-bilateral filter of the raw weight maps (Sec. 4.2, Eq. 32-34).

    weights, denoised_full, denoised_a, denoised_b : (N, H, W, C); albedo, normal (H, W, 3).
    The guide is the raw combined image z = sum w y_i with Var[z] ~ (z^A - z^B)^2 / 2; all
    N x C maps share one kernel per pixel. Defaults are the paper's filter alone
    (:data:`FILTER_PARAMETERS`, :data:`PAPER_FILTER`). The public code's passes (the module
    docstring): ``guide_variance_blur="gaussian9"`` blurs Var[z] with
    :func:`mcbench.filters.bilateral.gaussian_blur` (9 x 9) first, ``outlier_removal=True`` runs
    :func:`mcbench.filters.bilateral.remove_outliers` (7 x 7, 2.5 sigma) on the filtered maps and
    re-projects them, ``colour_distance="sum"`` sums Eq. 33 over the channels. ``dtype`` is the
    filter's working precision (:mod:`mcbench.filters.bilateral`; the ensemble uses float32).
    Returns (N, H, W, C) weights of ``dtype`` on the simplex; with ``nonnegative=False``
    (unconstrained weights, Sec. 5.2.1) weights summing to one, of any sign: no clipping,
    and the sum is restored against rounding by adding (1 - sum) / N to each weight.
    """
    check_choices(guide_variance_blur=guide_variance_blur, colour_distance=colour_distance)
    w = np.asarray(weights, np.float64)
    z = planar64(combine_with(w, denoised_full))
    var = planar64(0.5 * (combine_with(w, denoised_a) - combine_with(w, denoised_b)) ** 2)
    return _filter_all(w, z, var, np.asarray(albedo), np.asarray(normal), dtype=dtype,
                       radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                       sigma_albedo=sigma_albedo, sigma_normal=sigma_normal,
                       nonnegative=nonnegative, guide_variance_blur=guide_variance_blur,
                       outlier_removal=outlier_removal, colour_distance=colour_distance)


def planar64(image) -> np.ndarray:
    """(H, W, C) -> contiguous (C, H, W) float64 (the filter's layout of z and Var[z])."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(image, np.float64), 2, 0))
