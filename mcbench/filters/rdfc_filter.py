"""The NL-means variant of RDFC's authors (Rousselle, Manzi, Zwicker 2013) and the steps around it,
as their CUDA/C++ code runs them: fbksd/fbksd-package ``denoisers/RDFC/src/`` at commit
3059e1480bf7d0eb5cd4a8a106e37fc06078c59f. Citations: ``C`` = ``featurefilter.cu``, ``F`` =
``multifilm.cpp``, ``H`` = ``featurefilter.h``; file:line. All arithmetic is float64 (theirs float32).

Images are (H, W, C) arrays here; :func:`nl_means` filters ``B`` buffers of one image with one set
of weights (``apply_weights`` loops over buffers, C:68-89).

* :func:`nl_means` -- ``FilterData`` (C:1138-1178) and ``FilterDataDelta`` (C:1181-1237). For each
  pair of window offsets +o, -o (half-plane loop, C:1151-1153) the neighbours are ``n1 = mirror(p+o)``,
  ``n2 = mirror(p-o)`` with the mirrored indices of ``CLAMP_MIRROR`` (C:40-41: -x below 0, 2N-x-2
  above). Colour weights (``UpdateWeights``, C:1432-1465): per pixel and channel the distances
  (``distance``, C:350-395)

      d1 = [(g_p - g_n1)^2 - (Vn_p + min(Vn_p, Vn_n1))] / (eps + k^2 (Vd_p + Vd_n1)),
      ds = [(g_p - (g_n1 + g_n2)/2)^2 - (Vn_p + (min(Vn_p,Vn_n1) + min(Vn_p,Vn_n2))/4)]
           / (eps + k^2 (Vd_p + (Vd_n1 + Vd_n2)/4)),

  (d2 as d1 with n2) averaged over channels; with ``use_diff_var=False`` every denominator is
  eps + k^2 * 2 Vd_p (C:386-390). eps = 1e-10 (``DISTANCE_EPSILON``, C:18). The three maps are
  box-averaged over the patch (2f+1)^2 (``conv_box``, truncated at the borders, C:255-280,1448-1451),
  turned into weights exp(-max(0, d)) (C:467-476), the weight maps box-averaged over
  (2 f_w + 1)^2 (C:1455-1458; f_w = f - PTC_RAD_D = f - 1 in ``PushData``, C:20,1029), and the
  symmetric weight blended in where both patch distances are below ``MAX_D2`` = 25 (C:19,479-491):
  a = clip(w_s / (w1 + w2) - 1, 0, 1), w_i <- a w_s + (1 - a) w_i (the threshold is the argument
  ``max_d2``, default ``MAX_D2``; ``-inf`` switches the blend off, a diagnostic). Feature weights
  (``dist_wgt_feat``, C:567-633): the same distances per pixel (no patch) with the feature's
  Vn (its residual variance) and Vd (its normaliser, :func:`feature_normaliser`), k = k_f, the same
  symmetric blend; the weight of a neighbour is the minimum over colour and every feature
  (C:497,628-629). Accumulation (C:68-89): w_max = max over all neighbour weights, floored at
  ``WEIGHT_EPSILON`` = 1e-3 (C:17,1148), is the centre pixel's weight (C:1175-1177).
* ``delta=True`` (``FilterDataDelta``, C:1181-1237, with ``distance_delta`` C:398-465 and
  ``update_weights_delta`` C:636-696): a second filter of the guide whose centre value is scaled by
  ``DELTA_SCALE`` = 1.01 (C:13) in the n = 0 patch term only (d_s = d + (s - b) / (2f+1)^2 with the
  fixed centre weight of C:1529, ``add_sym=false`` C:1533) and in the centre pixel's value
  (C:1198,1235), no weight box (C:1505-1508 have none); when only one of the scaled patch distances
  is below 25 the blend factor ``a`` of the unscaled weights is reused (C:685-689, kept). The
  derivative is F/(1e-10 + y - 1.01 y) - F_s/(1e-10 + y - 1.01 y) per channel (C:132-141,1349).

Around it: :func:`scaled_sample_variance` (``GetScaledSampleVariance``, C:1392-1412),
:func:`dual_buffer_variance` (``GetDataMeanVariance``, C:1415-1429), :func:`feature_normaliser`
(``sqr_gradient`` + ``get_var_th``, C:212-252,882-897), :func:`clamp_derivative` (C:1335-1370),
:func:`sure` (F:427-434, mean over channels F:639), :func:`select_candidate` (F:650-662).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import prange

from mcbench.filters.smoothing import box_mean, pyramid_smooth
from mcbench.jit import cached_njit

DELTA_SCALE = 1.01          # C:13
DELTA_OFFSET_DEN = 1e-10    # C:15
WEIGHT_EPSILON = 1e-3       # C:17
DISTANCE_EPSILON = 1e-10    # C:18
MAX_D2 = 25.0               # C:19
RATIO_EPSILON = 1e-10       # C:150,160
VARIANCE_BOX = 10           # C:1406-1409: 21 x 21 box of the dual-buffer rescaling
GRADIENT_STEP = 0.5         # C:224-225,234-235: one-sided differences divided by 2 ("half-pixel")


# ----------------------------------------------------------------------------- kernel

@cached_njit(error_model="numpy")
def _mirror(pos, n):
    """CLAMP_MIRROR (C:40-41), then clipped into [0, n) (only reached when the window is wider than
    the image; the authors' index would leave the buffer there)."""
    if pos < 0:
        pos = -pos
    elif pos >= n:
        pos = 2 * n - pos - 2
    return min(max(pos, 0), n - 1)


@cached_njit(error_model="numpy")
def _weight(d):
    """exp(-max(0, d)) (C:473-475,616-618)."""
    return 1.0 if d <= 0.0 else np.exp(-d)


@cached_njit(parallel=True, error_model="numpy")
def _box(src, tmp, dst, r):
    """conv_box (C:255-280) along x then y: mean over the in-image taps of a (2r+1) box."""
    h, w = src.shape
    for y in prange(h):
        for x in range(w):
            lo = max(x - r, 0)
            hi = min(x + r, w - 1)
            acc = 0.0
            for i in range(lo, hi + 1):
                acc += src[y, i]
            tmp[y, x] = acc / (hi - lo + 1)
    for y in prange(h):
        lo = max(y - r, 0)
        hi = min(y + r, h - 1)
        for x in range(w):
            acc = 0.0
            for i in range(lo, hi + 1):
                acc += tmp[i, x]
            dst[y, x] = acc / (hi - lo + 1)


@cached_njit(error_model="numpy", inline="always")
def _dist_one(gc, g1, g2, vc, vn1, vn2, vdc, vd1, vd2, k2, diff):
    """One channel of ``distance``/``distance_delta``/``dist_wgt_feat`` (C:350-465,575-605) at one
    pixel: centre value gc, neighbours g1 (p+o) and g2 (p-o), their Vn and Vd. Returns the three
    normalised distances and those of the 1.01-scaled centre (C:440-446)."""
    eps = DISTANCE_EPSILON
    v1 = min(vc, vn1)
    v2 = min(vc, vn2)
    if diff:
        den1 = eps + k2 * (vdc + vd1)
        den2 = eps + k2 * (vdc + vd2)
        den3 = eps + k2 * (vdc + (vd1 + vd2) / 4.0)
    else:
        den1 = eps + k2 * (vdc * 2.0)
        den2 = den1
        den3 = den1
    r1 = vc + v1
    r2 = vc + v2
    r3 = vc + (v1 + v2) / 4.0
    m = (g1 + g2) / 2.0
    gs = DELTA_SCALE * gc
    q1 = gc - g1
    q2 = gc - g2
    q3 = gc - m
    u1 = gs - g1
    u2 = gs - g2
    u3 = gs - m
    return ((q1 * q1 - r1) / den1, (q2 * q2 - r2) / den2, (q3 * q3 - r3) / den3,
            (u1 * u1 - r1) / den1, (u2 * u2 - r2) / den2, (u3 * u3 - r3) / den3)


@cached_njit(error_model="numpy")
def _dist_rows(img, vn, vd, c0, c1, y, y1, y2, dx, lo, hi, mx1, mx2, k2, diff, delta, o1, o2, o3, s1, s2, s3):
    """Channel means over c0..c1 of the distances of row y for offset (dx, y1 - y) into o1, o2, o3
    (and, if ``delta``, the scaled ones into s1, s2, s3): the interior [lo, hi) has unmirrored
    neighbours x +- dx, the other columns the mirrored ones mx1, mx2."""
    w = o1.shape[0]
    inv = 1.0 / (c1 - c0)
    for x in range(w):
        x1 = x + dx if lo <= x < hi else mx1[x]
        x2 = x - dx if lo <= x < hi else mx2[x]
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        b1 = 0.0
        b2 = 0.0
        b3 = 0.0
        for c in range(c0, c1):
            t1, t2, t3, u1, u2, u3 = _dist_one(img[c, y, x], img[c, y1, x1], img[c, y2, x2],
                                               vn[c, y, x], vn[c, y1, x1], vn[c, y2, x2],
                                               vd[c, y, x], vd[c, y1, x1], vd[c, y2, x2], k2, diff)
            a1 += t1
            a2 += t2
            a3 += t3
            b1 += u1
            b2 += u2
            b3 += u3
        o1[x] = a1 * inv
        o2[x] = a2 * inv
        o3[x] = a3 * inv
        if delta:
            s1[x] = b1 * inv
            s2[x] = b2 * inv
            s3[x] = b3 * inv


@cached_njit(error_model="numpy")
def _sym(d1, d2, ds, w1, w2, max_d2):
    """Weights exp(-max(0, d)) of both neighbours with the symmetric blend (C:479-491,620-626) where
    both distances are below ``max_d2`` (-inf: never); returns (w1, w2, a) with ``w1``/``w2`` the
    weights when a is 0 (passed in, already computed)."""
    a = 0.0
    if d1 < max_d2 and d2 < max_d2:
        a = min(1.0, max(0.0, _weight(ds) / max(w1 + w2, 1e-300) - 1.0))
    if a > 0.0:
        ws = _weight(ds)
        w1 = a * ws + (1.0 - a) * w1
        w2 = a * ws + (1.0 - a) * w2
    return w1, w2, a


@cached_njit(error_model="numpy")
def _axpy2(out, d1, u1, d2, u2):
    for i in range(out.shape[0]):
        out[i] += d1[i] * u1[i] + d2[i] * u2[i]


@cached_njit(parallel=True, error_model="numpy")
def _nlm_kernel(data, g, vn, vd, feat, fvn, fvd, fstart, wnd, ptcs, ptc_wgt, k2c, colour, diff_c,
                k2f, diff_f, delta, max_d2):
    """See :func:`nl_means`. data (B, C, H, W); g, vn, vd (Cg, H, W); feat, fvn, fvd (Cf, H, W);
    ptcs (K,) patch radii: K filters that differ only in the patch radius, sharing the per-pixel
    distances and the feature weights of each offset (FIRST and SECOND). ``max_d2``: threshold of
    the symmetric blend (``MAX_D2``; -inf turns the blend off). Returns (K, B, C, H, W)
    outputs, (K, H, W) w_max and sum w, (K, Cg, H, W) scaled filters."""
    nb, nc, h, w = data.shape
    nk = ptcs.shape[0]
    cg = g.shape[0]
    nfeat = fstart.shape[0] - 1
    out = np.zeros((nk, nb, nc, h, w))
    wsum = np.zeros((nk, h, w))
    wmax = np.full((nk, h, w), WEIGHT_EPSILON)
    outs = np.zeros((nk, cg, h, w))
    wsum_s = np.zeros((nk, h, w))
    wmax_s = np.full((nk, h, w), WEIGHT_EPSILON)
    d1 = np.zeros((h, w))
    d2 = np.zeros((h, w))
    ds = np.zeros((h, w))
    s1 = np.zeros((h, w))
    s2 = np.zeros((h, w))
    ss = np.zeros((h, w))
    p1 = np.zeros((h, w))
    p2 = np.zeros((h, w))
    ps = np.zeros((h, w))
    e1 = np.zeros((h, w))
    e2 = np.zeros((h, w))
    es = np.zeros((h, w))
    tmp = np.zeros((h, w))
    w1 = np.zeros((nk, h, w))
    w2 = np.zeros((nk, h, w))
    w1s = np.zeros((nk, h, w))
    w2s = np.zeros((nk, h, w))
    mx1 = np.zeros(w, dtype=np.int64)
    mx2 = np.zeros(w, dtype=np.int64)
    for dy in range(-wnd, 1):
        dx_max = -1 if dy == 0 else wnd
        for dx in range(-wnd, dx_max + 1):
            for x in range(w):
                mx1[x] = _mirror(x + dx, w)
                mx2[x] = _mirror(x - dx, w)
            lo = min(abs(dx), w)
            hi = max(w - abs(dx), lo)
            w1[:] = 1.0
            w2[:] = 1.0
            w1s[:] = 1.0
            w2s[:] = 1.0
            if colour:
                for y in prange(h):
                    _dist_rows(g, vn, vd, 0, cg, y, _mirror(y + dy, h), _mirror(y - dy, h), dx, lo, hi, mx1, mx2,
                               k2c, diff_c, delta, d1[y], d2[y], ds[y], s1[y], s2[y], ss[y])
                for k in range(nk):
                    ptc = ptcs[k]
                    wc = 1.0 / ((2 * ptc + 1) * (2 * ptc + 1))
                    if ptc > 0:
                        _box(d1, tmp, p1, ptc)
                        _box(d2, tmp, p2, ptc)
                        _box(ds, tmp, ps, ptc)
                    else:
                        p1[:] = d1
                        p2[:] = d2
                        ps[:] = ds
                    if delta:
                        for y in prange(h):
                            for x in range(w):
                                n1 = p1[y, x]
                                n2 = p2[y, x]
                                c1, c2, a = _sym(n1, n2, ps[y, x], _weight(n1), _weight(n2), max_d2)
                                m1 = n1 + wc * (s1[y, x] - d1[y, x])
                                m2 = n2 + wc * (s2[y, x] - d2[y, x])
                                m3 = ps[y, x] + wc * (ss[y, x] - ds[y, x])
                                t1 = _weight(m1)
                                t2 = _weight(m2)
                                if m1 < max_d2 and m2 < max_d2:       # else a is kept (C:685-689)
                                    a = min(1.0, max(0.0, _weight(m3) / max(t1 + t2, 1e-300) - 1.0))
                                if a > 0.0:
                                    t3 = _weight(m3)
                                    t1 = a * t3 + (1.0 - a) * t1
                                    t2 = a * t3 + (1.0 - a) * t2
                                w1[k, y, x] = min(w1[k, y, x], c1)
                                w2[k, y, x] = min(w2[k, y, x], c2)
                                w1s[k, y, x] = min(w1s[k, y, x], t1)
                                w2s[k, y, x] = min(w2s[k, y, x], t2)
                    else:
                        for y in prange(h):
                            for x in range(w):
                                e1[y, x] = _weight(p1[y, x])
                                e2[y, x] = _weight(p2[y, x])
                                es[y, x] = _weight(ps[y, x])
                        if ptc_wgt > 0:
                            _box(e1, tmp, e1, ptc_wgt)
                            _box(e2, tmp, e2, ptc_wgt)
                            _box(es, tmp, es, ptc_wgt)
                        for y in prange(h):
                            for x in range(w):
                                a = 0.0
                                if p1[y, x] < max_d2 and p2[y, x] < max_d2:
                                    a = min(1.0, max(0.0, es[y, x] / max(e1[y, x] + e2[y, x], 1e-300) - 1.0))
                                w1[k, y, x] = min(w1[k, y, x], a * es[y, x] + (1.0 - a) * e1[y, x])
                                w2[k, y, x] = min(w2[k, y, x], a * es[y, x] + (1.0 - a) * e2[y, x])
            for y in prange(h):
                y1 = _mirror(y + dy, h)
                y2 = _mirror(y - dy, h)
                f1 = np.empty(w)
                f2 = np.empty(w)
                f3 = np.empty(w)
                for j in range(nfeat):
                    _dist_rows(feat, fvn, fvd, fstart[j], fstart[j + 1], y, y1, y2, dx, lo, hi, mx1, mx2,
                               k2f, diff_f, False, f1, f2, f3, f1, f2, f3)
                    for x in range(w):
                        c1, c2, a = _sym(f1[x], f2[x], f3[x], _weight(f1[x]), _weight(f2[x]), max_d2)
                        for k in range(nk):
                            w1[k, y, x] = min(w1[k, y, x], c1)
                            w2[k, y, x] = min(w2[k, y, x], c2)
                            w1s[k, y, x] = min(w1s[k, y, x], c1)
                            w2s[k, y, x] = min(w2s[k, y, x], c2)
                for k in range(nk):
                    for x in range(w):
                        wmax[k, y, x] = max(wmax[k, y, x], max(w1[k, y, x], w2[k, y, x]))
                        wsum[k, y, x] += w1[k, y, x] + w2[k, y, x]
                    for b in range(nb):
                        for c in range(nc):
                            if hi > lo:
                                _axpy2(out[k, b, c, y, lo:hi], data[b, c, y1, lo + dx:hi + dx], w1[k, y, lo:hi],
                                       data[b, c, y2, lo - dx:hi - dx], w2[k, y, lo:hi])
                            for x in range(w):
                                if x < lo or x >= hi:
                                    out[k, b, c, y, x] += (data[b, c, y1, mx1[x]] * w1[k, y, x]
                                                           + data[b, c, y2, mx2[x]] * w2[k, y, x])
                    if delta:
                        for x in range(w):
                            wmax_s[k, y, x] = max(wmax_s[k, y, x], max(w1s[k, y, x], w2s[k, y, x]))
                            wsum_s[k, y, x] += w1s[k, y, x] + w2s[k, y, x]
                        for c in range(cg):
                            if hi > lo:
                                _axpy2(outs[k, c, y, lo:hi], g[c, y1, lo + dx:hi + dx], w1s[k, y, lo:hi],
                                       g[c, y2, lo - dx:hi - dx], w2s[k, y, lo:hi])
                            for x in range(w):
                                if x < lo or x >= hi:
                                    outs[k, c, y, x] += (g[c, y1, mx1[x]] * w1s[k, y, x]
                                                         + g[c, y2, mx2[x]] * w2s[k, y, x])
    for y in prange(h):
        for k in range(nk):
            for x in range(w):
                wsum[k, y, x] += wmax[k, y, x]
                for b in range(nb):
                    for c in range(nc):
                        out[k, b, c, y, x] = (out[k, b, c, y, x] + data[b, c, y, x] * wmax[k, y, x]) / wsum[k, y, x]
                if delta:
                    wsum_s[k, y, x] += wmax_s[k, y, x]
                    for c in range(cg):
                        outs[k, c, y, x] = ((outs[k, c, y, x] + DELTA_SCALE * g[c, y, x] * wmax_s[k, y, x])
                                            / wsum_s[k, y, x])
    return out, wmax, wsum, outs


# ----------------------------------------------------------------------------- API

@dataclass(frozen=True)
class Feature:
    """One feature as the filter sees it: ``value`` (H, W, C) (the mean of the two prefiltered
    buffers, C:869), ``variance`` (H, W, C) its residual variance (C:870), ``tau`` its threshold."""

    value: np.ndarray
    variance: np.ndarray
    tau: float


@dataclass(frozen=True)
class Filtered:
    """Result of :func:`nl_means`: ``buffers`` (B, H, W, C) filtered buffers; ``centre`` (H, W)
    w_max / (1e-10 + sum w) (``ratio``, C:1339 with C:150); ``scaled`` (H, W, Cg) the filter of the guide with its centre scaled by
    1.01 (``delta=True`` only, else None)."""

    buffers: np.ndarray
    centre: np.ndarray
    scaled: np.ndarray | None


def _planes(a):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    return np.ascontiguousarray(np.moveaxis(a, -1, 0))


def feature_gradient_sq(feature) -> np.ndarray:
    """``sqr_gradient`` (C:212-242) of an (H, W, C) feature, (H, W, C): per axis the smaller square of
    the two one-sided half-pixel differences ((f(x +- 1) - f(x)) / 2), horizontal + vertical; an
    axis contributes 0 within one pixel of its borders (C:221,231)."""
    f = np.asarray(feature, dtype=np.float64)
    if f.ndim == 2:
        f = f[..., None]
    out = np.zeros_like(f)
    for axis in (0, 1):
        n = f.shape[axis]
        if n < 3:
            continue
        c = [slice(None)] * 3
        lo, mid, hi = list(c), list(c), list(c)
        lo[axis], mid[axis], hi[axis] = slice(0, n - 2), slice(1, n - 1), slice(2, n)
        g1 = (f[tuple(lo)] - f[tuple(mid)]) * GRADIENT_STEP
        g2 = (f[tuple(hi)] - f[tuple(mid)]) * GRADIENT_STEP
        out[tuple(mid)] += np.minimum(g1 * g1, g2 * g2)
    return out


def feature_normaliser(feature, variance, tau: float) -> np.ndarray:
    """``features_var_den`` (C:245-252,882-897, use_grad = true, scale 1): per channel
    max(Var, max(grad^2, tau)), (H, W, C)."""
    var = np.asarray(variance, dtype=np.float64)
    grad = feature_gradient_sq(feature)
    return np.maximum(var.reshape(grad.shape), np.maximum(grad, tau))


def scaled_sample_variance(buffer_a, buffer_b, sample_variance, radius: int = VARIANCE_BOX) -> np.ndarray:
    """``GetScaledSampleVariance`` (C:1392-1412) + ``scale_sample_variance`` (C:155-162): the
    per-pixel sample variance of the mean V rescaled by the dual-buffer estimate,
    V * box(V_dual) / (1e-10 + box(V)), V_dual = (A - B)^2 / 4 (the two-buffer variance of the
    mean, C:1399-1403), box = (2 radius + 1)^2 truncated at the borders; float64, shape of V."""
    a = np.asarray(buffer_a, dtype=np.float64)
    b = np.asarray(buffer_b, dtype=np.float64)
    v = np.maximum(np.asarray(sample_variance, dtype=np.float64), 0.0)
    dual = (a - b) ** 2 / 4.0
    return v * box_mean(dual, radius) / (RATIO_EPSILON + box_mean(v, radius))


def dual_buffer_variance(buffer_a, buffer_b) -> np.ndarray:
    """``GetDataMeanVariance`` (C:1415-1429): (A - B)^2 / 4 per channel, smoothed by the separable
    [0.1353, 1, 0.1353] kernel (``conv_pyr``, C:319-347; H:148); float64."""
    a = np.asarray(buffer_a, dtype=np.float64)
    b = np.asarray(buffer_b, dtype=np.float64)
    return pyramid_smooth((a - b) ** 2 / 4.0)


def nl_means(buffers, guide, guide_variance, *, radius: int, patch_radius, weight_radius: int,
             k: float, use_colour: bool = True, use_diff_var: bool = True, features=(),
             feature_k: float = 0.6, feature_diff_var: bool | None = None, delta: bool = False,
             guide_variance_den=None, max_d2: float = MAX_D2) -> Filtered:
    """The authors' NL-means (module docstring) of ``buffers`` (B, H, W, C) with shared weights.

    ``guide`` (H, W, Cg): colour guide (the buffers' mean in the authors' calls); ``guide_variance``:
    its Vn (and Vd unless ``guide_variance_den`` is given). ``radius``: window radius; ``patch_radius``
    f, or a tuple of radii: then a list of results, one per radius, of filters identical but for f
    (FIRST and SECOND, computed together: same per-pixel distances and feature weights);
    ``weight_radius``: radius of the box on the weight maps (the authors: f - 1, and 0 for the
    candidates' ``delta`` filter and for THIRD, C:1048). ``k``: k_c (``var_den_scale = k^2``);
    ``use_colour=False``: feature weights only (THIRD, ``feat_only``, C:1028,1157). ``features``: a
    sequence of :class:`Feature`; their normaliser is :func:`feature_normaliser` with their tau;
    ``feature_diff_var`` (default ``use_diff_var``): p+q (True) or 2p (False) denominators.
    ``delta``: also the scaled filter of the guide (needs ``weight_radius == 0``). ``max_d2``: the
    symmetric blend's threshold on both distances (default ``MAX_D2`` = 25, C:19); ``-inf`` turns the
    blend off, leaving w_i = exp(-max(0, d_i)) (a merely negative value would not: distances net of
    the variance can be negative).
    """
    if np.isnan(max_d2):
        raise ValueError("max_d2 must be a number (25: the authors'; -inf: no symmetric blend), got nan")
    bufs = np.asarray(buffers, dtype=np.float64)
    if bufs.ndim == 3:
        bufs = bufs[..., None]
    if delta and weight_radius:
        raise ValueError("delta=True has no weight box in the authors' code (C:1489-1534): pass weight_radius=0")
    data = np.ascontiguousarray(np.moveaxis(bufs, -1, 1))
    h, w = data.shape[2:]
    g = _planes(guide)
    vn = _planes(np.maximum(np.nan_to_num(guide_variance), 0.0))
    vd = vn if guide_variance_den is None else _planes(np.maximum(guide_variance_den, 0.0))
    fstart = [0]
    values, vnums, vdens = [], [], []
    for f in features:
        value = np.asarray(f.value, dtype=np.float64)
        if value.ndim == 2:
            value = value[..., None]
        var = np.maximum(np.asarray(f.variance, dtype=np.float64).reshape(value.shape), 0.0)
        values.append(_planes(value))
        vnums.append(_planes(var))
        vdens.append(_planes(feature_normaliser(value, var, f.tau)))
        fstart.append(fstart[-1] + value.shape[2])
    if values:
        feat, fvn, fvd = (np.ascontiguousarray(np.concatenate(x, axis=0)) for x in (values, vnums, vdens))
    else:
        feat = fvn = fvd = np.zeros((1, h, w))
    diff_f = use_diff_var if feature_diff_var is None else feature_diff_var
    radii = np.atleast_1d(np.asarray(patch_radius, dtype=np.int64))
    out, wmax, wsum, outs = _nlm_kernel(data, g, vn, vd, feat, fvn, fvd, np.asarray(fstart, dtype=np.int64),
                                        int(radius), radii, int(weight_radius), float(k) ** 2,
                                        bool(use_colour), bool(use_diff_var), float(feature_k) ** 2,
                                        bool(diff_f), bool(delta), float(max_d2))
    results = [Filtered(buffers=np.moveaxis(out[i], 1, -1), centre=wmax[i] / (RATIO_EPSILON + wsum[i]),
                        scaled=np.moveaxis(outs[i], 0, -1) if delta else None) for i in range(len(radii))]
    return results if np.ndim(patch_radius) else results[0]


def finite_difference_derivative(filtered, scaled, guide) -> np.ndarray:
    """``derivative`` (C:132-141,1349): F / (1e-10 + y - 1.01 y) - F_s / (1e-10 + y - 1.01 y) per
    channel, F the filtered guide, F_s the scaled filter; float64, (H, W, C). Non-finite values are
    kept as IEEE arithmetic gives them, as the authors' kernel has no guard: where the denominator
    is 0 (y = +-inf, or a y ~ 1e-8 whose two roundings cancel) the result is +-inf (then replaced by
    w_max / sum w in :func:`clamp_derivative`, C:1364) or NaN (which passes the clamp, whose
    comparisons are false for NaN, and makes that candidate's SURE NaN: never selected)."""
    y = np.asarray(guide, dtype=np.float64)
    den = DELTA_OFFSET_DEN + y - DELTA_SCALE * y
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.asarray(filtered, dtype=np.float64) / den - np.asarray(scaled, dtype=np.float64) / den


def clamp_derivative(derivative, centre) -> np.ndarray:
    """C:1361-1369: where any channel of dF/dy (H, W, 3) lies outside [0, 1], all three become
    w_max / sum w (``centre``, (H, W)); +-inf is outside, NaN is not (its comparisons are false, so
    a NaN channel stays NaN unless another channel is outside)."""
    d = np.asarray(derivative, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        invalid = np.any((d < 0.0) | (d > 1.0), axis=-1, keepdims=True)
    return np.where(invalid, np.asarray(centre)[..., None], d)


def sure(filtered, derivative, color, variance) -> np.ndarray:
    """``ComputeSURE`` (F:427-434, var_scale 1) averaged over channels (``rgb2avg``, F:639):
    mean_c [(F - y)^2 + 2 dF/dy sigma^2 - sigma^2], (H, W)."""
    v = np.asarray(variance, dtype=np.float64)
    e = (np.asarray(filtered) - np.asarray(color)) ** 2 + 2.0 * np.asarray(derivative) * v - v
    return e.mean(axis=-1)


def select_candidate(errors, derivative_first, derivative_second, *, index_bug: bool = True) -> np.ndarray:
    """The selection rule of F:650-662: (H, W) int index of the chosen candidate.

    ``errors`` (K, H, W) filtered SURE maps. Candidates are visited from the last to the first with a
    strict ``<`` against the running minimum, which starts at +inf (F:652; ties go to the higher
    index). A pixel where no candidate passes (every eligible SURE NaN or +inf) keeps the map's
    initial 0, FIRST: ``sel_map`` is zero-initialised (``resize``, F:87) and only written at F:658
    before this point of the driver's single ``WriteImage`` (F:480-486). The first (FIRST) is
    eligible only if mean_c dF/dy(FIRST)_p <= the mean of three entries of SECOND's derivative. The
    authors' code reads those as ``derivatives[1][pix]`` (F:656): the flat (pixel-major, channel-minor)
    entries pix, pix+1, pix+2 instead of 3 pix..3 pix+2, an index bug followed by default;
    ``index_bug=False`` reads pixel p's own three channels."""
    err = np.asarray(errors, dtype=np.float64)
    k, h, w = err.shape
    first = np.asarray(derivative_first, dtype=np.float64).reshape(h, w, 3).mean(axis=-1)
    second = np.asarray(derivative_second, dtype=np.float64).reshape(h, w, 3)
    if index_bug:
        flat = np.concatenate([second.ravel(), np.zeros(2)])
        pix = np.arange(h * w)
        second_mean = ((flat[pix] + flat[pix + 1] + flat[pix + 2]) / 3.0).reshape(h, w)
    else:
        second_mean = second.mean(axis=-1)
    best = np.full((h, w), np.inf)
    sel = np.zeros((h, w), dtype=np.int64)                  # F:87: sel_map starts at 0 (FIRST)
    for i in range(k - 1, -1, -1):
        with np.errstate(invalid="ignore"):
            better = err[i] < best
            if i == 0 and k > 1:
                better &= first <= second_mean
        best = np.where(better, err[i], best)
        sel = np.where(better, i, sel)
    return sel
