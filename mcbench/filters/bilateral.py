"""Generic cross (joint) bilateral filter, Zheng et al. 2021 Eq. 32-34, and the smoothing passes
the authors' public code puts around it (a Gaussian blur of the guide variance, outlier
removal: :func:`gaussian_blur`, :func:`remove_outliers` (ours), :func:`remove_outlier_pixels` (as the code
is written), :func:`reflect101_tile` for its reflected borders).

Used by the ensemble's weight-map filter (``methods/ensemble.py``), the one-hot selection's
filters (``mcbench/combine/selection.py``) and the joint-bilateral base denoiser. All maps share one
kernel per pixel:

    kappa(p, q) = exp(-|p - q|^2 / (2 sigma_s^2))                       (spatial)
                * exp(-D^2(g(p), g(q)) / (2 sigma_g^2))                  (colour guide, Eq. 33)
                * prod_f exp(-|f(p) - f(q)|^2 / (2 sigma_f^2))            (features, Eq. 32)

    out_k(p) = sum_q kappa(p, q) values_k(q) / sum_q kappa(p, q)          (Eq. 34)

with q over the (2 radius + 1)^2 square window around p clipped at the image borders.

Colour distance (Eq. 33) -- our documented reading of ``|z_p - z_q|^2 / (Var_p + Var_q)``
for RGB is the per-channel mean (``colour_distance="mean"``)::

    D^2 = 1/C sum_c (g_p,c - g_q,c)^2 / (v_p,c + v_q,c)

``colour_distance="sum"`` drops the 1/C, as the authors' public code does (so "sum" with
sigma_g equals "mean" with sigma_g / sqrt(C)). The division is guarded: when
``v_p,c + v_q,c <= 1e-20`` the channel's term is 0 if the numerator is 0 and "infinite"
(kernel 0) otherwise. Since kappa(p, p) = 1 the normaliser is always >= 1, so the output is
finite for finite inputs.

Implementation. The kernel is symmetric, kappa(p, q) = kappa(q, p), so each pair of pixels is
evaluated once and added to both ends (half of the (2r + 1)^2 - 1 offsets per pixel), and it is
evaluated once per pair for all K maps (and their C channels). The image (or the rows asked
for) is cut into bands of about :data:`BAND_ROWS` rows, one parallel work item each (numba
``prange``), as many bands as a multiple of the thread count and of equal height
(:func:`_band_rows`: numba hands each thread an equal run of items, so 3 bands on 2 threads
would leave one thread idle for a third of the work); a band owns its output rows, so pairs that
cross a band border are evaluated by both bands (about r / BAND_ROWS extra work) and no two
threads write the same memory. A pixel's sums are added in the same order whatever the bands. The inner loops run along image rows on planar
copies of the guide and features, so they vectorise. ``dtype`` is the working precision of the
kernel, the accumulation and the result: float64 by default (and for every caller that does not
ask), float32 for the ensemble's weight maps, where its 1e-7 relative rounding is far below
anything a weight map can show (the ensemble keeps its solver's geometry in float64). The colour
term is float64 whatever ``dtype``: Eq. 33 divides differences of nearly equal guide values by
variances that can be 0, and the zero-variance guard tests the difference for exact equality,
so rounding the guide to float32 would switch neighbours on and off. Neighbours with exponent
above :data:`EXPONENT_CUTOFF` (kernel below 1.6e-38 of the centre's weight) count
as 0.
"""

from __future__ import annotations

import math
from typing import Literal

import numba
import numpy as np
from numba import prange

from mcbench.jit import cached_njit

VARIANCE_FLOOR = 1e-20
EXPONENT_CUTOFF = 87.0       # exp(-87) = 1.6e-38: the smallest normal float32 is 1.2e-38
BAND_ROWS = 64               # output rows per parallel work item
COLOUR_DISTANCES = ("mean", "sum")
_IMPOSSIBLE = 1e30           # a colour term for "Var = 0 and the guides differ": kernel 0


