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

**The public code's passes and details** (LuisaGroup/Ensemble-Denoising, ``filter.h`` /
``main.cpp``), each a switch of :func:`filter_weights` and of the ensemble's combine():
``guide_variance_blur="gaussian9"``: Var[z] blurred with a 9 x 9 Gaussian (OpenCV's fixed
9-tap table for sigma 0, borders reflected) before the filter; ``outlier_removal="public_code"``:
after the filter, a pixel of a weight map where any channel lies 2.5 or more standard
deviations from the mean of the other 48 pixels of its 7 x 7 window takes the map's 7 x 7
Gaussian blur (:func:`mcbench.filters.blur_and_outliers.remove_outlier_pixels`), ``"neighbour_mean"``
our own reading (one value -> the neighbours' mean,
:func:`mcbench.filters.blur_and_outliers.remove_outliers`), then the weights are projected back onto
the simplex (onto sum one when unconstrained; a pixel-channel left with all weights 0 keeps its
filtered ones); ``filter_border="reflect101"``: windows reflected at the image borders;
``variance_sum_floor=1e-6``: Eq. 33's denominator max(v_p + v_q, 1e-6);
``normal_features="standardised"``: the normal feature standardised per channel (mean,
population std floored at 1e-3) and clipped to +-3 (``main.cpp:34-43``; the text is silent).
Eq. 33's ||.||^2 is a sum over the channels (the text and the code; ``colour_distance="mean"``
is our own reading). The ensemble's defaults
(``mcbench.combine.ensemble_weights.ENSEMBLE_DEFAULTS``) follow the text where it decides and the
code where it is silent; :data:`PAPER_FILTER` is Sec. 4.2 alone and :data:`PUBLIC_CODE_FILTER`
the code's choices (with :func:`public_code_sigmas` for its feature terms).

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
from mcbench.filters.bilateral import cross_bilateral_filter_vectors
from mcbench.filters.blur_and_outliers import gaussian_blur, reflect101_tile, remove_outlier_pixels, remove_outliers

__all__ = ["FILTER_PARAMETERS", "PAPER_FILTER", "PUBLIC_CODE_FILTER", "OUTLIER_RADIUS", "OUTLIER_THRESHOLD",
           "NORMAL_STD_FLOOR", "NORMAL_CLIP", "PUBLIC_CODE_VARIANCE_SUM_FLOOR",
           "FILTER_BLOCK_PIXELS", "filter_weights", "filter_band", "tile_rows", "planar64",
           "normal_statistics", "standardised_normal", "public_code_sigmas"]

#: Sec. 4.2's kernel parameters (the paper's): window radius (px), sigma_s, sigma_z (Eq. 33),
#: sigma_albedo, sigma_normal
FILTER_PARAMETERS = {"radius": 7, "sigma_spatial": 3.0, "sigma_color": 2.0, "sigma_albedo": 0.25,
                     "sigma_normal": 0.15}
#: the options of the paper's filter alone, without the public code's passes
PAPER_FILTER = {"guide_variance_blur": "none", "outlier_removal": "none", "colour_distance": "sum",
                "filter_border": "clip", "normal_features": "raw", "variance_sum_floor": 0.0}
#: the options that make the filter the public code's (``main.cpp:158-165``, ``filter.h``), but
#: for its feature terms, exp(-|g_p - g_q|^2 / (2 sigma)) (``filter.h:185``, its slip): to follow
#: them pass sigma_albedo = sqrt(0.25) and sigma_normal = sqrt(0.15) (:func:`public_code_sigmas`)
PUBLIC_CODE_FILTER = {"guide_variance_blur": "gaussian9", "outlier_removal": "public_code",
                      "colour_distance": "sum", "filter_border": "reflect101",
                      "normal_features": "standardised", "variance_sum_floor": 1e-6}
NORMAL_STD_FLOOR = 1e-3    # the public code's floor of the normal's standard deviation (main.cpp:38-40)
NORMAL_CLIP = 3.0          # ... and its clip of the standardised normal (main.cpp:42)
PUBLIC_CODE_VARIANCE_SUM_FLOOR = 1e-6   # Eq. 33's denominator floor in the public code (filter.h:197)
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


