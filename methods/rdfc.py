"""RDFC: Robust Denoising using Feature and Color information (Rousselle, Manzi and Zwicker,
Computer Graphics Forum 32(7), Pacific Graphics 2013), base denoiser #8 of Zheng et al. 2021.

Pipeline (section numbers of the RDFC paper as we understand them from its public
descriptions; the paper text was not available, so "Sec." references are to its structure):

1. **Feature prefiltering** (Sec. 4.1). Albedo, normal and depth of each half buffer are
   NL-means filtered (:func:`mcbench.nlmeans.nl_means_filter`, RKZ12 Eq. 5-6) guided by
   themselves and their per-pixel variance. The residual variance of the prefiltered feature
   is re-estimated from the two half buffers, ``(f~_A - f~_B)^2 / 2``, box-smoothed.
2. **Joint weights** (Sec. 4.2, 4.3). ``w(p, q) = min(w_c(p, q), w_f(p, q))`` with
   * colour weight (NL-means with variance cancellation, RKZ12):
     ``d_c^2 = mean_{n in patch, channels i} [(u_i(p+n) - u_i(q+n))^2 - alpha (V_i(p+n) +
     min(V_i(p+n), V_i(q+n)))] / (eps + k_c^2 (V_i(p+n) + V_i(q+n)))``,
     ``w_c = exp(-max(0, d_c^2))``;
   * feature weight: for feature j (mean over its channels of squared differences)
     ``Phi_j^2 = [|f_j(p) - f_j(q)|^2 - (Var_j(p) + min(Var_j(p), Var_j(q)))] /
     (k_f^2 max(tau, Var_j(p), |Grad_j(p)|^2))``, ``w_f = exp(-max_j max(0, Phi_j^2))``.
3. **Three candidate filters** (Sec. 5), all with window radius r = 10 and k_f = 0.6:
   FIRST  k_c = 0.45, patch radius f = 1; SECOND k_c = 0.45, f = 3; THIRD k_c = inf
   (feature weights only). ``F_p = sum_q w_pq y_q / sum_q w_pq``.
4. **SURE** (Sec. 5.1): per pixel and channel
   ``SURE = (F(y) - y)^2 + 2 sigma^2 dF/dy - sigma^2`` with sigma^2 the variance of the mean.
   In the first pass the colour weights depend on y; :func:`candidate_filters` returns the
   exact derivative ``dF_p/dy_p = (w_pp + sum_q dw_pq/dy_p (y_q - F_p)) / sum_q w_pq``, where
   ``dw_pq/dy_p`` collects the two patch terms in which y_p enters d_c^2(p, q) (position n = 0
   and n = p - q).
5. **Selection** (Sec. 5.2): the per-pixel SURE maps (summed over channels) are NL-means
   filtered, the per-pixel argmin gives binary selection maps, those are filtered with the same
   filter and used as blending weights of the candidates.
6. **Second pass** (Sec. 5.3): the candidates are recomputed with colour weights taken from
   the first-pass output of the *other* half buffer (its propagated variance as guide
   variance). Weights then do not depend on the filtered buffer, so dF_p/dy_p = w_pp / sum w
   and SURE is exact; selection as in 5.

Half buffers A and B are each denoised this way (they are the internal buffers RDFC needs
for the feature variance and the second pass); ``Denoised.a``/``.b`` are the two results and
``Denoised.full = (a + b) / 2``.

Constants (published ones first, then ours with the reason):

* r = 10, k_c = 0.45, k_f = 0.6, FIRST f = 1, SECOND f = 3, THIRD k_c = inf, tau = 1e-3,
  alpha = 1 (variance cancellation), prefilter r = 5, f = 3, k = 0.5: published values as
  reported in RDFC / NFOR descriptions (the prefilter triple is the one NFOR reuses from RDFC).
* eps = 1e-10 in the colour-distance denominator: guards the zero-variance case (same value
  as mcbench.nlmeans).
* Feature gradient ``|Grad_j(p)|^2``: per axis the smaller of the two one-sided differences
  (so the normaliser is not inflated across an edge), summed over axes, mean over channels.
* Prefiltered-feature variance smoothed with a 3x3 box: the raw dual-buffer squared
  difference is a one-sample estimate.
* Error/selection map filter: NL-means r = 3, f = 1, k = 1.0, guided by the noisy colour
  (pass 1) or the other buffer's first-pass output (pass 2): small window keeps selection
  local, k = 1 is the usual NL-means strength.
* Kernel tile size 128 px (+ halo r + max f): keeps the per-offset maps and accumulators in
  cache; results are identical to the untiled kernel (tested).
* Argmin ties resolve to the lowest index (FIRST): on noise-free input FIRST reproduces it.
* Propagated output variance ``sum w^2 V / (sum w)^2`` ignores weight/colour correlation;
  the blend's variance is approximated by ``sum_k s_k Var_k``; used only as a guide variance.

Departures from the paper: the SURE map filter parameters and the second-pass guide (other
buffer's first-pass output, to make the second-pass SURE exact) are our choices; we use the
renderer's per-pixel variance directly (no dual-buffer rescaling of the colour variance);
the visibility/direct-light feature of the paper is not rendered, so only albedo, normal and
depth are used; patch distances at image borders average only the in-image patch pairs.
"""