def _exp_constants(dtype) -> np.ndarray:
    """Constants of :func:`_exp_neg_row` in ``dtype``: cutoff, log2(e), ln 2 split into a short
    high part (n * hi exact for n < 128) and the rest, 1/2, the Taylor coefficients 1/k! for
    k = 2..12, then 2^-(2^j) for j = 0..6."""
    hi = 0.693359375 if np.dtype(dtype) == np.float32 else 0.6931471803691238
    return np.array([EXPONENT_CUTOFF, 1.0 / math.log(2.0), hi, math.log(2.0) - hi, 0.5]
                    + [1.0 / math.factorial(k) for k in range(2, 13)]
                    + [2.0 ** -(2 ** j) for j in range(7)], dtype)


@cached_njit(error_model="numpy")
def _exp_neg_row(er, kr, c, m):
    """kr[i] = exp(-er[i]) for i < m, er >= 0, 0 from the cutoff c[0] on; a loop that vectorises (the
    C library's exp does not): exp(-e) = 2^-n exp(-f) with n = round(e / ln 2) (n < 128) and
    |f| <= ln(2) / 2, exp(-f) by its Taylor series to degree 12 (Horner), 2^-n from the bits of
    n. Relative error below 1e-7 in float32 and 5e-15 in float64 (tests/filters/test_bilateral.py)."""
    cutoff = c[0]
    log2e = c[1]
    hi = c[2]
    lo = c[3]
    half = c[4]
    zero = half - half
    one = half + half
    for i in range(m):
        e = er[i]
        inside = e < cutoff
        e = e if inside else zero
        nf = np.floor(e * log2e + half)
        f = (nf * hi - e) + nf * lo              # -(e - n ln 2)
        p = c[15]
        for k in range(14, 4, -1):
            p = p * f + c[k]
        p = (p * f + one) * f + one
        n = np.int32(nf)
        p = p * (c[16] if n & 1 else one)
        p = p * (c[17] if n & 2 else one)
        p = p * (c[18] if n & 4 else one)
        p = p * (c[19] if n & 8 else one)
        p = p * (c[20] if n & 16 else one)
        p = p * (c[21] if n & 32 else one)
        p = p * (c[22] if n & 64 else one)
        kr[i] = p if inside else zero


@cached_njit(error_model="numpy")
def _add_weighted_row(out, wsum, values, krow, kk, y, band_row, x0, j0, src_y, src_j0, m, mc):
    """One end of a row of pixel pairs: wsum[band_row, x0 + i] += krow[i] (i < m) and
    out[g, y, j0 + j] += kk[j] values[g, src_y, src_j0 + j] (j < mc, every map g)."""
    for i in range(m):
        wsum[band_row, x0 + np.uint64(i)] += krow[i]
    for g in range(values.shape[0]):
        for j in range(mc):
            u = np.uint64(j)
            out[g, y, j0 + u] += kk[j] * values[g, src_y, src_j0 + u]