def normal_statistics(normal) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and population standard deviation (floored at :data:`NORMAL_STD_FLOOR`) of
    a normal map (H, W, 3), float64, as OpenCV's ``meanStdDev`` in the public code (``main.cpp:34-43``).
    ``normal`` may be read by rows (any array-like indexed ``normal[y0:y1]``)."""
    height = np.shape(normal)[0]
    total, total_sq, count = np.zeros(3), np.zeros(3), 0
    for y0 in range(0, height, 256):
        rows = np.asarray(normal[y0:y0 + 256], np.float64).reshape(-1, 3)
        total += rows.sum(axis=0)
        total_sq += (rows * rows).sum(axis=0)
        count += rows.shape[0]
    mean = total / max(count, 1)
    std = np.sqrt(np.maximum(total_sq / max(count, 1) - mean * mean, 0.0))
    return mean, np.maximum(std, NORMAL_STD_FLOOR)


def standardised_normal(normal, statistics) -> np.ndarray:
    """(normal - mean) / std clipped to +-:data:`NORMAL_CLIP` per channel (the public code's
    feature, ``main.cpp:34-43``), ``statistics`` from :func:`normal_statistics`; float64 (H, W, 3)."""
    mean, std = statistics
    return np.clip((np.asarray(normal, np.float64) - mean) / std, -NORMAL_CLIP, NORMAL_CLIP)


def public_code_sigmas(sigma_albedo=FILTER_PARAMETERS["sigma_albedo"],
                       sigma_normal=FILTER_PARAMETERS["sigma_normal"]) -> dict[str, float]:
    """The sigmas under which Eq. 32's exp(-d^2 / (2 s^2)) equals the public code's
    exp(-d^2 / (2 sigma)) (``filter.h:185``): s = sqrt(sigma)."""
    return {"sigma_albedo": float(np.sqrt(sigma_albedo)), "sigma_normal": float(np.sqrt(sigma_normal))}


def filter_band(values, y0, y1, guide, guide_variance, v0, albedo, normal, *, radius,
                 sigma_spatial, sigma_color, sigma_albedo, sigma_normal, nonnegative,
                 guide_variance_blur, outlier_removal, colour_distance, dtype,
                 filter_border="clip", normal_statistics=None, variance_sum_floor=0.0):
    """Sec. 4.2 plus the public code's optional passes for the rows y0 .. y1 - 1 of an image of
    H rows, from a tile with its halo (:func:`tile_rows`): ``values`` (N, H, W, C) raw weights
    (whole, or any array-like read by rows), ``guide`` and ``guide_variance`` planar (C, T, W)
    float64 holding the rows v0 .. v0 + T - 1 of z and Var[z] (at least (v0, v1) of
    :func:`tile_rows`), ``albedo``, ``normal`` (H, W, 3) read by rows. Returns the final weights
    (N, y1 - y0, W, C) of ``dtype``.

    ``filter_border="reflect101"``: the filter's windows reflect at the image borders
    (:func:`mcbench.filters.blur_and_outliers.reflect101_tile`) instead of being clipped.
    ``normal_statistics`` (mean, std) of the whole normal map: the filter's normal feature is
    :func:`standardised_normal` (None: the normal as given). ``variance_sum_floor``: Eq. 33's
    denominator floor. ``outlier_removal``: ``"none"``, ``"neighbour_mean"``
    (:func:`mcbench.filters.blur_and_outliers.remove_outliers`) or ``"public_code"``
    (:func:`mcbench.filters.blur_and_outliers.remove_outlier_pixels`).

    Each stage works on the rows it needs only; the filter and the blurs give every row exactly
    the whole image's result (:func:`mcbench.filters.bilateral.cross_bilateral_filter_vectors`,
    :func:`mcbench.filters.blur_and_outliers.gaussian_blur`: same sums in the same order), the
    neighbour-mean outlier pass's window statistics start their running sums at the tile
    (float64; differences ~1e-16 relative, tests/combine/test_ensemble.py)."""
    height = values.shape[1]
    (o0, o1), (f0, f1), (vv0, vv1) = tile_rows(
        y0, y1, height, radius=radius, blur=guide_variance_blur == "gaussian9",
        outliers=outlier_removal != "none")
    z = np.moveaxis(guide[:, f0 - v0:f1 - v0], 0, 2)
    if guide_variance_blur == "gaussian9":
        var = gaussian_blur(np.moveaxis(guide_variance[:, vv0 - v0:vv1 - v0], 0, 2),
                            kernel_size=9, rows=(f0, f1), first_row=vv0, height=height)
    else:
        var = np.moveaxis(guide_variance[:, f0 - v0:f1 - v0], 0, 2)
    weights = values[:, f0:f1]
    features = [np.asarray(albedo[f0:f1]), np.asarray(normal[f0:f1])]
    if normal_statistics is not None:
        features[1] = standardised_normal(features[1], normal_statistics)
    rows = (o0 - f0, o1 - f0)
    if filter_border == "reflect101":   # pad by the window's radius: no window is clipped
        tile = dict(radius=radius, first_row=f0, height=height, rows=(o0, o1))
        weights = reflect101_tile(np.asarray(weights), row_axis=1, **tile)
        z, var = reflect101_tile(z, **tile), reflect101_tile(var, **tile)
        features = [reflect101_tile(f, **tile) for f in features]
        rows = (radius, radius + o1 - o0)
    elif filter_border != "clip":
        raise ValueError(f"unknown filter_border '{filter_border}'; choose 'clip' or 'reflect101'")
    out = cross_bilateral_filter_vectors(weights, z, var, features,
                                         [sigma_albedo, sigma_normal], sigma_spatial, sigma_color,
                                         radius, colour_distance=colour_distance, dtype=dtype,
                                         rows=rows, variance_sum_floor=variance_sum_floor)
    if filter_border == "reflect101":
        out = np.ascontiguousarray(out[:, :, radius:radius + values.shape[2]])
    _onto_constraint(out, nonnegative=nonnegative, check=True)
    if outlier_removal == "none":
        return out
    keep = slice(y0 - o0, y1 - o0)
    if outlier_removal == "public_code":
        cleaned = remove_outlier_pixels(out, radius=OUTLIER_RADIUS, threshold=OUTLIER_THRESHOLD,
                                        first_row=o0, height=height, rows=(y0, y1))
    elif outlier_removal == "neighbour_mean":
        cleaned = remove_outliers(out, radius=OUTLIER_RADIUS, threshold=OUTLIER_THRESHOLD)[:, keep]
    else:
        raise ValueError(f"unknown outlier_removal '{outlier_removal}'; choose one of "
                         f"'none', 'neighbour_mean', 'public_code'")
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
                   colour_distance=PAPER_FILTER["colour_distance"],
                   filter_border=PAPER_FILTER["filter_border"],
                   normal_features=PAPER_FILTER["normal_features"],
                   variance_sum_floor=PAPER_FILTER["variance_sum_floor"], dtype=np.float64):
    """Cross-bilateral filter of the raw weight maps (Sec. 4.2, Eq. 32-34).

    weights, denoised_full, denoised_a, denoised_b : (N, H, W, C); albedo, normal (H, W, 3).
    The guide is the raw combined image z = sum w y_i with Var[z] ~ (z^A - z^B)^2 / 2; all
    N x C maps share one kernel per pixel. Defaults are the paper's filter alone
    (:data:`FILTER_PARAMETERS`, :data:`PAPER_FILTER`: Eq. 33 summed over the channels, windows
    clipped at the borders). The public code's passes and details (the module docstring;
    :data:`PUBLIC_CODE_FILTER` sets them all): ``guide_variance_blur="gaussian9"`` blurs Var[z]
    with :func:`mcbench.filters.blur_and_outliers.gaussian_blur` (9 x 9) first; ``outlier_removal``
    ``"public_code"`` (:func:`mcbench.filters.blur_and_outliers.remove_outlier_pixels`) or
    ``"neighbour_mean"`` (mcbench's, :func:`mcbench.filters.blur_and_outliers.remove_outliers`) cleans the
    filtered maps, which are then re-projected; ``colour_distance="mean"`` averages Eq. 33 over
    the channels instead; ``filter_border="reflect101"`` reflects the windows at the borders;
    ``normal_features="standardised"`` standardises the normal (:func:`standardised_normal`);
    ``variance_sum_floor`` floors Eq. 33's denominator. ``dtype`` is the filter's working
    precision (:mod:`mcbench.filters.bilateral`; the ensemble uses float32).
    Returns (N, H, W, C) weights of ``dtype`` on the simplex; with ``nonnegative=False``
    (unconstrained weights, Sec. 5.2.1) weights summing to one, of any sign: no clipping,
    and the sum is restored against rounding by adding (1 - sum) / N to each weight.
    """
    check_choices(guide_variance_blur=guide_variance_blur, colour_distance=colour_distance,
                  outlier_removal=outlier_removal, filter_border=filter_border,
                  normal_features=normal_features)
    w = np.asarray(weights, np.float64)
    z = planar64(combine_with(w, denoised_full))
    var = planar64(0.5 * (combine_with(w, denoised_a) - combine_with(w, denoised_b)) ** 2)
    statistics = normal_statistics(normal) if normal_features == "standardised" else None
    return _filter_all(w, z, var, np.asarray(albedo), np.asarray(normal), dtype=dtype,
                       radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                       sigma_albedo=sigma_albedo, sigma_normal=sigma_normal,
                       nonnegative=nonnegative, guide_variance_blur=guide_variance_blur,
                       outlier_removal=outlier_removal, colour_distance=colour_distance,
                       filter_border=filter_border, normal_statistics=statistics,
                       variance_sum_floor=variance_sum_floor)


def planar64(image) -> np.ndarray:
    """(H, W, C) -> contiguous (C, H, W) float64 (the filter's layout of z and Var[z])."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(image, np.float64), 2, 0))