from __future__ import annotations

import numpy as np
from numba import prange
from scipy.ndimage import uniform_filter

from mcbench.buffers import Denoised, RenderBuffers
from mcbench.jit import cached_njit
from mcbench.nlmeans import nl_means_filter
from mcbench.progress import StageLog

KIND = "denoiser"
LABEL = "#8 RDFC"

WINDOW_RADIUS = 10
K_COLOR = 0.45
K_FEATURE = 0.6
TAU = 1e-3
ALPHA = 1.0
EPSILON = 1e-10
CANDIDATE_PATCH_RADII = (1, 3, 0)          # FIRST, SECOND, THIRD
CANDIDATE_K_COLOR = (K_COLOR, K_COLOR, np.inf)
CANDIDATE_NAMES = ("FIRST", "SECOND", "THIRD")
PREFILTER = dict(radius=5, patch_radius=3, k=0.5)
SELECTION_FILTER = dict(radius=3, patch_radius=1, k=1.0)
FEATURES = ("albedo", "normal", "depth")
TILE = 128


# ----------------------------------------------------------------------------- kernels

@cached_njit(parallel=True)
def _pair_maps(g, gv, dy, dx, kc, alpha, eps, m, valid, grad):
    """For offset o = (dy, dx): m(x) = mean_i Delta_i(x, x+o), valid(x), and per channel
    grad_i(x) = 2 (g_i(x) - g_i(x+o)) / den_i (derivative of Delta_i wrt g_i(x))."""
    h, w, nc = g.shape
    for y in prange(h):
        yq = y + dy
        for x in range(w):
            xq = x + dx
            if yq < 0 or yq >= h or xq < 0 or xq >= w:
                m[y, x] = 0.0
                valid[y, x] = 0.0
                for c in range(nc):
                    grad[y, x, c] = 0.0
                continue
            s = 0.0
            for c in range(nc):
                vp = gv[y, x, c]
                vq = gv[yq, xq, c]
                den = eps + kc * kc * (vp + vq)
                diff = g[y, x, c] - g[yq, xq, c]
                s += (diff * diff - alpha * (vp + min(vp, vq))) / den
                grad[y, x, c] = 2.0 * diff / den
            m[y, x] = s / nc
            valid[y, x] = 1.0


@cached_njit(parallel=True)
def _integral(a, out):
    """out[y+1, x+1] = sum of a[:y+1, :x+1] (float64)."""
    h, w = a.shape
    for y in prange(h):
        acc = 0.0
        for x in range(w):
            acc += a[y, x]
            out[y + 1, x + 1] = acc
    for x in prange(w):
        for y in range(h):
            out[y + 1, x + 1] += out[y, x + 1]