@cached_njit(parallel=True, error_model="numpy")
def _cbf_bands(values, channels, guide, guide_var, feats, spatial, consts, exp_consts, radius,
               band_rows, out0, out1):
    """values (G, H, W * channels): G maps of ``channels``-vectors per pixel; guide, guide_var
    (Cg, H, W) planar float64 (Cg = 0 for no colour term); feats (F, H, W) planar, pre-scaled so
    that the feature term is sum_f (f_p - f_q)^2; spatial (r + 1, 2r + 1): |d|^2 / (2 sigma_s^2)
    for the offset (dy, dx - r); consts (float64): [colour scale 1/(2 sigma_g^2) (/ Cg for the
    mean), variance floor, impossible term, lower bound of v_p + v_q (0: none)]; exp_consts (:func:`_exp_constants`), values, feats,
    spatial in the working dtype. Only the output rows out0 .. out1 - 1 are computed (the other
    rows are read as neighbours: a tile with its halo); each pixel's sums are added in the same
    order whatever the bands and rows (upper pixel row ascending, then dy, dx), so a row's result
    does not depend on them. Returns (G, out1 - out0, W * channels) of the working dtype."""
    G, H, WC = values.shape
    W = WC // channels
    Cg = guide.shape[0]
    F = feats.shape[0]
    colour_scale = consts[0]
    floor = consts[1]
    impossible = consts[2]
    den_min = consts[3]
    zero = consts[0] - consts[0]            # float64, for the guide's term
    one = spatial[0, 0] * 0 + 1             # the working dtype
    out = np.empty((G, out1 - out0, WC), values.dtype)
    nbands = (out1 - out0 + band_rows - 1) // band_rows
    for band in prange(nbands):
        y0 = out0 + band * band_rows
        y1 = min(out1, y0 + band_rows)
        wsum = np.ones((y1 - y0, W), values.dtype)   # the centre pixel, kappa(p, p) = 1
        for y in range(y0, y1):
            for g in range(G):
                for j in range(WC):
                    out[g, y - out0, j] = values[g, y, j]
        erow = np.empty(W, values.dtype)
        krow = np.empty(W, values.dtype)
        kexp = np.empty(WC, values.dtype)
        for y in range(max(0, y0 - radius), y1):
            for dy in range(max(0, y0 - y), radius + 1):
                y2 = y + dy
                if y2 >= H:
                    break
                own1 = y >= y0          # the pair's upper pixel is in this band
                own2 = y2 < y1          # ... its lower pixel
                if not (own1 or own2):
                    continue
                for dx in range(1 if dy == 0 else -radius, radius + 1):
                    xs = max(0, -dx)
                    m = min(W, W - dx) - xs
                    if m <= 0:
                        continue
                    # pixel p = (y, xs + i), q = (y2, xs + dx + i), i < m; unsigned offsets
                    # (no negative-index wraparound) let these loops vectorise without views
                    op = np.uint64(xs)
                    oq = np.uint64(xs + dx)
                    s = spatial[dy, dx + radius]
                    for i in range(m):
                        erow[i] = s
                    for f in range(F):
                        for i in range(m):
                            u = np.uint64(i)
                            d = feats[f, y, op + u] - feats[f, y2, oq + u]
                            erow[i] += d * d
                    for c in range(Cg):
                        for i in range(m):
                            u = np.uint64(i)
                            num = guide[c, y, op + u] - guide[c, y2, oq + u]
                            num = num * num
                            den = max(guide_var[c, y, op + u] + guide_var[c, y2, oq + u], den_min)
                            term = num / den if den > floor else (zero if num == zero else impossible)
                            erow[i] += colour_scale * term
                    _exp_neg_row(erow, krow, exp_consts, m)
                    if channels == 1:
                        kk = krow
                    elif channels == 3:      # RGB vectors (the ensemble): unrolled, it vectorises
                        kk = kexp
                        for i in range(m):
                            k = krow[i]
                            kk[3 * i] = k
                            kk[3 * i + 1] = k
                            kk[3 * i + 2] = k
                    else:
                        kk = kexp
                        for i in range(m):
                            for c in range(channels):
                                kk[i * channels + c] = krow[i]
                    mc = m * channels
                    jp = np.uint64(xs * channels)
                    jq = np.uint64((xs + dx) * channels)
                    if own1:      # p gets q's values
                        _add_weighted_row(out, wsum, values, krow, kk, y - out0, y - y0, op, jp, y2,
                                          jq, m, mc)
                    if own2:      # q gets p's values
                        _add_weighted_row(out, wsum, values, krow, kk, y2 - out0, y2 - y0, oq, jq, y,
                                          jp, m, mc)
        inv = np.empty(WC, values.dtype)
        for y in range(y0, y1):
            for x in range(W):
                q = one / wsum[y - y0, x]
                for c in range(channels):
                    inv[x * channels + c] = q
            for g in range(G):
                for j in range(WC):
                    out[g, y - out0, j] *= inv[j]
    return out


