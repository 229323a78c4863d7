"""NFOR: Nonlinearly Weighted First-order Regression (Bitterli et al. 2016), #4 in Zheng et al. 2021.

By default this is the program of the NFOR authors' public re-implementation, Tungsten's
``src/denoiser/`` (tunabrain/tungsten 88ea020; D = ``denoiser.cpp``, N = ``NlMeans.hpp``,
Rg = ``Regression.cpp``): every switch of :func:`denoise` defaults to Tungsten's behaviour
(:data:`TUNGSTEN`), and on stored 32x32 renders the output matches Tungsten's ``denoiser`` to
relMSE <= 2.3e-5, its intermediates (pass-1 regressions, MSE and selection maps, r^A, r^B) to
relMSE <= 5.8e-5 (``tests/methods/test_nfor_golden.py``,
``tests/methods/test_nfor_golden_intermediates.py``, ``docs/fidelity_nfor.md``). The paper's text was not available; where it might differ from
Tungsten, Tungsten is followed. :data:`PAPER_READING` holds a reading of the paper with the conventions
of :mod:`mcbench.filters.nlmeans`, kept for comparison.

Pipeline (section numbers of Bitterli et al., CGF 35(4) 2016):

1. **Feature cross-prefiltering (Sec. 5.1, D:44-51).** Every scalar feature f (normal x/y/z,
   albedo r/g/b, depth: 7 features) has half buffers f_A, f_B. The variance of one half buffer is
   2 x the render's variance of the full-buffer mean (``<feature>_variance``; D:48-51 with
   ``varianceScale`` 2, N:72-73), and each half is NL-means filtered with weights from the
   *other* half (values f_A, guide f_B and vice versa): 11x11 window (radius 5), 7x7 patches
   (patch radius 3), k = 0.5.
2. **Collaborative first-order regression (Sec. 5.2, D:59-65, Rg).** For every pixel p, a
   weighted least-squares fit of colour over the 19x19 window (radius 9) with design rows
   x_q = [1, q_x - p_x, q_y - p_y, f(q) - f(p)] (d = 10 columns) and NL-means weights w_pq
   (7x7 patches, the minimum of the per-channel weights, N:37-40,87) computed on the *other*
   half buffer's colour with variance 2 x ``variance`` (Rg:72). The fit is evaluated at every q
   of the window and accumulated, result(q) = sum_p w_pq x_q beta_p / sum_p w_pq. Colour A is
   regressed with colour-B weights and the B-side prefiltered features, colour B symmetrically
   (cross filtering), for two bandwidths k = 0.5 and k = 1.0.
3. **MSE estimation and bandwidth selection (Sec. 5.3, D:67-102).** Per bandwidth i, with
   F_i^A, F_i^B the filtered halves, x^A, x^B the noisy halves and V = 2 x ``variance`` (D:71-75;
   Zheng et al. 2021 Eq. 36-37):
   MSE[F_i^A] ~ (F_i^A - x^B)^2 - V, MSE[F_i^B] ~ (F_i^B - x^A)^2 - V,
   MSE[F_i] ~ (MSE[F_i^A] + MSE[F_i^B]) / 2 - (F_i^A - F_i^B)^2 / 4.
   The MSE maps are NL-means filtered (guide: full colour with its variance, 19x19 window, 3x3
   patches, k = 1, an independent weight per channel, N:33-36); a per-pixel, per-channel binary
   selection map (1 where k = 1.0 has the lower filtered MSE, ties 1) is filtered the same way
   and used to blend the candidates: r^A = (1 - s) F_0.5^A + s F_1.0^A, r^B likewise.
4. **Second pass (Sec. 5.4, D:107-132).** Features: the mean of the two prefiltered halves, with
   variance (f'_A - f'_B)^2 / 4, NL-means filtered by themselves (5x5 window, 7x7 patches,
   k = 0.5). Colour: r = (r^A + r^B) / 2 with variance 2 x (r^A - r^B)^2 / 4 (Tungsten's
   regression multiplies every variance by 2, Rg:72) is regressed again with weights from itself
   (19x19 window, 7x7 patches, k = 1.0). That regression is the final output.

Every NL-means filter uses Tungsten's epsilon 1e-7 (N:51), its per-pixel distance clamp 1e4
(N:53,76) and truncated patch means at the image borders (N:62-67,83); the regressions' rank rule
is Eigen's float32 one (:func:`denoise`, ``rank_threshold``).

Output: ``Denoised(full, a, b)`` with ``a = r^A``, ``b = r^B`` (the internal first-pass,
bandwidth-selected half-buffer results, which Zheng et al. 2021 Sec. 5.1 saved from NFOR instead
of running it three times) and ``full`` the second-pass result. ``extras["selection"]`` holds the
filtered selection map s (H, W, 3) in [0, 1]; ``intermediates=True`` adds the per-bandwidth
regressions and MSE maps. All images (H, W, 3) float32 linear radiance.

Constants from Tungsten (D:51,59,63,65,81,94,122,132): feature prefilter R = 5, F = 3, k = 0.5;
regression R = 9, F = 3, k in {0.5, 1.0}; MSE and selection filters R = 9, F = 1, k = 1; second
pass features R = 2, F = 3, k = 0.5 and regression R = 9, F = 3, k = 1.0; NL-means alpha = 1
(Rousselle et al. 2012).

Constants we chose (implementation, not Tungsten's):

* ``DISTANCE_CLAMP = 1e4``: Tungsten's clamp (N:53,76); the regressions always apply it,
  the NL-means filters with ``filter_clamp`` (default on).
* ``CHUNK_ROWS = 8``: rows per parallel work item of the regression (weights of one chunk are
  8 x W x 361 float64, pixel-major, ~12 MB at W = 512); affects speed only.

The paper reading (:data:`PAPER_READING`; each a switch of :func:`denoise`, with its reason; their
effects against Tungsten in ``docs/fidelity_nfor.md``):

* ``nlm_epsilon = NLM_EPSILON = 1e-10``: the epsilon of :mod:`mcbench.filters.nlmeans`, so
  zero-variance inputs give weight 1 for identical colours and 0 otherwise.
* ``pivot_tolerance = PIVOT_TOLERANCE = 1e-9``, ``rank_threshold = 0``: in the Cholesky solve of
  the column-normalised normal equations a column whose pivot (1 - R^2 against the previous
  columns) falls below 1e-9 is dropped (coefficient 0), so constant or collinear features (grey
  albedo r = g = b) never make the system singular; float64 Cholesky keeps ~7 significant digits
  at this pivot.
* ``feature_resolution = FEATURE_RESOLUTION = 1e-9``: a feature difference f(q) - f(p) within
  1e-9 of max(|f(q)|, |f(p)|) counts as 0, so that a feature constant up to float64 rounding is
  not a regressor of pure noise (with Tungsten's rank rule it is redundant).
* ``feature_variance = "halves"``: the per-pixel (f_A - f_B)^2 / 2, attributed to the paper but
  with no source we could check; a 1-degree-of-freedom estimate, the largest departure from
  Tungsten (relMSE 8e-3 at 8 spp), so not the default.
* ``color_variance = "halves"``: each half's own ``variance_a`` / ``variance_b``.
* ``regression_channels = filter_channels = "mean"``: distances averaged over colour channels
  (Rousselle et al. 2012 Eq. 5, as :mod:`mcbench.filters.nlmeans`); ``patch_borders =
  "replicate"``, ``filter_clamp = False``: the conventions of :mod:`mcbench.filters.nlmeans`.
* ``second_pass_variance_scale = 1``: the variance of the mean of the halves, (r^A - r^B)^2 / 4.

The helpers :func:`collaborative_regression` and :func:`prefilter_features` keep these paper-reading
values as their own keyword defaults (their tests compare with brute force at those values);
:func:`denoise` passes every switch explicitly.

Implementation and speed. NL-means filters are :func:`mcbench.filters.nlmeans.nl_means_filter`
(compiled). The regression computes, per chunk of rows, the NL-means weights of every window
offset, pixel-major (:func:`mcbench.filters.nlmeans.nl_means_window_weights`), then per pixel
gathers the neighbours with w > 0 into columns (design row and colour), forms the normal
equations as dot products over the neighbours (float64, reassociated so they vectorise), solves
by pivot-dropping Cholesky on the scaled normal equations (with Eigen's rank rule,
``rank_threshold``), and evaluates the fit at every neighbour. All kernels use float64 (Tungsten:
float32, the source of the remaining ~1e-5 differences). ``benchmarks/bench_nfor.py`` measures
the speed (``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_nfor.py --sizes 128 512``).

Remaining departures from Tungsten: float64 instead of float32 and exact exp instead of fmath's
table exp; Cholesky of the normal equations instead of Eigen's column-pivoted QR (the same
least-squares fit at full rank); 7 features (no direct-visibility feature: the renders do not
produce one; Tungsten uses it only if listed).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.jit import cached_njit
from mcbench.filters.nlmeans import (BORDER_MODES, CHANNEL_MODES, guide_planes, nl_means_filter,
                                     nl_means_window_weights)
from mcbench.progress import StageLog
from mcbench.contracts.method import MethodSpec

NLM_EPSILON = 1e-10
NLM_ALPHA = 1.0
DISTANCE_CLAMP = 1e4
PIVOT_TOLERANCE = 1e-9
FEATURE_RESOLUTION = 1e-9
CHUNK_ROWS = 8

FEATURE_PREFILTER = dict(radius=5, patch_radius=3, k=0.5)       # Sec. 5.1
REGRESSION_RADIUS = 9                                            # 19x19 window, Sec. 5.2
REGRESSION_PATCH = 3                                             # 7x7 patches
BANDWIDTHS = (0.5, 1.0)                                          # Sec. 5.2
MSE_FILTER = dict(radius=9, patch_radius=1, k=1.0)               # Sec. 5.3 (also selection maps)
SECOND_PASS_FEATURES = dict(radius=2, patch_radius=3, k=0.5)     # Sec. 5.4
SECOND_PASS_K = 1.0                                              # Sec. 5.4
#: Every switch of :func:`denoise` at Tungsten's behaviour: these are :func:`denoise`'s defaults
#: (``docs/fidelity_nfor.md``, ``tests/methods/test_nfor_golden.py``).
TUNGSTEN = dict(second_pass_variance_scale=2.0, regression_channels="min", filter_channels="independent",
                nlm_epsilon=1e-7, feature_variance="buffer", color_variance="buffer", patch_borders="truncate",
                filter_clamp=True, feature_resolution=0.0, rank_threshold=float(np.finfo(np.float32).eps),
                pivot_tolerance=float(np.finfo(np.float32).eps) ** 2)
#: The switches as a reading of the paper with the conventions of :mod:`mcbench.filters.nlmeans`
#: (where Tungsten's program, the default, differs). Kept for comparison (``tools/golden/tungsten_nfor_departures.py``); each entry's reason is in
#: the module docstring, its measured effect in ``docs/fidelity_nfor.md``. Not a default anywhere:
#: ``feature_variance="halves"`` has no source and moves the output by relMSE 8e-3 at 8 spp.
PAPER_READING = dict(second_pass_variance_scale=1.0, regression_channels="mean", filter_channels="mean",
            nlm_epsilon=NLM_EPSILON, feature_variance="halves", color_variance="halves", patch_borders="replicate",
            filter_clamp=False, feature_resolution=FEATURE_RESOLUTION, rank_threshold=0.0,
            pivot_tolerance=PIVOT_TOLERANCE)


# ---------------------------------------------------------------------------------------------
# Numba kernels
# ---------------------------------------------------------------------------------------------

@cached_njit(fastmath={"reassoc", "contract"}, error_model="numpy")
def _dot(a, b, n):
    """sum_{i < n} a[i] b[i] in float64, reassociated so that it vectorises (SIMD partial sums)."""
    s = 0.0
    for i in range(n):
        s += a[i] * b[i]
    return s


@cached_njit(error_model="numpy")
def _minus_kept_products(value, lmat, keep, i, j):
    """value - sum over kept columns m < j of lmat[i, m] lmat[j, m] (Cholesky update), in order."""
    for m in range(j):
        if keep[m]:
            value -= lmat[i, m] * lmat[j, m]
    return value


@cached_njit(error_model="numpy")
def _solve_normal_equations(a, b, d, nch, tol, beta, rank_tol2=0.0):
    """Solve a beta = b (a: (d, d) SPD-ish, b: (d, nch)) by Cholesky on the diagonally scaled
    matrix, dropping columns whose pivot is below ``tol`` (their coefficients are 0), and columns
    whose residual squared norm (pivot x a_jj) is at most ``rank_tol2`` x max_i a_ii (Eigen's
    rank rule with rank_tol2 = eps^2; 0: off)."""
    scale = np.zeros(d)
    amax = 0.0
    for i in range(d):
        scale[i] = np.sqrt(a[i, i]) if a[i, i] > 0.0 else 0.0
        amax = max(amax, a[i, i])
    lmat = np.zeros((d, d))
    keep = np.zeros(d, dtype=np.bool_)
    for j in range(d):
        if scale[j] <= 0.0:
            continue
        s = _minus_kept_products(a[j, j] / (scale[j] * scale[j]), lmat, keep, j, j)
        if s <= tol or s * a[j, j] <= rank_tol2 * amax:
            continue
        keep[j] = True
        ljj = np.sqrt(s)
        lmat[j, j] = ljj
        for i in range(j + 1, d):
            if scale[i] <= 0.0:
                continue
            t = _minus_kept_products(a[i, j] / (scale[i] * scale[j]), lmat, keep, i, j)
            lmat[i, j] = t / ljj
    z = np.zeros(d)
    for ch in range(nch):
        # forward substitution on kept columns, with scaled rhs
        for i in range(d):
            if not keep[i]:
                z[i] = 0.0
                continue
            t = b[i, ch] / scale[i]
            for m in range(i):
                if keep[m]:
                    t -= lmat[i, m] * z[m]
            z[i] = t / lmat[i, i]
        for i in range(d - 1, -1, -1):
            if not keep[i]:
                beta[i, ch] = 0.0
                continue
            t = z[i]
            for m in range(i + 1, d):
                if keep[m]:
                    t -= lmat[m, i] * beta[m, ch]
            beta[i, ch] = t / lmat[i, i]
        for i in range(d):
            if keep[i]:
                beta[i, ch] = beta[i, ch] / scale[i]
    return keep[0]


@cached_njit(parallel=True, error_model="numpy")
def _collaborative_regression(color, guide, guide_variance, features, radius, patch, k, alpha, eps,
                              clamp_d, tol, feature_resolution, chunk, truncate, mode, rank_tol2):
    """Collaborative first-order regression (Bitterli et al. 2016 Sec. 5.2).

    color: (H, W, 3) values to filter; guide, guide_variance: (C, H, W) planes for the NL-means
    weights; features: (H, W, F). Returns (H, W, 3) float64.

    Per chunk of rows: the chunk's weights (rows, W, (2R+1)^2), then per pixel p the neighbours
    q with w_pq > 0 gathered into columns z_i(q) (design row [1, dx, dy, f(q) - f(p)] and the
    colour), the normal equations A_ij = sum_q w z_i z_j, b_ic = sum_q w z_i y_c as dot
    products over q (float64), the pivot-dropping Cholesky solve, and the fit evaluated at
    every q and accumulated. Feature differences within ``feature_resolution`` (relative) of
    zero are rounding noise of the prefilter and count as 0. ``truncate``, ``mode``: see
    :func:`mcbench.filters.nlmeans.nl_means_window_weights`; ``rank_tol2``:
    :func:`_solve_normal_equations`.
    """
    h, w, nch = color.shape
    nf = features.shape[2]
    d = 3 + nf
    side = 2 * radius + 1
    nwin = side * side
    nchunks = (h + chunk - 1) // chunk
    span = chunk + 2 * radius
    acc = np.zeros((nchunks, span, w, nch + 1))
    for ci in prange(nchunks):
        y0 = ci * chunk
        y1 = min(h, y0 + chunk)
        rows = y1 - y0
        base = y0 - radius
        weights = nl_means_window_weights(guide, guide_variance, y0, y1, radius, patch, k, alpha, eps, clamp_d,
                                          truncate, mode)
        a = np.zeros((d, d))
        b = np.zeros((d, nch))
        beta = np.zeros((d, nch))
        z = np.zeros((d + nch, nwin))        # columns z_i(q) of the gathered neighbours
        wz = np.zeros(nwin)
        wq = np.zeros(nwin)
        pred = np.zeros(nwin)
        qys = np.zeros(nwin, dtype=np.int64)
        qxs = np.zeros(nwin, dtype=np.int64)
        for y in range(y0, y1):
            for x in range(w):
                wrow = weights[y - y0, x]
                fp = features[y, x]
                n = 0
                for oy in range(-radius, radius + 1):
                    qy = y + oy
                    for ox in range(-radius, radius + 1):
                        wt = wrow[(oy + radius) * side + ox + radius]
                        if wt <= 0.0:
                            continue
                        qx = x + ox
                        wq[n] = wt
                        qys[n] = qy
                        qxs[n] = qx
                        z[0, n] = 1.0
                        z[1, n] = ox
                        z[2, n] = oy
                        fq = features[qy, qx]
                        for f in range(nf):
                            diff = fq[f] - fp[f]
                            if abs(diff) <= feature_resolution * max(abs(fq[f]), abs(fp[f])):
                                diff = 0.0
                            z[3 + f, n] = diff
                        for ch in range(nch):
                            z[d + ch, n] = color[qy, qx, ch]
                        n += 1
                wsum = 0.0
                for m in range(n):
                    wsum += wq[m]
                for i in range(d):
                    zi = z[i]
                    for m in range(n):
                        wz[m] = wq[m] * zi[m]
                    for j in range(i + 1):
                        a[i, j] = _dot(wz, z[j], n)
                        a[j, i] = a[i, j]
                    for ch in range(nch):
                        b[i, ch] = _dot(wz, z[d + ch], n)
                ok = _solve_normal_equations(a, b, d, nch, tol, beta, rank_tol2)
                finite = ok
                for i in range(d):
                    for ch in range(nch):
                        if not np.isfinite(beta[i, ch]):
                            finite = False
                if not finite:  # fall back to the weighted mean (zeroth-order fit)
                    beta[:, :] = 0.0
                    for ch in range(nch):
                        beta[0, ch] = b[0, ch] / wsum
                # evaluate the local fit at every neighbour and accumulate (collaborative step)
                for ch in range(nch):
                    for m in range(n):
                        pred[m] = 0.0
                    for i in range(d):
                        zi = z[i]
                        bi = beta[i, ch]
                        for m in range(n):
                            pred[m] += zi[m] * bi
                    for m in range(n):
                        acc[ci, qys[m] - base, qxs[m], ch] += wq[m] * pred[m]
                for m in range(n):
                    acc[ci, qys[m] - base, qxs[m], nch] += wq[m]
    out = np.zeros((h, w, nch))
    wsum_img = np.zeros((h, w))
    for ci in range(nchunks):
        base = ci * chunk - radius
        for r in range(span):
            y = base + r
            if y < 0 or y >= h:
                continue
            for x in range(w):
                for ch in range(nch):
                    out[y, x, ch] += acc[ci, r, x, ch]
                wsum_img[y, x] += acc[ci, r, x, nch]
    for y in range(h):
        for x in range(w):
            # every pixel's own fit gives it weight 1, so wsum >= 1
            for ch in range(nch):
                out[y, x, ch] /= wsum_img[y, x]
    return out


# ---------------------------------------------------------------------------------------------
# Python driver
# ---------------------------------------------------------------------------------------------

def collaborative_regression(color, guide, guide_variance, features, radius=REGRESSION_RADIUS,
                             patch_radius=REGRESSION_PATCH, k=1.0, *, epsilon=NLM_EPSILON,
                             feature_resolution=FEATURE_RESOLUTION, channels="mean", borders="replicate",
                             rank_threshold=0.0, pivot_tolerance=PIVOT_TOLERANCE):
    """Filter ``color`` (H, W, 3) by collaborative first-order regression on ``features`` (H, W, F)
    with NL-means weights from ``guide`` / ``guide_variance`` (H, W, C). Returns float64 (H, W, 3).
    ``channels`` "mean" | "min", ``borders`` "replicate" | "truncate", ``rank_threshold``,
    ``pivot_tolerance``: see :func:`denoise`."""
    if channels not in ("mean", "min") or borders not in BORDER_MODES:
        raise ValueError(f"regression channels {channels!r} (mean, min), borders {borders!r} {BORDER_MODES}")
    def as64(x):
        return np.ascontiguousarray(x, dtype=np.float64)

    guide, guide_variance = guide_planes(guide, guide_variance)
    features = as64(features)
    if features.ndim == 2:
        features = features[..., None]
    return _collaborative_regression(as64(color), guide, guide_variance, features, int(radius),
                                     int(patch_radius), float(k), NLM_ALPHA, float(epsilon),
                                     DISTANCE_CLAMP, float(pivot_tolerance), float(feature_resolution), CHUNK_ROWS,
                                     borders == "truncate", CHANNEL_MODES[channels], float(rank_threshold) ** 2)


def _features(buffers: RenderBuffers, suffix: str) -> np.ndarray:
    """(H, W, 7) float64: normal (3), albedo (3), depth (1) of the full ("") or a half buffer."""
    layers = buffers.layers

    def get(name):
        return np.asarray(layers.get(name + suffix, layers[name]), dtype=np.float64)

    depth = get("depth")
    if depth.ndim == 3:
        depth = depth[..., 0]
    return np.concatenate([get("normal"), get("albedo"), depth[..., None]], axis=2)


def _feature_variance(buffers: RenderBuffers) -> np.ndarray:
    """(H, W, 7) float64 variance of the full-buffer feature means (``normal_variance``,
    ``albedo_variance``, ``depth_variance``), clipped at 0; ValueError names a missing layer."""
    layers = buffers.layers
    missing = [n for n in ("normal_variance", "albedo_variance", "depth_variance") if n not in layers]
    if missing:
        raise ValueError(f"NFOR's feature_variance='buffer' (the default, Tungsten's) needs the layers {missing}, "
                         "which every render of mcbench.render.renderer holds; for buffers without them pass "
                         "feature_variance='halves' (methods.nfor.PAPER_READING)")
    depth = np.asarray(layers["depth_variance"], dtype=np.float64)
    if depth.ndim == 3:
        depth = depth[..., 0]
    stacked = np.concatenate([np.asarray(layers["normal_variance"], dtype=np.float64),
                              np.asarray(layers["albedo_variance"], dtype=np.float64), depth[..., None]], axis=2)
    return np.maximum(stacked, 0.0)


def prefilter_features(features_a, features_b, variance=None, *, epsilon=NLM_EPSILON, borders="replicate",
                       clamp=None):
    """Sec. 5.1: cross-prefilter every scalar feature; returns (filtered A, filtered B), (H, W, F).

    ``variance`` (H, W, F): the variance of one half buffer, the same for A and B; None: the
    per-pixel (f_A - f_B)^2 / 2. A is filtered with weights from B and vice versa. ``epsilon``,
    ``borders``, ``clamp``: :func:`mcbench.filters.nlmeans.nl_means_filter`.
    """
    if variance is None:
        variance = 0.5 * (features_a - features_b) ** 2
    options = dict(alpha=NLM_ALPHA, epsilon=epsilon, borders=borders, clamp=clamp, **FEATURE_PREFILTER)
    out_a = np.empty_like(features_a)
    out_b = np.empty_like(features_b)
    for j in range(features_a.shape[2]):
        var_j = variance[..., j]
        out_a[..., j] = nl_means_filter(features_a[..., j], features_b[..., j], var_j, **options)
        out_b[..., j] = nl_means_filter(features_b[..., j], features_a[..., j], var_j, **options)
    return out_a, out_b


def mse_estimate(filtered_a, filtered_b, color_a, color_b, variance_a, variance_b):
    """Sec. 5.3 (D:69-76): the unfiltered MSE map of one bandwidth's candidate, (H, W, 3) float64.

    ``filtered_a``/``filtered_b``: the regressions of halves A and B; ``color_a``/``color_b``:
    the noisy halves; ``variance_a``/``variance_b``: their variances (Tungsten: 2 x ``variance``
    for both). MSE_A = (F_A - x_B)^2 - Var[x_B], MSE_B = (F_B - x_A)^2 - Var[x_A],
    MSE = (MSE_A + MSE_B) / 2 - (F_A - F_B)^2 / 4.
    """
    mse_a = (filtered_a - color_b) ** 2 - variance_b
    mse_b = (filtered_b - color_a) ** 2 - variance_a
    return 0.5 * (mse_a + mse_b) - 0.25 * (filtered_a - filtered_b) ** 2


def _first_pass(halves, color, variance, regression: dict, filters: dict, filter_channels: str, stage_done):
    """Steps 2-3 of :func:`denoise`: each half's cross-filtered regression per bandwidth (Sec.
    5.2), their MSE estimates filtered and the bandwidth selection (Sec. 5.3): ``(selection,
    result A, result B, the intermediates by name)``."""
    color_a, color_b, var_a, var_b, feat_a, feat_b = halves
    cand_a, cand_b, mses, stages = [], [], [], {}
    for k in BANDWIDTHS:
        fa = collaborative_regression(color_a, color_b, var_b, feat_b, k=k, **regression)
        fb = collaborative_regression(color_b, color_a, var_a, feat_a, k=k, **regression)
        mses.append(mse_estimate(fa, fb, color_a, color_b, var_a, var_b))
        cand_a.append(fa)
        cand_b.append(fb)
        stages[f"filtered_a_k{k:.1f}"], stages[f"filtered_b_k{k:.1f}"] = fa, fb
        stage_done(f"regression of A and B at k = {k} (Sec. 5.2)")
    filtered_mse = nl_means_filter(np.concatenate(mses, axis=2), color, variance, channels=filter_channels,
                                   **filters, **MSE_FILTER)
    stages.update({f"mse_k{k:.1f}": filtered_mse[..., 3 * i:3 * i + 3] for i, k in enumerate(BANDWIDTHS)})
    raw_selection = (filtered_mse[..., 3:] <= filtered_mse[..., :3]).astype(np.float64)
    selection = nl_means_filter(raw_selection, color, variance, channels=filter_channels, **filters, **MSE_FILTER)
    selection = np.clip(selection, 0.0, 1.0)
    result_a = (1.0 - selection) * cand_a[0] + selection * cand_a[1]
    result_b = (1.0 - selection) * cand_b[0] + selection * cand_b[1]
    stage_done("MSE filtering and bandwidth selection (Sec. 5.3)")
    return selection, result_a, result_b, stages


def _second_pass(feat_a, feat_b, result_a, result_b, variance_scale: float, regression: dict, filters: dict,
                 stage_done) -> np.ndarray:
    """Step 4 of :func:`denoise` (Sec. 5.4): the halves' features and results combined, the
    features filtered, one regression of the combined result."""
    combined_features = 0.5 * (feat_a + feat_b)
    combined_feature_var = 0.25 * (feat_a - feat_b) ** 2
    final_features = np.empty_like(combined_features)
    for j in range(combined_features.shape[2]):
        final_features[..., j] = nl_means_filter(combined_features[..., j], combined_features[..., j],
                                                 combined_feature_var[..., j], **filters, **SECOND_PASS_FEATURES)
    combined = 0.5 * (result_a + result_b)
    combined_var = variance_scale * 0.25 * (result_a - result_b) ** 2
    stage_done("second-pass features (Sec. 5.4)")
    full = collaborative_regression(combined, combined, combined_var, final_features,
                                    **dict(regression, k=SECOND_PASS_K))
    stage_done("second-pass regression (Sec. 5.4)")
    return full


def denoise(buffers: RenderBuffers, *, second_pass_variance_scale: float = 2.0, regression_channels: str = "min",
            filter_channels: str = "independent", nlm_epsilon: float = 1e-7, feature_variance: str = "buffer",
            color_variance: str = "buffer", patch_borders: str = "truncate", filter_clamp: bool = True,
            feature_resolution: float = 0.0, rank_threshold: float = float(np.finfo(np.float32).eps),
            pivot_tolerance: float = float(np.finfo(np.float32).eps) ** 2,
            intermediates: bool = False) -> Denoised:
    """NFOR on one render. Returns ``Denoised(full, a, b, extras={"selection": s})``, float32.

    Keyword switches. The defaults are Tungsten's behaviour (tunabrain/tungsten 88ea020,
    ``src/denoiser/``: D = ``denoiser.cpp``, N = ``NlMeans.hpp``, Rg = ``Regression.cpp``), the
    same values as :data:`TUNGSTEN`; :data:`PAPER_READING` sets each to the paper reading
    (``docs/fidelity_nfor.md`` measures each). Layers read: ``color``, ``color_a``, ``color_b``,
    ``variance`` and the features ``normal``, ``albedo``, ``depth`` with their ``_a``/``_b``
    halves; with the defaults also ``normal_variance``, ``albedo_variance``, ``depth_variance``
    (every render of :mod:`mcbench.render.renderer` has them); with ``color_variance="halves"``
    also ``variance_a``, ``variance_b``.

    * ``second_pass_variance_scale``: the second-pass guide variance is this times
      (r^A - r^B)^2 / 4; Tungsten 2 (its regression multiplies every variance by 2, Rg:72, also
      in the second pass, D:129-132).
    * ``regression_channels``: "mean" (weight from the channel-mean distance) or "min" (the
      minimum of the per-channel weights, Tungsten, N:37-40,87 with Rg:40,71-72).
    * ``filter_channels``: MSE and selection filters, "mean" or "independent" (each channel of
      the map averaged with weights from that colour channel alone, Tungsten, D:81,94, N:33-36,142-152).
    * ``nlm_epsilon``: epsilon of every NL-means distance; Tungsten 1e-7 (N:51).
    * ``feature_variance``: prefilter variance of a half buffer, "halves" ((f_A - f_B)^2 / 2) or
      "buffer" (2 x the render's ``<feature>_variance`` of the full mean, Tungsten, D:48-51 with N:72-73).
    * ``color_variance``: variance of the other half in the pass-1 regressions and the MSE
      estimate, "halves" (``variance_b`` for A, ``variance_a`` for B) or "buffer" (2 x
      ``variance`` for both, Tungsten, D:63-76, Rg:72).
    * ``patch_borders``: "replicate" (edge replication) or "truncate" (patch means over the
      in-image pairs only, Tungsten, N:62-67,83), in every NL-means filter and regression.
    * ``filter_clamp``: clip per-pixel, per-channel distances at 1e4 in the NL-means filters too
      (Tungsten, N:53,76; the regressions always clip).
    * ``feature_resolution``: relative threshold under which a feature difference counts as 0;
      Tungsten has none (0.0; Rg:96-97).
    * ``rank_threshold``: a design column (of sqrt(W) X, unscaled) whose residual norm after the
      previous kept columns is at most this times the largest column norm counts as 0. Tungsten
      solves in float32 with Eigen's ``ColPivHouseholderQR`` (Rg:105-106), whose rank rule drops
      columns below float32 epsilon (1.19e-7) times the largest column norm
      (``Eigen/src/QR/ColPivHouseholderQR.h:511-527``, Eigen 3.4, external): this is what removes
      the prefilter's rounding noise in a feature that is constant in a window. 0: off.
    * ``pivot_tolerance``: scaled Cholesky pivot (1 - R^2 of a column against the previous kept
      ones) below which a column is dropped. Tungsten has no such rule (Eigen keeps every column
      above its rank threshold); its float32 QR cannot resolve a residual below float32 epsilon
      of the column's own norm, so :data:`TUNGSTEN` uses eps_32^2 = 1.4e-14 instead of 1e-9.
    * ``intermediates``: also return, in ``extras``, the first-pass regressions of each half per
      bandwidth (``"filtered_a_k0.5"``, ``"filtered_b_k0.5"``, ``"filtered_a_k1.0"``,
      ``"filtered_b_k1.0"``: D:63,65) and the filtered MSE maps (``"mse_k0.5"``, ``"mse_k1.0"``:
      D:81), each (H, W, 3) float32, the quantities Tungsten's ``denoiser`` saves with
      ``tools/golden/tungsten_nfor_intermediates.patch``. ``extras["selection"]`` (D:94) and
      ``a``/``b`` (resultA/resultB, D:97-102) are always returned.
    """
    if feature_variance not in ("halves", "buffer") or color_variance not in ("halves", "buffer"):
        raise ValueError(f"feature_variance {feature_variance!r}, color_variance {color_variance!r}: "
                         "expected 'halves' or 'buffer'")
    def f64(name):
        return np.asarray(buffers.layers[name], dtype=np.float64)

    color, variance = f64("color"), np.maximum(f64("variance"), 0.0)
    color_a, color_b = f64("color_a"), f64("color_b")
    if color_variance == "buffer":
        var_a = var_b = 2.0 * variance
    else:
        var_a, var_b = np.maximum(f64("variance_a"), 0.0), np.maximum(f64("variance_b"), 0.0)
    stage_done = StageLog.for_image("nfor", *color.shape[:2])    # prints on large images only
    clamp = DISTANCE_CLAMP if filter_clamp else None
    filters = dict(alpha=NLM_ALPHA, epsilon=nlm_epsilon, borders=patch_borders, clamp=clamp)
    regression = dict(radius=REGRESSION_RADIUS, patch_radius=REGRESSION_PATCH, epsilon=nlm_epsilon,
                      feature_resolution=feature_resolution, channels=regression_channels, borders=patch_borders,
                      rank_threshold=rank_threshold, pivot_tolerance=pivot_tolerance)

    # 1. feature cross-prefiltering (Sec. 5.1)
    half_var = 2.0 * _feature_variance(buffers) if feature_variance == "buffer" else None
    feat_a, feat_b = prefilter_features(_features(buffers, "_a"), _features(buffers, "_b"), half_var,
                                        epsilon=nlm_epsilon, borders=patch_borders, clamp=clamp)
    stage_done("feature prefiltering (Sec. 5.1)")

    halves = (color_a, color_b, var_a, var_b, feat_a, feat_b)
    selection, result_a, result_b, stages = _first_pass(halves, color, variance, regression, filters, filter_channels,
                                                        stage_done)
    full = _second_pass(feat_a, feat_b, result_a, result_b, second_pass_variance_scale, regression, filters,
                        stage_done)

    def f32(x):
        return np.ascontiguousarray(x, dtype=np.float32)

    extras = {"selection": f32(selection)}
    if intermediates:
        extras.update({name: f32(image) for name, image in stages.items()})
    return Denoised(full=f32(full), a=f32(result_a), b=f32(result_b), extras=extras)


def params_layers(params: dict) -> tuple[str, ...]:
    """The render layers NFOR needs with ``params`` beyond every render's required ones: the
    feature variances of the full image with ``feature_variance='buffer'`` (the default,
    Tungsten's), so that renders imported without them are refused when the DAG is parsed."""
    if params.get("feature_variance", "buffer") == "buffer":
        return ("normal_variance", "albedo_variance", "depth_variance")
    return ()


METHOD = MethodSpec(kind="denoiser", label="#4 NFOR", run=denoise, params_layers=params_layers)