@cached_njit()
def _box(ii, y0, x0, y1, x1):
    return ii[y1 + 1, x1 + 1] - ii[y0, x1 + 1] - ii[y1 + 1, x0] + ii[y0, x0]


@cached_njit(parallel=True)
def _candidates_kernel(y_img, v_img, g, gv, feat, fvar, fnorm, fstart, radius, patch_radii,
                       k_colors, self_guided, alpha, eps):
    """Joint-weight filters of y_img for every candidate; see :func:`candidate_filters`."""
    h, w, nc = y_img.shape
    ncand = patch_radii.shape[0]
    nfeat = fstart.shape[0] - 1
    wsum = np.zeros((ncand, h, w))
    wself = np.zeros((ncand, h, w))
    wy = np.zeros((ncand, h, w, nc))
    w2v = np.zeros((ncand, h, w, nc))
    sdw = np.zeros((ncand, h, w, nc))
    sdwy = np.zeros((ncand, h, w, nc))
    m = np.zeros((h, w))
    valid = np.zeros((h, w))
    grad = np.zeros((h, w, nc))
    im = np.zeros((h + 1, w + 1))
    iv = np.zeros((h + 1, w + 1))
    need_colour = False
    for k in range(ncand):
        if np.isfinite(k_colors[k]):
            need_colour = True
    kc0 = 0.0
    for k in range(ncand):
        if np.isfinite(k_colors[k]):
            kc0 = k_colors[k]
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if need_colour:
                _pair_maps(g, gv, dy, dx, kc0, alpha, eps, m, valid, grad)
                _integral(m, im)
                _integral(valid, iv)
            for y in prange(h):
                yq = y + dy
                if yq < 0 or yq >= h:
                    continue
                for x in range(w):
                    xq = x + dx
                    if xq < 0 or xq >= w:
                        continue
                    # feature weight (pixel-wise, max over features)
                    dfeat = 0.0
                    for j in range(nfeat):
                        dist = 0.0
                        for c in range(fstart[j], fstart[j + 1]):
                            diff = feat[y, x, c] - feat[yq, xq, c]
                            dist += diff * diff
                        dist /= max(fstart[j + 1] - fstart[j], 1)
                        vp = fvar[y, x, j]
                        phi = (dist - (vp + min(vp, fvar[yq, xq, j]))) / fnorm[y, x, j]
                        if phi > dfeat:
                            dfeat = phi
                    wf = np.exp(-dfeat)
                    for k in range(ncand):
                        wc = 1.0
                        d2 = 0.0
                        cnt = 1.0
                        pr = patch_radii[k]
                        if np.isfinite(k_colors[k]):
                            y0 = max(y - pr, 0)
                            y1 = min(y + pr, h - 1)
                            x0 = max(x - pr, 0)
                            x1 = min(x + pr, w - 1)
                            cnt = max(_box(iv, y0, x0, y1, x1), 1.0)
                            d2 = _box(im, y0, x0, y1, x1) / cnt
                            wc = np.exp(-max(d2, 0.0))
                        wt = min(wc, wf)
                        wsum[k, y, x] += wt
                        if dy == 0 and dx == 0:
                            wself[k, y, x] = wt
                        for c in range(nc):
                            wy[k, y, x, c] += wt * y_img[yq, xq, c]
                            w2v[k, y, x, c] += wt * wt * v_img[yq, xq, c]
                        if self_guided and np.isfinite(k_colors[k]) and wc < wf and d2 > 0.0:
                            back = (abs(dy) <= pr and abs(dx) <= pr and y - dy >= 0 and y - dy < h
                                    and x - dx >= 0 and x - dx < w)
                            for c in range(nc):
                                dd2 = grad[y, x, c]
                                if back:
                                    dd2 -= grad[y - dy, x - dx, c]
                                dwt = -wc * dd2 / (nc * cnt)
                                sdw[k, y, x, c] += dwt
                                sdwy[k, y, x, c] += dwt * y_img[yq, xq, c]
    out = np.zeros((ncand, h, w, nc))
    deriv = np.zeros((ncand, h, w, nc))
    outvar = np.zeros((ncand, h, w, nc))
    for k in range(ncand):
        for y in prange(h):
            for x in range(w):
                cs = max(wsum[k, y, x], 1e-300)
                for c in range(nc):
                    f = wy[k, y, x, c] / cs
                    out[k, y, x, c] = f
                    outvar[k, y, x, c] = w2v[k, y, x, c] / (cs * cs)
                    deriv[k, y, x, c] = (wself[k, y, x] + sdwy[k, y, x, c] - f * sdw[k, y, x, c]) / cs
    return out, deriv, outvar