def _band_rows(rows: int) -> int:
    """Rows per band of :func:`_cbf_bands` for ``rows`` output rows: a multiple of numba's thread
    count of bands (the nearest to rows / BAND_ROWS, at least one per thread) of equal height
    (1024 rows on 2 threads: 16 bands of 64)."""
    threads = max(1, numba.get_num_threads())
    bands = threads * max(1, round(rows / (threads * BAND_ROWS)))
    return max(1, -(-rows // bands))


def _planar(array, name, shape, dtype) -> np.ndarray:
    """(H, W[, C]) -> contiguous (C, H, W) of ``dtype``; ``name`` for errors."""
    a = np.asarray(array)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[:2] != shape:
        raise ValueError(f"{name} has shape {a.shape}, expected {shape}[+ (C,)]")
    return np.ascontiguousarray(np.moveaxis(a, 2, 0), dtype=dtype)


def cross_bilateral_filter_vectors(values, guide, guide_variance, features, feature_sigmas,
                                   sigma_spatial, sigma_guide, radius, *,
                                   colour_distance: Literal["mean", "sum"] = "mean",
                                   variance_sum_floor: float = 0.0,
                                   dtype=np.float64, rows: tuple[int, int] | None = None
                                   ) -> np.ndarray:
    """Filter G maps of per-pixel C-vectors, values (G, H, W, C), with one shared kernel per pixel
    (Eq. 32-34); the arguments as :func:`cross_bilateral_filter`. ``values`` is used without a
    copy when it is already C-contiguous of ``dtype`` (e.g. the ensemble's (N, H, W, 3) float32
    weights), and so are ``guide`` and ``guide_variance`` when they are float64 views
    ``np.moveaxis(planar, 0, 2)`` of contiguous (C, H, W) arrays (neither is modified).
    ``rows=(r0, r1)``: only the output rows r0 .. r1 - 1 (the others are read as neighbours,
    e.g. a tile's halo of ``radius`` rows): the result equals those rows of the whole filter
    bit for bit when the arrays hold every row within ``radius`` of them (or the image ends
    there). ``variance_sum_floor``: Eq. 33's denominator is max(v_p,c + v_q,c, floor) (the
    public code's 1e-6, ``filter.h:197``; 0, the default: no floor, only the zero-variance guard).
    Returns (G, H, W, C) (or (G, r1 - r0, W, C)) of ``dtype`` (float32 or float64)."""
    dtype = np.dtype(dtype)
    if not (variance_sum_floor >= 0 and np.isfinite(variance_sum_floor)):
        raise ValueError(f"variance_sum_floor must be finite and >= 0, got {variance_sum_floor}")
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    if colour_distance not in COLOUR_DISTANCES:
        raise ValueError(f"colour_distance must be one of {COLOUR_DISTANCES}, got '{colour_distance}'")
    vals = np.ascontiguousarray(values, dtype=dtype)
    if vals.ndim != 4:
        raise ValueError(f"values must be (G, H, W, C), got shape {vals.shape}")
    G, H, W, C = vals.shape
    features = list(features or [])
    feature_sigmas = list(feature_sigmas or [])
    if len(features) != len(feature_sigmas):
        raise ValueError(f"{len(features)} features but {len(feature_sigmas)} feature sigmas")
    radius = int(radius)
    if radius < 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    if not sigma_spatial > 0:
        raise ValueError(f"sigma_spatial must be > 0, got {sigma_spatial}")
    scaled = []
    for i, (f, s) in enumerate(zip(features, feature_sigmas)):
        if not s > 0:
            raise ValueError(f"feature sigma {i} must be > 0, got {s}")
        scaled.append(_planar(np.asarray(f, np.float64) / (np.sqrt(2.0) * float(s)),
                              f"feature {i}", (H, W), dtype))
    feats = np.concatenate(scaled, axis=0) if scaled else np.zeros((0, H, W), dtype)
    if guide is not None:
        g = _planar(guide, "guide", (H, W), np.float64)       # float64 always: see the docstring
        gv = _planar(guide_variance, "guide_variance", (H, W), np.float64)
        if gv.shape != g.shape:
            raise ValueError(f"guide {g.shape[::-1]} / guide_variance {gv.shape[::-1]} (as W, H, C) "
                             f"do not match")
        if not sigma_guide > 0:
            raise ValueError(f"sigma_guide must be > 0, got {sigma_guide}")
        if (gv < 0).any():
            gv = np.maximum(gv, 0)
        colour_scale = 1.0 / (2.0 * float(sigma_guide) ** 2)
        if colour_distance == "mean":
            colour_scale /= g.shape[0]
    else:
        g = gv = np.zeros((0, H, W))
        colour_scale = 0.0
    offsets = np.arange(-radius, radius + 1)
    spatial = ((np.arange(radius + 1)[:, None] ** 2 + offsets[None, :] ** 2)
               / (2.0 * float(sigma_spatial) ** 2)).astype(dtype)
    consts = np.array([colour_scale, VARIANCE_FLOOR, _IMPOSSIBLE, float(variance_sum_floor)])
    r0, r1 = (0, H) if rows is None else (int(rows[0]), int(rows[1]))
    if not 0 <= r0 <= r1 <= H:
        raise ValueError(f"rows {rows} outside the {H} rows of the values")
    out = _cbf_bands(vals.reshape(G, H, W * C), C, g, gv, feats, spatial, consts,
                     _exp_constants(dtype), radius, _band_rows(r1 - r0), r0, r1)
    return out.reshape(G, r1 - r0, W, C)


def cross_bilateral_filter(values, guide, guide_variance, features, feature_sigmas,
                           sigma_spatial, sigma_guide, radius, *,
                           colour_distance: Literal["mean", "sum"] = "mean",
                           dtype=np.float64) -> np.ndarray:
    """Filter K maps with one shared cross-bilateral kernel per pixel (Eq. 32-34).

    Parameters
    ----------
    values : (K, H, W) array (a single (H, W) map is accepted and returned as (1, H, W)).
    guide : (H, W, C) colour guide (e.g. the raw combined image z) or None for no colour term.
    guide_variance : (H, W, C) per-pixel variance of ``guide`` (Var[z] in Eq. 33); ignored
        when ``guide`` is None.
    features : list of (H, W, Cf) or (H, W) feature buffers (albedo, normal, depth, ...).
    feature_sigmas : list of positive floats, one per feature (sigma_g in Eq. 32), in the
        feature's units.
    sigma_spatial : positive float, pixels (sigma_s).
    sigma_guide : positive float, unitless (sigma_z, in units of the normalised distance D).
    radius : int >= 0, half width of the square window in pixels.
    colour_distance : ``"mean"`` (default) or ``"sum"`` over the guide's channels (Eq. 33).
    dtype : working precision and result type, float64 (default) or float32.

    Returns
    -------
    (K, H, W) array of ``dtype``: the normalised weighted averages (Eq. 34). Finite for finite
    inputs (the centre pixel always has weight 1).
    """
    values = np.asarray(values)
    if values.ndim == 2:
        values = values[None]
    if values.ndim != 3:
        raise ValueError(f"values must be (K, H, W), got shape {values.shape}")
    out = cross_bilateral_filter_vectors(values[..., None], guide, guide_variance, features,
                                         feature_sigmas, sigma_spatial, sigma_guide, radius,
                                         colour_distance=colour_distance, dtype=dtype)
    return out[..., 0]


# ---------------------------------------------------------------------------------------
# the passes the authors' public code puts around the filter (public-code-facts.md, 1-2)
# ---------------------------------------------------------------------------------------
#: OpenCV's fixed Gaussian taps: ``getGaussianKernel(k, 0)`` for k = 1 .. 9 returns these tables
#: (multiples of 1/256; measured with OpenCV 4.6, Debian 12's, which built the public code for
#: tests/data/golden/ensemble_cpp), not the sigma rule of larger sizes
OPENCV_SMALL_KERNELS = {1: (256,), 3: (64, 128, 64), 5: (16, 64, 96, 64, 16), 7: (8, 28, 56, 72, 56, 28, 8),
                        9: (4, 13, 30, 51, 60, 51, 30, 13, 4)}


def gaussian_kernel(kernel_size: int) -> np.ndarray:
    """The normalised 1-D Gaussian of OpenCV's ``GaussianBlur`` with sigma 0: for sizes up to 9
    OpenCV's fixed table (:data:`OPENCV_SMALL_KERNELS`, /256; for 9 it is the sigma-1.7 Gaussian
    rounded to 1/256, for 7 the public code's outlier blur [1, 3.5, 7, 9, 7, 3.5, 1] / 32), above 9
    sigma = 0.3 ((kernel_size - 1) / 2 - 1) + 0.8 and taps exp(-x^2 / (2 sigma^2)) at
    x = -(k - 1)/2 .. (k - 1)/2 divided by their sum. (kernel_size,) float64."""
    if kernel_size < 1 or kernel_size % 2 == 0:
        raise ValueError(f"kernel_size must be odd and positive, got {kernel_size}")
    if kernel_size in OPENCV_SMALL_KERNELS:
        return np.array(OPENCV_SMALL_KERNELS[kernel_size], dtype=np.float64) / 256.0
    sigma = 0.3 * ((kernel_size - 1) / 2 - 1) + 0.8
    x = np.arange(kernel_size) - (kernel_size - 1) / 2
    taps = np.exp(-x ** 2 / (2 * sigma ** 2))
    return taps / taps.sum()


@cached_njit(parallel=True, error_model="numpy")
def _blur_kernel(a, taps, idx0, idx1, n_out, c):
    """Rows, then columns: t[i] = sum_k taps[k] a[idx0[i + k]] (i < n_out), then
    out[:, x] = sum_k taps[k] t[:, idx1[x + k]], each sum from 0.0 with k ascending; a (T, W C)
    float64, idx0 / idx1 the padded rows' / columns' sources. Each row of t is padded once, so
    the column taps run over contiguous memory. Returns (n_out, W C)."""
    m = a.shape[1]
    w = m // c
    t_rows = np.zeros((n_out, m))
    for i in prange(n_out):
        for k in range(taps.shape[0]):
            tap = taps[k]
            src = idx0[i + k]
            for j in range(m):
                t_rows[i, j] += tap * a[src, j]
    out = np.zeros((n_out, m))
    for y in prange(n_out):
        padded = np.empty(idx1.shape[0] * c)
        for x in range(idx1.shape[0]):
            for ch in range(c):
                padded[x * c + ch] = t_rows[y, idx1[x] * c + ch]
        for k in range(taps.shape[0]):
            tap = taps[k]
            off = k * c
            for j in range(m):
                out[y, j] += tap * padded[off + j]
    return out


def _reflect_index(length: int, r: int) -> np.ndarray:
    """Source index of each of the length + 2 r padded positions: BORDER_REFLECT_101 (NumPy's
    "reflect", repeated for short axes), "edge" for an axis of length 1. int64."""
    return np.pad(np.arange(length), r, mode="reflect" if length > 1 else "edge")


def reflect101_tile(array, *, radius: int, first_row: int = 0, height: int | None = None,
                    rows: tuple[int, int] | None = None, row_axis: int = 0) -> np.ndarray:
    """Rows r0 - radius .. r1 + radius - 1 and columns -radius .. W + radius - 1 of an image,
    out-of-image positions reflected without repeating the edge (OpenCV's BORDER_REFLECT_101,
    :func:`_reflect_index`): the padding under which a clipped-window filter of those rows equals
    the public code's reflected windows (``cv::borderInterpolate``). ``array`` holds the rows
    ``first_row`` .. ``first_row + T - 1`` (along ``row_axis``; columns along the next axis) of
    an image of ``height`` rows (default: the tile is the image); ``rows=(r0, r1)`` default: the
    tile's rows. Every source row must be in the tile, else ``ValueError``. A copy, same dtype."""
    a = np.asarray(array)
    t_rows, width = a.shape[row_axis], a.shape[row_axis + 1]
    height = first_row + t_rows if height is None else int(height)
    r0, r1 = (first_row, first_row + t_rows) if rows is None else (int(rows[0]), int(rows[1]))
    idx0 = _reflect_index(height, radius)[r0:r1 + 2 * radius] - first_row
    if idx0.size and (idx0.min() < 0 or idx0.max() >= t_rows):
        raise ValueError(f"reflected rows {r0}:{r1} (radius {radius}) need image rows outside the tile "
                         f"{first_row}:{first_row + t_rows}")
    return np.take(np.take(a, idx0, axis=row_axis), _reflect_index(width, radius), axis=row_axis + 1)


def gaussian_blur(image, *, kernel_size: int = 9, rows: tuple[int, int] | None = None,
                  first_row: int = 0, height: int | None = None) -> np.ndarray:
    """Separable Gaussian blur of an (H, W) or (H, W, C) image with :func:`gaussian_kernel`,
    borders reflected without repeating the edge pixel (OpenCV's default BORDER_REFLECT_101,
    NumPy's ``pad`` mode "reflect"; an axis of length 1 is constant): rows first, then columns,
    each output the sum of tap x value from k = 0 up (the order of the NumPy formulation
    ``out += tap * shifted``, so the result is the same bit for bit; tests/filters/test_bilateral.py).

    A tile: ``image`` holds the rows ``first_row`` .. ``first_row + T - 1`` of an image of
    ``height`` rows (default: the whole image), and ``rows=(r0, r1)`` asks for the blurred rows
    r0 .. r1 - 1 of the image (default: the tile's); every row within kernel_size // 2 of them
    (reflected at the image's borders) must be in the tile. Returns float64 of shape
    (r1 - r0, W[, C])."""
    a = np.asarray(image, np.float64)
    flat = a.ndim == 2
    if flat:
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"image must be (H, W) or (H, W, C), got shape {np.shape(image)}")
    taps = gaussian_kernel(kernel_size)
    r = kernel_size // 2
    t_rows, w, c = a.shape
    height = first_row + t_rows if height is None else int(height)
    r0, r1 = (first_row, first_row + t_rows) if rows is None else (int(rows[0]), int(rows[1]))
    idx0 = _reflect_index(height, r)[r0:r1 + 2 * r] - first_row
    if r1 > r0 and (idx0.min() < 0 or idx0.max() >= t_rows):
        raise ValueError(f"blurred rows {r0}:{r1} need image rows outside the tile "
                         f"{first_row}:{first_row + t_rows}")
    if r1 <= r0:
        out = np.zeros((0, w, c))
    else:
        out = _blur_kernel(np.ascontiguousarray(a).reshape(t_rows, w * c), taps, idx0,
                           _reflect_index(w, r), r1 - r0, c).reshape(r1 - r0, w, c)
    return out[..., 0] if flat else out


def gaussian_blur_reference(image, *, kernel_size: int = 9) -> np.ndarray:
    """:func:`gaussian_blur` in NumPy (pad, then ``out += tap * shifted`` per axis), the
    reference of its tests. Returns float64 of the image's shape."""
    a = np.asarray(image, np.float64)
    taps = gaussian_kernel(kernel_size)
    r = kernel_size // 2
    for axis in (0, 1):
        length = a.shape[axis]
        widths = [(0, 0)] * a.ndim
        widths[axis] = (r, r)
        padded = np.pad(a, widths, mode="reflect" if length > 1 else "edge")
        out = np.zeros_like(a)
        window = [slice(None)] * a.ndim
        for k, tap in enumerate(taps):
            window[axis] = slice(k, k + length)
            out += tap * padded[tuple(window)]
        a = out
    return a


@cached_njit(parallel=True, error_model="numpy")
def _outlier_kernel(maps, radius, threshold):
    """maps (G, H, W, C); per (map, channel) in parallel: the clipped window's sums of the values
    and their squares as running column sums (add the row entering the window, subtract the one
    leaving it) and a running sum along the row, in float64. Returns the cleaned maps."""
    G, H, W, C = maps.shape
    out = np.empty_like(maps)
    for item in prange(G * C):
        g = item // C
        c = item % C
        col = np.zeros(W)
        col2 = np.zeros(W)
        top = 0                   # rows [top, bottom) are in the column sums
        bottom = 0
        for y in range(H):
            lo = max(0, y - radius)
            hi = min(H, y + radius + 1)
            while bottom < hi:
                for x in range(W):
                    v = float(maps[g, bottom, x, c])
                    col[x] += v
                    col2[x] += v * v
                bottom += 1
            while top < lo:
                for x in range(W):
                    v = float(maps[g, top, x, c])
                    col[x] -= v
                    col2[x] -= v * v
                top += 1
            rows = hi - lo
            s = 0.0
            s2 = 0.0
            left = 0
            right = 0
            for x in range(W):
                xl = max(0, x - radius)
                xr = min(W, x + radius + 1)
                while right < xr:
                    s += col[right]
                    s2 += col2[right]
                    right += 1
                while left < xl:
                    s -= col[left]
                    s2 -= col2[left]
                    left += 1
                v = float(maps[g, y, x, c])
                others = rows * (xr - xl) - 1
                out[g, y, x, c] = maps[g, y, x, c]
                if others > 0:
                    mean = (s - v) / others
                    var = max((s2 - v * v) / others - mean * mean, 0.0)
                    if abs(v - mean) > threshold * np.sqrt(var):
                        out[g, y, x, c] = mean
    return out


def remove_outliers(maps, *, radius: int = 3, threshold: float = 2.5) -> np.ndarray:
    """The public code's outlier pass over filtered maps (``remove_outliers<3>(f, 2.5)``), our
    reading. For each map, pixel and channel independently: the mean m and the (population)
    standard deviation s of the *other* pixels of the (2 radius + 1)^2 window (the centre is
    left out, as the public code does, so an outlier does not inflate its own s; the window is
    clipped at the image borders like the bilateral filter's); a value with |v - m| > threshold s
    is replaced by m. (The public code instead replaces the whole pixel, all channels, by a
    7 x 7 Gaussian blur of the map when any channel is an outlier, and reflects at the borders.)
    Window statistics in float64 (running sums), O(1) per value.

    maps : (G, H, W, C) or (H, W, C), float32 or float64. Returns a new array of the same shape
    and dtype; the caller re-projects weights onto their constraint (the replacement is per
    map)."""
    a = np.asarray(maps)
    if a.dtype not in (np.float32, np.float64):
        a = a.astype(np.float64)
    stacked = np.ascontiguousarray(a if a.ndim == 4 else a[None])
    if stacked.ndim != 4:
        raise ValueError(f"maps must be (G, H, W, C) or (H, W, C), got shape {np.shape(maps)}")
    out = _outlier_kernel(stacked, int(radius), float(threshold))
    return out if a.ndim == 4 else out[0]


def remove_outlier_pixels(maps, *, radius: int = 3, threshold: float = 2.5, first_row: int = 0,
                          height: int | None = None, rows: tuple[int, int] | None = None) -> np.ndarray:
    """The public code's outlier pass over filtered maps as it is written (``filter.h:83-136``,
    ``remove_outliers<3>(f, 2.5)`` at ``main.cpp:165``), per map: with m_c and s_c the mean and
    sqrt((1 - 1/n) (E[x^2] - E[x]^2)) of channel c over the n = (2 radius + 1)^2 - 1 other pixels
    of the window (borders reflected, BORDER_REFLECT_101), a pixel where *any* channel has
    |v_c - m_c| >= threshold s_c takes, in all channels, the map's (2 radius + 1)^2 Gaussian blur
    (:func:`gaussian_blur`, OpenCV's sigma-0 kernel: for 7 x 7 its fixed taps
    [1, 3.5, 7, 9, 7, 3.5, 1] / 32, borders reflected); the others keep their value. A negative
    E[x^2] - E[x]^2 (rounding) gives s_c = NaN there, which no comparison passes, as in the C++.
    Statistics and blur in float64 (the C++: float32), O((2 radius + 1)^2) per value.

    maps : (G, T, W, C) or (T, W, C): the rows ``first_row`` .. ``first_row + T - 1`` of maps of
    ``height`` rows (default: whole maps); ``rows=(r0, r1)``: the output rows (default: the
    tile's), every row within ``radius`` of them (reflected) must be in the tile. Returns
    (G, r1 - r0, W, C) (or without G) of the maps' dtype (float32 or float64); the caller
    re-projects weights onto their constraint (a replaced pixel's weights need not sum to 1)."""
    a = np.asarray(maps)
    dtype = a.dtype if a.dtype in (np.float32, np.float64) else np.dtype(np.float64)
    stacked = a if a.ndim == 4 else a[None]
    if stacked.ndim != 4:
        raise ValueError(f"maps must be (G, H, W, C) or (H, W, C), got shape {np.shape(maps)}")
    g_maps, t_rows, width, channels = stacked.shape
    height = first_row + t_rows if height is None else int(height)
    r0, r1 = (first_row, first_row + t_rows) if rows is None else (int(rows[0]), int(rows[1]))
    padded = reflect101_tile(np.asarray(stacked, np.float64), radius=radius, first_row=first_row,
                             height=height, rows=(r0, r1), row_axis=1)
    n_rows, k = r1 - r0, 2 * radius + 1
    total = np.zeros((g_maps, n_rows, width, channels))
    total_sq = np.zeros_like(total)
    for dy in range(k):
        for dx in range(k):
            if dy == radius and dx == radius:
                continue
            v = padded[:, dy:dy + n_rows, dx:dx + width]
            total += v
            total_sq += v * v
    n = k * k - 1
    mean = total / n
    spread = (1.0 - 1.0 / n) * (total_sq / n - mean * mean)
    with np.errstate(invalid="ignore"):
        sigma = np.where(spread >= 0, np.sqrt(np.maximum(spread, 0.0)), np.nan)
        centre = padded[:, radius:radius + n_rows, radius:radius + width]
        outlier = (np.abs(centre - mean) >= threshold * sigma).any(axis=-1)
    out = centre.copy()
    for g in range(g_maps):
        if outlier[g].any():
            blurred = gaussian_blur(stacked[g], kernel_size=k, rows=(r0, r1), first_row=first_row,
                                    height=height)
            out[g][outlier[g]] = blurred[outlier[g]]
    out = out.astype(dtype)
    return out if a.ndim == 4 else out[0]
