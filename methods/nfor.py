"""NFOR: Nonlinearly Weighted First-order Regression (Bitterli et al. 2016), #4 in Zheng et al. 2021.

Pipeline (section numbers of Bitterli et al., CGF 35(4) 2016):

1. **Feature cross-prefiltering (Sec. 5.1).** Every scalar feature f (normal x/y/z, albedo r/g/b,
   depth: 7 features) has half buffers f_A, f_B. The variance of one half buffer is estimated from
   their difference, Var[f_A] = Var[f_B] ~ (f_A - f_B)^2 / 2, and each half is NL-means filtered
   with weights from the *other* half (values f_A, guide f_B and vice versa): 11x11 window
   (radius 5), 7x7 patches (patch radius 3), k = 0.5.
2. **Collaborative first-order regression (Sec. 5.2).** For every pixel p, a weighted least-squares
   fit of colour over the 19x19 window (radius 9) with design rows
   x_q = [1, q_x - p_x, q_y - p_y, f(q) - f(p)] (d = 10 columns) and NL-means weights w_pq
   (7x7 patches) computed on the *other* half buffer's colour with that buffer's variance. The
   fit is evaluated at every q of the window and accumulated, result(q) = sum_p w_pq x_q beta_p /
   sum_p w_pq. Colour A is regressed with colour-B weights and the B-side prefiltered features,
   colour B symmetrically (cross filtering), for two bandwidths k = 0.5 and k = 1.0.
3. **MSE estimation and bandwidth selection (Sec. 5.3).** Per bandwidth i, with F_i^A, F_i^B the
   filtered halves and x^A, x^B the noisy halves (Zheng et al. 2021 Eq. 36-37):
   MSE[F_i^A] ~ (F_i^A - x^B)^2 - Var[x^B], MSE[F_i^B] ~ (F_i^B - x^A)^2 - Var[x^A],
   MSE[F_i] ~ (MSE[F_i^A] + MSE[F_i^B]) / 2 - (F_i^A - F_i^B)^2 / 4.
   The MSE maps are NL-means filtered (guide: full colour with its variance, 19x19 window, 3x3
   patches, k = 1); a per-pixel, per-channel binary selection map (1 where k = 1.0 has the lower
   filtered MSE) is filtered the same way and used to blend the candidates:
   r^A = (1 - s) F_0.5^A + s F_1.0^A, r^B likewise.
4. **Second pass (Sec. 5.4).** Features: the mean of the two prefiltered halves, with variance
   (f'_A - f'_B)^2 / 4, NL-means filtered by themselves (5x5 window, 7x7 patches, k = 0.5).
   Colour: r = (r^A + r^B) / 2 with variance (r^A - r^B)^2 / 4 is regressed again with weights
   from itself (19x19 window, 7x7 patches, k = 1.0). That regression is the final output.

Output: ``Denoised(full, a, b)`` with ``a = r^A``, ``b = r^B`` (the internal first-pass,
bandwidth-selected half-buffer results, which Zheng et al. 2021 Sec. 5.1 saved from NFOR instead
of running it three times) and ``full`` the second-pass result. ``extras["selection"]`` holds the
filtered selection map s (H, W, 3) in [0, 1]. All images (H, W, 3) float32 linear radiance.

Constants taken from the NFOR paper / its authors' public re-implementation (Tungsten):
feature prefilter R = 5, F = 3, k = 0.5; regression R = 9, F = 3, k in {0.5, 1.0};
MSE and selection filters R = 9, F = 1, k = 1; second pass features R = 2, F = 3, k = 0.5 and
regression R = 9, F = 3, k = 1.0; NL-means alpha = 1 (Rousselle et al. 2012).

Constants we had to choose (one-line reasons):

* ``NLM_EPSILON = 1e-10``: same epsilon as :mod:`mcbench.nlmeans`, so zero-variance inputs give
  weight 1 for identical colours and 0 otherwise (noise-free input is returned unchanged).
* ``DISTANCE_CLAMP = 1e4``: per-pixel distances are clipped before the patch mean (as Tungsten
  does); exp(-1e4 / 49) is already 0, it only keeps sums finite with 1e4-scale fireflies.
* ``PIVOT_TOLERANCE = 1e-9``: in the Cholesky solve of the column-normalised normal equations
  a column whose pivot (1 - R^2 against the previous columns) falls below this is dropped
  (coefficient 0): constant or collinear features (grey albedo r = g = b) never make the system
  singular; the intercept column always has a pivot of 1, so the fit falls back to the weighted
  mean at worst. Float64 Cholesky keeps ~7 significant digits at this pivot.
* ``CHUNK_ROWS = 8``: rows per parallel work item of the regression (weights of one chunk are
  361 x 8 x W float64, ~12 MB at W = 512); affects speed only.
* Feature variance of a half buffer: the raw per-pixel (f_A - f_B)^2 / 2, not smoothed, because
  the paper derives it from the half-buffer difference and NL-means averages it over 7x7 patches.
* Distances are averaged over colour channels (Rousselle et al. 2012 Eq. 5, as
  :mod:`mcbench.nlmeans`), and patches replicate image edges like :mod:`mcbench.nlmeans`.

Departures from the paper: NL-means weights over colour channels are averaged (Tungsten takes
the per-channel minimum weight); we have 7 features (no direct-visibility feature: the renders
do not produce one); the normal equations are solved by pivot-dropping Cholesky rather than a
column-pivoted QR; the second-pass guide variance is (r^A - r^B)^2 / 4, the variance of the mean
of the halves (``second_pass_variance_scale`` multiplies it; Tungsten effectively uses 2).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.buffers import Denoised, RenderBuffers
from mcbench.jit import cached_njit
from mcbench.nlmeans import nl_means_filter
from mcbench.progress import StageLog

KIND = "denoiser"
LABEL = "#4 NFOR"

NLM_EPSILON = 1e-10
NLM_ALPHA = 1.0
DISTANCE_CLAMP = 1e4
PIVOT_TOLERANCE = 1e-9
CHUNK_ROWS = 8

FEATURE_PREFILTER = dict(radius=5, patch_radius=3, k=0.5)       # Sec. 5.1
REGRESSION_RADIUS = 9                                            # 19x19 window, Sec. 5.2
REGRESSION_PATCH = 3                                             # 7x7 patches
BANDWIDTHS = (0.5, 1.0)                                          # Sec. 5.2
MSE_FILTER = dict(radius=9, patch_radius=1, k=1.0)               # Sec. 5.3 (also selection maps)
SECOND_PASS_FEATURES = dict(radius=2, patch_radius=3, k=0.5)     # Sec. 5.4
SECOND_PASS_K = 1.0                                              # Sec. 5.4


# ---------------------------------------------------------------------------------------------
# Numba kernels
# ---------------------------------------------------------------------------------------------

@cached_njit()
def _clamp(i, n):
    if i < 0:
        return 0
    if i >= n:
        return n - 1
    return i


@cached_njit()
def _weights_block(guide, variance, y0, y1, radius, patch, k, alpha, eps, clamp_d):
    """NL-means weights w(p, p + o) for the pixels p in rows [y0, y1) and every window offset.

    guide, variance: (H, W, C) float64. Returns (n_offsets, y1 - y0, W) float64; offset index
    (dy + R) * (2R + 1) + (dx + R). Distances follow Rousselle et al. 2012 Eq. 5-6, averaged over
    channels and over the patch with replicated edges; weight 0 where p + o leaves the image.
    """
    h, w, c = guide.shape
    side = 2 * radius + 1
    rows = y1 - y0
    out = np.zeros((side * side, rows, w))
    ra = y0 - patch
    nr = rows + 2 * patch
    dmap = np.empty((nr, w))
    hsum = np.empty((nr, w))
    k2 = k * k
    norm = 1.0 / ((2 * patch + 1) * (2 * patch + 1))
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            o = (dy + radius) * side + (dx + radius)
            # per-pixel distance map on the rows the patches touch (edge-replicated rows)
            for r in range(nr):
                yp = _clamp(ra + r, h)
                yq = _clamp(yp + dy, h)
                for x in range(w):
                    xq = _clamp(x + dx, w)
                    acc = 0.0
                    for ch in range(c):
                        vp = variance[yp, x, ch]
                        vq = variance[yq, xq, ch]
                        diff = guide[yp, x, ch] - guide[yq, xq, ch]
                        num = diff * diff - alpha * (vp + min(vp, vq))
                        acc += num / (eps + k2 * (vp + vq))
                    acc /= c
                    if acc > clamp_d:
                        acc = clamp_d
                    dmap[r, x] = acc
            # horizontal patch sums (edge replication)
            for r in range(nr):
                for x in range(w):
                    s = 0.0
                    for nx in range(-patch, patch + 1):
                        s += dmap[r, _clamp(x + nx, w)]
                    hsum[r, x] = s
            # vertical patch sums and weights
            for r in range(rows):
                y = y0 + r
                if y + dy < 0 or y + dy >= h:
                    continue
                for x in range(w):
                    if x + dx < 0 or x + dx >= w:
                        continue
                    s = 0.0
                    for ny in range(-patch, patch + 1):
                        # patch row y + ny, clamped to the image, mapped into the dmap rows
                        s += hsum[_clamp(y + ny, h) - ra, x]
                    d = s * norm
                    out[o, r, x] = np.exp(-d) if d > 0.0 else 1.0
    return out


@cached_njit()
def _design_row(xrow, features, qy, qx, y, x, nf):
    """Row of the first-order design matrix of neighbour (qy, qx) about centre (y, x):
    [1, dx, dy, f(q) - f(centre)...] (first-order regression of Bitterli et al. 2016)."""
    xrow[0] = 1.0
    xrow[1] = qx - x
    xrow[2] = qy - y
    for f in range(nf):
        xrow[3 + f] = features[qy, qx, f] - features[y, x, f]


@cached_njit()
def _minus_kept_products(value, lmat, keep, i, j):
    """value - sum over kept columns m < j of lmat[i, m] lmat[j, m] (Cholesky update), in order."""
    for m in range(j):
        if keep[m]:
            value -= lmat[i, m] * lmat[j, m]
    return value


@cached_njit()
def _solve_normal_equations(a, b, d, nch, tol, beta):
    """Solve a beta = b (a: (d, d) SPD-ish, b: (d, nch)) by Cholesky on the diagonally scaled
    matrix, dropping columns whose pivot is below ``tol`` (their coefficients are 0)."""
    scale = np.zeros(d)
    for i in range(d):
        scale[i] = np.sqrt(a[i, i]) if a[i, i] > 0.0 else 0.0
    lmat = np.zeros((d, d))
    keep = np.zeros(d, dtype=np.bool_)
    for j in range(d):
        if scale[j] <= 0.0:
            continue
        s = _minus_kept_products(a[j, j] / (scale[j] * scale[j]), lmat, keep, j, j)
        if s <= tol:
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


@cached_njit(parallel=True)
def _collaborative_regression(color, guide, guide_variance, features, radius, patch, k, alpha, eps,
                              clamp_d, tol, chunk):
    """Collaborative first-order regression (Bitterli et al. 2016 Sec. 5.2).

    color: (H, W, 3) values to filter; guide, guide_variance: (H, W, C) for the NL-means weights;
    features: (H, W, F). Returns (H, W, 3) float64.
    """
    h, w, nch = color.shape
    nf = features.shape[2]
    d = 3 + nf
    side = 2 * radius + 1
    nchunks = (h + chunk - 1) // chunk
    span = chunk + 2 * radius
    acc = np.zeros((nchunks, span, w, nch + 1))
    for ci in prange(nchunks):
        y0 = ci * chunk
        y1 = min(h, y0 + chunk)
        base = y0 - radius
        weights = _weights_block(guide, guide_variance, y0, y1, radius, patch, k, alpha, eps, clamp_d)
        a = np.zeros((d, d))
        b = np.zeros((d, nch))
        beta = np.zeros((d, nch))
        xrow = np.zeros(d)
        for y in range(y0, y1):
            qy0 = max(0, y - radius)
            qy1 = min(h, y + radius + 1)
            for x in range(w):
                qx0 = max(0, x - radius)
                qx1 = min(w, x + radius + 1)
                a[:, :] = 0.0
                b[:, :] = 0.0
                wsum = 0.0
                for qy in range(qy0, qy1):
                    for qx in range(qx0, qx1):
                        wt = weights[(qy - y + radius) * side + (qx - x + radius), y - y0, x]
                        if wt <= 0.0:
                            continue
                        wsum += wt
                        _design_row(xrow, features, qy, qx, y, x, nf)
                        for i in range(d):
                            wi = wt * xrow[i]
                            for j in range(i, d):
                                a[i, j] += wi * xrow[j]
                            for ch in range(nch):
                                b[i, ch] += wi * color[qy, qx, ch]
                for i in range(d):
                    for j in range(i):
                        a[i, j] = a[j, i]
                ok = _solve_normal_equations(a, b, d, nch, tol, beta)
                finite = ok
                for i in range(d):
                    for ch in range(nch):
                        if not np.isfinite(beta[i, ch]):
                            finite = False
                if not finite:  # fall back to the weighted mean (zeroth-order fit)
                    beta[:, :] = 0.0
                    for ch in range(nch):
                        beta[0, ch] = b[0, ch] / wsum
                # evaluate the local fit over the window and accumulate (collaborative step)
                for qy in range(qy0, qy1):
                    for qx in range(qx0, qx1):
                        wt = weights[(qy - y + radius) * side + (qx - x + radius), y - y0, x]
                        if wt <= 0.0:
                            continue
                        _design_row(xrow, features, qy, qx, y, x, nf)
                        for ch in range(nch):
                            pred = 0.0
                            for i in range(d):
                                pred += xrow[i] * beta[i, ch]
                            acc[ci, qy - base, qx, ch] += wt * pred
                        acc[ci, qy - base, qx, nch] += wt
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
                             patch_radius=REGRESSION_PATCH, k=1.0):
    """Filter ``color`` (H, W, 3) by collaborative first-order regression on ``features`` (H, W, F)
    with NL-means weights from ``guide`` / ``guide_variance`` (H, W, C). Returns float64 (H, W, 3)."""
    as64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)
    guide = as64(guide)
    guide_variance = np.maximum(as64(guide_variance), 0.0)
    if guide.ndim == 2:
        guide, guide_variance = guide[..., None], guide_variance[..., None]
    features = as64(features)
    if features.ndim == 2:
        features = features[..., None]
    return _collaborative_regression(as64(color), guide, guide_variance, features, int(radius),
                                     int(patch_radius), float(k), NLM_ALPHA, NLM_EPSILON,
                                     DISTANCE_CLAMP, PIVOT_TOLERANCE, CHUNK_ROWS)


def _features(buffers: RenderBuffers, suffix: str) -> np.ndarray:
    """(H, W, 7) float64: normal (3), albedo (3), depth (1) of the full ("") or a half buffer."""
    layers = buffers.layers

    def get(name):
        return np.asarray(layers.get(name + suffix, layers[name]), dtype=np.float64)

    depth = get("depth")
    if depth.ndim == 3:
        depth = depth[..., 0]
    return np.concatenate([get("normal"), get("albedo"), depth[..., None]], axis=2)


def prefilter_features(features_a, features_b):
    """Sec. 5.1: cross-prefilter every scalar feature; returns (filtered A, filtered B), (H, W, F).

    Half-buffer variance (f_A - f_B)^2 / 2; A is filtered with weights from B and vice versa.
    """
    variance = 0.5 * (features_a - features_b) ** 2
    out_a = np.empty_like(features_a)
    out_b = np.empty_like(features_b)
    for j in range(features_a.shape[2]):
        var_j = variance[..., j]
        out_a[..., j] = nl_means_filter(features_a[..., j], features_b[..., j], var_j, alpha=NLM_ALPHA,
                                        epsilon=NLM_EPSILON, **FEATURE_PREFILTER)
        out_b[..., j] = nl_means_filter(features_b[..., j], features_a[..., j], var_j, alpha=NLM_ALPHA,
                                        epsilon=NLM_EPSILON, **FEATURE_PREFILTER)
    return out_a, out_b


def denoise(buffers: RenderBuffers, *, second_pass_variance_scale: float = 1.0) -> Denoised:
    """NFOR on one render. Returns ``Denoised(full, a, b, extras={"selection": s})``, float32."""
    f64 = lambda name: np.asarray(buffers.layers[name], dtype=np.float64)
    color, variance = f64("color"), np.maximum(f64("variance"), 0.0)
    color_a, color_b = f64("color_a"), f64("color_b")
    var_a, var_b = np.maximum(f64("variance_a"), 0.0), np.maximum(f64("variance_b"), 0.0)
    stage_done = StageLog.for_image("nfor", *color.shape[:2])    # prints on large images only

    # 1. feature cross-prefiltering (Sec. 5.1)
    feat_a, feat_b = prefilter_features(_features(buffers, "_a"), _features(buffers, "_b"))
    stage_done("feature prefiltering (Sec. 5.1)")

    # 2. cross-filtered regression for each bandwidth (Sec. 5.2) and 3. MSE estimates (Sec. 5.3)
    cand_a, cand_b, mses = [], [], []
    for k in BANDWIDTHS:
        fa = collaborative_regression(color_a, color_b, var_b, feat_b, k=k)
        fb = collaborative_regression(color_b, color_a, var_a, feat_a, k=k)
        mse_a = (fa - color_b) ** 2 - var_b
        mse_b = (fb - color_a) ** 2 - var_a
        mses.append(0.5 * (mse_a + mse_b) - 0.25 * (fa - fb) ** 2)
        cand_a.append(fa)
        cand_b.append(fb)
        stage_done(f"regression of A and B at k = {k} (Sec. 5.2)")
    filtered_mse = nl_means_filter(np.concatenate(mses, axis=2), color, variance, alpha=NLM_ALPHA,
                                   epsilon=NLM_EPSILON, **MSE_FILTER)
    raw_selection = (filtered_mse[..., 3:] <= filtered_mse[..., :3]).astype(np.float64)
    selection = nl_means_filter(raw_selection, color, variance, alpha=NLM_ALPHA, epsilon=NLM_EPSILON,
                                **MSE_FILTER)
    selection = np.clip(selection, 0.0, 1.0)
    result_a = (1.0 - selection) * cand_a[0] + selection * cand_a[1]
    result_b = (1.0 - selection) * cand_b[0] + selection * cand_b[1]
    stage_done("MSE filtering and bandwidth selection (Sec. 5.3)")

    # 4. second pass (Sec. 5.4)
    combined_features = 0.5 * (feat_a + feat_b)
    combined_feature_var = 0.25 * (feat_a - feat_b) ** 2
    final_features = np.empty_like(combined_features)
    for j in range(combined_features.shape[2]):
        final_features[..., j] = nl_means_filter(combined_features[..., j], combined_features[..., j],
                                                 combined_feature_var[..., j], alpha=NLM_ALPHA,
                                                 epsilon=NLM_EPSILON, **SECOND_PASS_FEATURES)
    combined = 0.5 * (result_a + result_b)
    combined_var = second_pass_variance_scale * 0.25 * (result_a - result_b) ** 2
    stage_done("second-pass features (Sec. 5.4)")
    full = collaborative_regression(combined, combined, combined_var, final_features, k=SECOND_PASS_K)
    stage_done("second-pass regression (Sec. 5.4)")

    f32 = lambda x: np.ascontiguousarray(x, dtype=np.float32)
    return Denoised(full=f32(full), a=f32(result_a), b=f32(result_b),
                    extras={"selection": f32(selection)})