# ----------------------------------------------------------------------------- building blocks

def feature_gradient_sq(feature: np.ndarray) -> np.ndarray:
    """|Grad f|^2 of a (H, W, C) feature: per axis min(|forward|, |backward|) difference
    (one-sided at borders), squared, summed over axes, mean over channels -> (H, W)."""
    f = np.asarray(feature, dtype=np.float64)
    out = np.zeros(f.shape[:2])
    for axis in (0, 1):
        if f.shape[axis] < 2:          # no neighbour along this axis: no gradient (1-pixel images)
            continue
        d = np.abs(np.diff(f, axis=axis))
        pad_lo = [(0, 0)] * 3
        pad_hi = [(0, 0)] * 3
        pad_lo[axis] = (1, 0)
        pad_hi[axis] = (0, 1)
        fwd = np.pad(d, pad_hi, mode="edge")    # |f(x+1) - f(x)|, edge-replicated at the end
        bwd = np.pad(d, pad_lo, mode="edge")    # |f(x) - f(x-1)|
        out += (np.minimum(fwd, bwd) ** 2).mean(axis=2)
    return out


def feature_normaliser(feature: np.ndarray, feature_variance: np.ndarray, k_f: float = K_FEATURE,
                       tau: float = TAU) -> np.ndarray:
    """k_f^2 max(tau, Var_j(p), |Grad_j(p)|^2) for one feature: (H, W), strictly positive."""
    var = np.asarray(feature_variance, dtype=np.float64)
    return k_f * k_f * np.maximum(np.maximum(tau, var), feature_gradient_sq(feature))


