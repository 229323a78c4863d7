"""Generic cross (joint) bilateral filter, Zheng et al. 2021 Eq. 32-34. The smoothing passes the
authors' public code puts around it (a Gaussian blur of the guide variance, outlier removal,
reflected borders) are :mod:`mcbench.filters.blur_and_outliers`.

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