def candidate_filters(color, variance, features, feature_variances, guide=None, guide_variance=None,
                      radius: int = WINDOW_RADIUS, patch_radii=CANDIDATE_PATCH_RADII,
                      k_colors=CANDIDATE_K_COLOR, k_f: float = K_FEATURE, tau: float = TAU,
                      alpha: float = ALPHA, epsilon: float = EPSILON, tile: int | None = TILE):
    """The candidate filters (FIRST, SECOND, THIRD by default) of one image.

    color, variance: (H, W, 3) noisy colour and variance of its mean. features: list of
    (H, W, C_j) or (H, W) arrays (prefiltered), feature_variances: list of (H, W) (or
    (H, W, C_j), averaged over channels) residual variances. ``guide``/``guide_variance``:
    colour used for the colour weights; None means the colour itself (self-guided, pass 1),
    in which case the returned derivative includes the weights' dependence on the colour.

    Returns ``(filtered, derivative, output_variance)``, each (K, H, W, 3) float64:
    F_k(y), dF_k,p,c / dy_p,c and sum w^2 V / (sum w)^2. ``tile`` (pixels, None = whole
    image) only changes speed: the image is processed in tiles with a halo.
    """
    finite_k = {float(k) for k in k_colors if np.isfinite(k)}
    if len(finite_k) > 1:
        raise ValueError(f"candidates must share one finite k_c, got {sorted(finite_k)}")
    y = np.ascontiguousarray(color, dtype=np.float64)
    v = np.ascontiguousarray(np.maximum(np.nan_to_num(variance), 0.0), dtype=np.float64)
    self_guided = guide is None
    g = y if self_guided else np.ascontiguousarray(guide, dtype=np.float64)
    gv = v if self_guided else np.ascontiguousarray(np.maximum(guide_variance, 0.0), dtype=np.float64)
    h, w = y.shape[:2]
    feats, fvars, fnorms, fstart = [], [], [], [0]
    for f, fv in zip(features, feature_variances):
        f = np.asarray(f, dtype=np.float64)
        if f.ndim == 2:
            f = f[..., None]
        fv = np.maximum(np.asarray(fv, dtype=np.float64), 0.0)
        if fv.ndim == 3:
            fv = fv.mean(axis=2)
        feats.append(f)
        fvars.append(fv)
        fnorms.append(feature_normaliser(f, fv, k_f, tau))
        fstart.append(fstart[-1] + f.shape[2])
    if feats:
        feat = np.ascontiguousarray(np.concatenate(feats, axis=2))
        fvar = np.ascontiguousarray(np.stack(fvars, axis=2))
        fnorm = np.ascontiguousarray(np.stack(fnorms, axis=2))
    else:
        feat, fvar, fnorm = np.zeros((h, w, 1)), np.zeros((h, w, 0)), np.ones((h, w, 0))
    patch_radii = np.asarray(patch_radii, dtype=np.int64)
    args = (np.asarray(fstart, dtype=np.int64), int(radius), patch_radii,
            np.asarray(k_colors, dtype=np.float64), bool(self_guided), float(alpha), float(epsilon))
    tile = int(tile) if tile else max(h, w)
    halo = int(radius) + int(patch_radii.max(initial=0))
    if tile >= h and tile >= w:
        return _candidates_kernel(y, v, g, gv, feat, fvar, fnorm, *args)
    # Tiles with a halo of r + max f pixels give bit-identical interiors (every pixel, patch and
    # back-term a kept pixel touches lies inside its halo) and keep the working set in cache.
    outs = [np.zeros((len(patch_radii), h, w, 3)) for _ in range(3)]
    for y0 in range(0, h, tile):
        for x0 in range(0, w, tile):
            y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
            ya, xa = max(y0 - halo, 0), max(x0 - halo, 0)
            yb, xb = min(y1 + halo, h), min(x1 + halo, w)
            crop = (slice(ya, yb), slice(xa, xb))
            res = _candidates_kernel(*(np.ascontiguousarray(a[crop]) for a in (y, v, g, gv, feat, fvar, fnorm)),
                                     *args)
            for full, part in zip(outs, res):
                full[:, y0:y1, x0:x1] = part[:, y0 - ya:y1 - ya, x0 - xa:x1 - xa]
    return tuple(outs)


def sure(filtered, derivative, color, variance) -> np.ndarray:
    """Stein's unbiased risk estimate per pixel and channel (Sec. 5.1):
    (F - y)^2 + 2 sigma^2 dF/dy - sigma^2. Shapes broadcast ((K, H, W, 3) vs (H, W, 3))."""
    v = np.maximum(np.asarray(variance, dtype=np.float64), 0.0)
    y = np.asarray(color, dtype=np.float64)
    return (filtered - y) ** 2 + 2.0 * v * derivative - v


def select_and_blend(filtered, out_variance, errors, guide, guide_variance, **filter_params):
    """Filter the (K, H, W) error maps, take per-pixel argmin (ties -> lowest index), filter the
    binary selection maps with the same NL-means filter and blend the candidates (Sec. 5.2).

    Returns (blend (H, W, 3), blend variance (H, W, 3), selection weights (H, W, K))."""
    params = dict(SELECTION_FILTER, **filter_params)
    err = np.moveaxis(errors, 0, -1)
    err_f = nl_means_filter(err, guide, guide_variance, **params)
    ncand = errors.shape[0]
    onehot = np.eye(ncand)[np.argmin(err_f, axis=2)]
    sel = nl_means_filter(onehot, guide, guide_variance, **params)
    sel = sel / np.maximum(sel.sum(axis=2, keepdims=True), 1e-300)
    blend = np.einsum("hwk,khwc->hwc", sel, filtered)
    blend_var = np.einsum("hwk,khwc->hwc", sel, out_variance)
    return blend, blend_var, sel


def _feature_with_variance(buffers: RenderBuffers, name: str, suffix: str):
    layers = buffers.layers
    f = np.asarray(layers.get(name + suffix, layers[name]), dtype=np.float64)
    if f.ndim == 2:
        f = f[..., None]
    var = layers.get(f"{name}_variance{suffix}")
    if var is None:
        fa = np.asarray(layers.get(name + "_a", layers[name]), dtype=np.float64)
        fb = np.asarray(layers.get(name + "_b", layers[name]), dtype=np.float64)
        var = (fa - fb) ** 2 / 2.0
    var = np.maximum(np.nan_to_num(np.asarray(var, dtype=np.float64)), 0.0)
    if var.ndim == 2:
        var = var[..., None]
    return np.nan_to_num(f), np.broadcast_to(var, f.shape)


def prefilter_features(buffers: RenderBuffers):
    """NL-means prefiltered features of A and B and their residual variances (Sec. 4.1).

    Returns {"a": (features, variances), "b": (...)}: lists of (H, W, C_j) and (H, W)."""
    out = {"a": ([], []), "b": ([], [])}
    for name in FEATURES:
        filtered = {}
        for which, suffix in (("a", "_a"), ("b", "_b")):
            f, var = _feature_with_variance(buffers, name, suffix)
            filtered[which] = nl_means_filter(f, f, var, **PREFILTER)
        resid = ((filtered["a"] - filtered["b"]) ** 2).mean(axis=2) / 2.0
        resid = uniform_filter(resid, size=3, mode="nearest")
        for which in ("a", "b"):
            out[which][0].append(filtered[which])
            out[which][1].append(resid)
    return out


def denoise(buffers: RenderBuffers, *, radius: int = WINDOW_RADIUS):
    """RDFC on the half buffers; returns Denoised(full=(a+b)/2, a, b) as float32 (H, W, 3)."""
    colors = {w: np.nan_to_num(np.asarray(buffers.layers["color" + s], dtype=np.float64))
              for w, s in (("a", "_a"), ("b", "_b"))}
    variances = {w: np.maximum(np.nan_to_num(np.asarray(buffers.layers["variance" + s],
                                                        dtype=np.float64)), 0.0)
                 for w, s in (("a", "_a"), ("b", "_b"))}
    stage_done = StageLog.for_image("rdfc", *colors["a"].shape[:2])    # prints on large images only
    feats = prefilter_features(buffers)
    stage_done("feature prefiltering")
    first, first_var = {}, {}
    for which in ("a", "b"):
        y, v = colors[which], variances[which]
        filt, deriv, ovar = candidate_filters(y, v, *feats[which], radius=radius)
        errors = sure(filt, deriv, y, v).sum(axis=3)
        first[which], first_var[which], _ = select_and_blend(filt, ovar, errors, y, v)
        stage_done(f"first pass of half buffer {which.upper()}")
    final = {}
    for which, other in (("a", "b"), ("b", "a")):
        y, v = colors[which], variances[which]
        filt, deriv, ovar = candidate_filters(y, v, *feats[which], guide=first[other],
                                              guide_variance=first_var[other], radius=radius)
        errors = sure(filt, deriv, y, v).sum(axis=3)
        final[which], _, _ = select_and_blend(filt, ovar, errors, first[other], first_var[other])
        stage_done(f"second pass of half buffer {which.upper()}")
    a = np.nan_to_num(final["a"]).astype(np.float32)
    b = np.nan_to_num(final["b"]).astype(np.float32)
    full = ((a.astype(np.float64) + b) / 2.0).astype(np.float32)
    return Denoised(full=full, a=a, b=b)
