"""RDFC: Robust Denoising using Feature and Color information (Rousselle, Manzi and Zwicker,
Computer Graphics Forum 32(7), Pacific Graphics 2013), base denoiser #8 of Zheng et al. 2021.

Pipeline (section numbers of the RDFC paper as we understand them from its public
descriptions; the paper text was not available, so "Sec." references are to its structure):

1. **Feature prefiltering** (Sec. 4.1). Albedo, normal and depth of each half buffer are
   NL-means filtered (:func:`mcbench.filters.nlmeans.nl_means_filter`, RKZ12 Eq. 5-6) guided by
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
   and n = p - q); by default (``CLAMP_DERIVATIVE``, the authors' rule) where any channel of
   it leaves [0, 1], all three are replaced by w_pp / sum w.
5. **Selection** (Sec. 5.2): the per-pixel SURE maps (summed over channels) are NL-means
   filtered, the per-pixel argmin gives binary selection maps, those are filtered with the same
   filter and used as blending weights of the candidates.
6. **Second pass** (default ``second_pass="authors"``, fbksd multifilm.cpp:409-423): the two
   pass-1 buffers are filtered once more with shared colour weights from their mean (variance
   (A~ - B~)^2 / 4, pyramid-smoothed), f = 3, k_c = 0.45, window r // 2, tau = 1e-4, no selection
   (:func:`authors_second_pass`). ``"ours"``: the noisy half is filtered
   again, three candidates guided by the *other* half's pass-1 output, SURE and selection as in 5.

Half buffers A and B are each denoised this way (they are the internal buffers RDFC needs
for the feature variance and the second pass); ``Denoised.a``/``.b`` are the two results and
``Denoised.full = (a + b) / 2``.

Constants (published ones first, then ours with the reason):

* k_c = 0.45, k_f = 0.6, FIRST f = 1, SECOND f = 3, THIRD k_c = inf, tau = 1e-3, alpha = 1:
  the authors' code. r = 10: their paper scenes (README "wnd_rad [10]"); fbksd's driver uses 20
  (``radius=20``, about 3x the time). Prefilter r = 5, f = 3 as theirs, k = 0.5 (theirs 1).
* eps = 1e-10 in the colour-distance denominator: guards the zero-variance case (same value
  as mcbench.filters.nlmeans).
* Feature gradient ``|Grad_j(p)|^2``: per axis the smaller of the two one-sided differences
  (so the normaliser is not inflated across an edge), summed over axes, mean over channels.
* Prefiltered-feature variance smoothed with a 3x3 box: the raw dual-buffer squared
  difference is a one-sample estimate.
* Error/selection map filter: NL-means r = 3, f = 1, k = 1.0, guided by the noisy colour
  (pass 1) or the other buffer's first-pass output (pass 2): small window keeps selection
  local, k = 1 is the usual NL-means strength.
* Kernel bands of ``BAND_ROWS = 8`` rows: per band, one window offset at a time, the patch
  colour distances (direct sums over the in-image patch pairs,
  :func:`mcbench.filters.nlmeans.nl_means_patch_distance_maps`) and every per-pixel term as
  loops over x that vectorise, into the band's sums; affects speed only. ``tile`` (default
  None) splits the image into tiles with a halo, with identical interiors (tested).
* Speed: ``benchmarks/bench_rdfc.py`` measures it
  (``NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/bench_rdfc.py --sizes 128 512``).
  All arithmetic is float64 (the SURE derivative subtracts terms of similar size).
* Argmin ties resolve to the lowest index (FIRST): on noise-free input FIRST reproduces it.
* Propagated output variance ``sum w^2 V / (sum w)^2`` ignores weight/colour correlation;
  the blend's variance is approximated by ``sum_k s_k Var_k``; used only as a guide variance.

Departures from the authors' code (fbksd-package denoisers/RDFC; table with file:line in
docs/fidelity_rdfc.md): each half denoised with its own weights (theirs: weights from the mean,
applied to both); the renderer's per-pixel half variance (``variance="rescaled"`` gives their
dual-buffer rescaling); no visibility feature, depth instead of world position; centre weight 1
(theirs: the largest neighbour weight); no symmetric weights; our selection-filter parameters.
"""

from __future__ import annotations

import numpy as np
from numba import prange
from scipy.ndimage import uniform_filter

from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.jit import cached_njit
from mcbench.filters.nlmeans import nl_means_filter, nl_means_patch_distance_maps
from mcbench.filters.smoothing import box_mean, pyramid_smooth
from mcbench.progress import StageLog
from mcbench.io.method_spec import MethodSpec

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
TILE = None
BAND_ROWS = 8
VARIANCE = "raw"            # colour variance of a half buffer: see half_variance
CLAMP_DERIVATIVE = True     # authors' dF/dy in [0, 1] rule (featurefilter.cu:1354-1369)
VARIANCE_BOX = 10           # radius of the authors' box for the dual-buffer rescaling (featurefilter.cu:1406-1409)
SECOND_PASS = "authors"     # see denoise
TAU_SECOND = 1e-4           # authors' pass-2 feature threshold (multifilm.cpp:416-420)


# ----------------------------------------------------------------------------- kernels

@cached_njit(parallel=True, error_model="numpy")
def _candidates_kernel(y_img, v_img, g, gv, feat, fvar, inv_norm, fstart, radius, patch_radii,
                       k_colors, self_guided, alpha, eps, band):
    """Joint-weight filters of y_img for every candidate; see :func:`candidate_filters`.

    Every image argument is a (channels, H, W) float64 plane stack: y_img, v_img, g, gv (3),
    feat (sum C_j), fvar and inv_norm = 1 / (k_f^2 max(tau, Var_j, |Grad_j|^2)) (J). Per band
    of ``band`` rows, one window offset at a time: the patch colour distances of the band (one
    map per distinct finite-k_c patch radius,
    :func:`mcbench.filters.nlmeans.nl_means_patch_distance_maps`), then per band row the
    feature distances, weights, sums and derivative terms of all pixels as loops over x (they
    vectorise), accumulated in the band's (K, 3, rows, W) sums. Returns (filtered, derivative, output variance), each
    (K, H, W, 3).
    """
    nc, h, w = y_img.shape
    ncand = patch_radii.shape[0]
    nfeat = fstart.shape[0] - 1
    # distinct patch radii of the candidates with a finite k_c, and each candidate's map
    cmap = np.full(ncand, -1, dtype=np.int64)
    radii = np.zeros(ncand, dtype=np.int64)
    nmaps = 0
    kc0 = 0.0
    for k in range(ncand):
        if np.isfinite(k_colors[k]):
            kc0 = k_colors[k]
            for j in range(nmaps):
                if radii[j] == patch_radii[k]:
                    cmap[k] = j
            if cmap[k] < 0:
                radii[nmaps] = patch_radii[k]
                cmap[k] = nmaps
                nmaps += 1
    radii = radii[:nmaps]
    fmax = 0
    for j in range(nmaps):
        fmax = max(fmax, radii[j])
    k2 = kc0 * kc0
    inv_count = np.zeros(max(nfeat, 1))
    for j in range(nfeat):
        inv_count[j] = 1.0 / max(fstart[j + 1] - fstart[j], 1)
    out = np.zeros((ncand, h, w, nc))
    deriv = np.zeros((ncand, h, w, nc))
    outvar = np.zeros((ncand, h, w, nc))
    centre = np.zeros((ncand, h, w))
    nbands = (h + band - 1) // band
    for bi in prange(nbands):
        y0 = bi * band
        rows = min(h, y0 + band) - y0
        dmaps = np.zeros((max(nmaps, 1), rows, w))
        m = np.zeros((rows + 2 * fmax, w))
        hs = np.zeros((rows + 2 * fmax, w))
        wsum = np.zeros((ncand, rows, w))
        wself = np.zeros((ncand, rows, w))
        wy = np.zeros((ncand, nc, rows, w))
        w2v = np.zeros((ncand, nc, rows, w))
        sdw = np.zeros((ncand, nc, rows, w))
        sdwy = np.zeros((ncand, nc, rows, w))
        dfeat = np.zeros(w)
        fd = np.zeros(w)
        wf = np.zeros(w)
        wt = np.zeros(w)
        wins = np.zeros(w)
        scale = np.zeros(w)
        grad = np.zeros((nc, w))
        back = np.zeros((nc, w))
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                x0 = max(0, -dx)
                x1 = min(w, w - dx)
                n = x1 - x0
                if n <= 0:
                    continue
                if nmaps > 0:
                    nl_means_patch_distance_maps(g, gv, y0, rows, dy, dx, kc0, alpha, eps, radii, m, hs, dmaps)
                for r in range(rows):
                    y = y0 + r
                    yq = y + dy
                    if yq < 0 or yq >= h:
                        continue
                    # feature weight w_f = exp(-max(0, max_j Phi_j^2)) of every pixel of the row
                    dfv = dfeat[:n]
                    dfv[:] = 0.0
                    for j in range(nfeat):
                        fdv = fd[:n]
                        fdv[:] = 0.0
                        for c in range(fstart[j], fstart[j + 1]):
                            fpv, fqv = feat[c, y, x0:x1], feat[c, yq, x0 + dx:x1 + dx]
                            for i in range(n):
                                diff = fpv[i] - fqv[i]
                                fdv[i] += diff * diff
                        vpv, vqv = fvar[j, y, x0:x1], fvar[j, yq, x0 + dx:x1 + dx]
                        inv, ic = inv_norm[j, y, x0:x1], inv_count[j]
                        for i in range(n):
                            vp = vpv[i]
                            dfv[i] = max(dfv[i], (fdv[i] * ic - (vp + min(vp, vqv[i]))) * inv[i])
                    wfv = wf[:n]
                    for i in range(n):
                        wfv[i] = np.exp(-dfv[i])
                    # derivative of d_c^2 wrt the colour at p: the n = 0 patch term (pair p, q)
                    # and, if p - o is inside, the n = p - q term (pair p - o, p)
                    yb = y - dy
                    back_row = 0 <= yb < h
                    if self_guided and nmaps > 0:
                        xb0 = max(x0, dx)           # x - dx inside the image
                        xb1 = max(min(x1, w + dx), xb0)
                        for c in range(nc):
                            gpv, gqv = g[c, y, x0:x1], g[c, yq, x0 + dx:x1 + dx]
                            vpv, vqv = gv[c, y, x0:x1], gv[c, yq, x0 + dx:x1 + dx]
                            gr = grad[c, :n]
                            for i in range(n):
                                gr[i] = 2.0 * (gpv[i] - gqv[i]) / (eps + k2 * (vpv[i] + vqv[i]))
                            bk = back[c, :n]
                            bk[:] = 0.0
                            if back_row and xb1 > xb0:
                                nb = xb1 - xb0
                                bkv = back[c, xb0 - x0:xb1 - x0]
                                gbv, gcv = g[c, yb, xb0 - dx:xb1 - dx], g[c, y, xb0:xb1]
                                vbv, vcv = gv[c, yb, xb0 - dx:xb1 - dx], gv[c, y, xb0:xb1]
                                for i in range(nb):
                                    bkv[i] = 2.0 * (gbv[i] - gcv[i]) / (eps + k2 * (vbv[i] + vcv[i]))
                    for k in range(ncand):
                        wtv = wt[:n]
                        wv = wins[:n]
                        if cmap[k] >= 0:
                            # w = min(w_c, w_f) = exp(-max(d_c^2, d_f)); the colour term wins where d_c^2 > d_f
                            d2v = dmaps[cmap[k], r, x0:x1]
                            for i in range(n):
                                wv[i] = 1.0 if d2v[i] > dfv[i] else 0.0
                                wtv[i] = np.exp(-max(d2v[i], dfv[i]))
                        else:
                            wtv[:] = wfv
                            wv[:] = 0.0
                        ws = wsum[k, r, x0:x1]
                        for i in range(n):
                            ws[i] += wtv[i]
                        if dy == 0 and dx == 0:
                            wself[k, r, x0:x1] = wtv
                        for c in range(nc):
                            yqv, vqv = y_img[c, yq, x0 + dx:x1 + dx], v_img[c, yq, x0 + dx:x1 + dx]
                            wyv, w2vv = wy[k, c, r, x0:x1], w2v[k, c, r, x0:x1]
                            for i in range(n):
                                wyv[i] += wtv[i] * yqv[i]
                                w2vv[i] += wtv[i] * wtv[i] * vqv[i]
                        if self_guided and cmap[k] >= 0:
                            pr = patch_radii[k]
                            use_back = back_row and abs(dy) <= pr and abs(dx) <= pr
                            ya = max(y - pr, 0)
                            yb_ = min(y + pr, h - 1)
                            cy = min(yb_, h - 1 - dy) - max(ya, -dy) + 1
                            sv = scale[:n]
                            for i in range(n):
                                x = x0 + i
                                cx = min(min(x + pr, w - 1), w - 1 - dx) - max(max(x - pr, 0), -dx) + 1
                                # dw/dy_p = -w (d d_c^2 / dy_p) / (channels x valid patch pairs)
                                sv[i] = -wtv[i] * wv[i] / (nc * cy * cx)
                            for c in range(nc):
                                gr, bk = grad[c, :n], back[c, :n]
                                yqv = y_img[c, yq, x0 + dx:x1 + dx]
                                sdwv, sdwyv = sdw[k, c, r, x0:x1], sdwy[k, c, r, x0:x1]
                                if use_back:
                                    for i in range(n):
                                        dwt = sv[i] * (gr[i] - bk[i])
                                        sdwv[i] += dwt
                                        sdwyv[i] += dwt * yqv[i]
                                else:
                                    for i in range(n):
                                        dwt = sv[i] * gr[i]
                                        sdwv[i] += dwt
                                        sdwyv[i] += dwt * yqv[i]
        for k in range(ncand):
            for r in range(rows):
                y = y0 + r
                for x in range(w):
                    cs = max(wsum[k, r, x], 1e-300)
                    centre[k, y, x] = wself[k, r, x] / cs
                    for c in range(nc):
                        f = wy[k, c, r, x] / cs
                        out[k, y, x, c] = f
                        outvar[k, y, x, c] = w2v[k, c, r, x] / (cs * cs)
                        deriv[k, y, x, c] = (wself[k, r, x] + sdwy[k, c, r, x] - f * sdw[k, c, r, x]) / cs
    return out, deriv, outvar, centre


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
                      alpha: float = ALPHA, epsilon: float = EPSILON, tile: int | None = TILE,
                      clamp_derivative: bool = CLAMP_DERIVATIVE, second_pass: str = SECOND_PASS):
    """The candidate filters (FIRST, SECOND, THIRD by default) of one image.

    color, variance: (H, W, 3) noisy colour and variance of its mean. features: list of
    (H, W, C_j) or (H, W) arrays (prefiltered), feature_variances: list of (H, W) (or
    (H, W, C_j), averaged over channels) residual variances. ``guide``/``guide_variance``:
    colour used for the colour weights; None means the colour itself (self-guided, pass 1),
    in which case the returned derivative includes the weights' dependence on the colour.

    Returns ``(filtered, derivative, output_variance)``, each (K, H, W, 3) float64:
    F_k(y), dF_k,p,c / dy_p,c and sum w^2 V / (sum w)^2. ``tile`` (pixels, None = whole
    image) only changes speed: the image is processed in tiles with a halo.
    ``clamp_derivative``: where any channel's derivative leaves [0, 1], all three are replaced by
    w_pp / sum w (the authors' rule, featurefilter.cu:1354-1369, with their fallback at :1339).
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
            np.asarray(k_colors, dtype=np.float64), bool(self_guided), float(alpha), float(epsilon), BAND_ROWS)
    tile = int(tile) if tile else max(h, w)
    halo = int(radius) + int(patch_radii.max(initial=0))
    def planes(a):
        return np.ascontiguousarray(np.moveaxis(a, 2, 0))
    images = (y, v, g, gv, feat, fvar, 1.0 / fnorm)
    if tile >= h and tile >= w:
        return _clamped(_candidates_kernel(*(planes(a) for a in images), *args), clamp_derivative)
    # Tiles with a halo of r + max f pixels give bit-identical interiors (every pixel, patch and
    # back-term a kept pixel touches lies inside its halo) and keep the working set in cache.
    outs = [np.zeros((len(patch_radii), h, w, 3)) for _ in range(3)] + [np.zeros((len(patch_radii), h, w))]
    for y0 in range(0, h, tile):
        for x0 in range(0, w, tile):
            y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
            ya, xa = max(y0 - halo, 0), max(x0 - halo, 0)
            yb, xb = min(y1 + halo, h), min(x1 + halo, w)
            crop = (slice(ya, yb), slice(xa, xb))
            res = _candidates_kernel(*(planes(a[crop]) for a in images), *args)
            for full, part in zip(outs, res):
                full[:, y0:y1, x0:x1] = part[:, y0 - ya:y1 - ya, x0 - xa:x1 - xa]
    return _clamped(outs, clamp_derivative)


def _clamped(results, clamp):
    """(filtered, derivative, output variance) of the kernel's results, the derivative clamped
    as the authors' (any channel outside [0, 1] -> all channels w_pp / sum w) if ``clamp``."""
    filtered, deriv, outvar, centre = results
    if clamp:
        invalid = np.any((deriv < 0.0) | (deriv > 1.0), axis=-1, keepdims=True)
        deriv = np.where(invalid, centre[..., None], deriv)
    return filtered, deriv, outvar


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


def half_variance(buffers: RenderBuffers, which: str, mode: str = VARIANCE) -> np.ndarray:
    """Colour variance (of the mean) of half buffer ``which`` used by RDFC, (H, W, 3) float64.

    ``"raw"``: the renderer's ``variance_a``/``variance_b`` (spp/2 samples; 1 degree of freedom at
    4 spp). ``"rescaled"``: the authors' dual-buffer rescaling (featurefilter.cu:1392-1412, there
    of the full image's variance) applied to the half: V_h * box(V_dual) / (1e-10 + box(V_h)), box
    of radius ``VARIANCE_BOX`` (:func:`mcbench.filters.smoothing.box_mean`), V_dual = (A - B)^2 / 2
    (an unbiased one-pixel estimate of a half's variance of the mean).
    """
    suffix = "_" + which
    v = np.maximum(np.nan_to_num(np.asarray(buffers.layers["variance" + suffix], dtype=np.float64)), 0.0)
    if mode == "raw":
        return v
    if mode != "rescaled":
        raise ValueError(f"variance must be 'raw' or 'rescaled', got {mode!r}")
    a, b = (np.nan_to_num(np.asarray(buffers.layers[n], dtype=np.float64)) for n in ("color_a", "color_b"))
    return v * box_mean((a - b) ** 2 / 2.0, VARIANCE_BOX) / (1e-10 + box_mean(v, VARIANCE_BOX))


def authors_second_pass(first: dict, feats: dict, radius: int = WINDOW_RADIUS) -> dict:
    """The authors' second pass (multifilm.cpp:409-423) of the pass-1 buffers ``first`` {"a", "b"}:
    each filtered once more with shared colour weights from their mean, whose variance is
    (A~ - B~)^2 / 4 pyramid-smoothed (featurefilter.cu:900-916, 1415-1429), patch radius 3, k_c =
    0.45, k_f = 0.6, window radius // 2, tau = ``TAU_SECOND``; no candidates, no selection."""
    guide = (first["a"] + first["b"]) / 2.0
    guide_var = pyramid_smooth((first["a"] - first["b"]) ** 2 / 4.0)
    return {w: candidate_filters(first[w], guide_var, *feats[w], guide=guide, guide_variance=guide_var,
                                 radius=max(radius // 2, 1), patch_radii=(3,), k_colors=(K_COLOR,),
                                 tau=TAU_SECOND)[0][0] for w in ("a", "b")}


def denoise(buffers: RenderBuffers, *, radius: int = WINDOW_RADIUS, variance: str = VARIANCE,
            clamp_derivative: bool = CLAMP_DERIVATIVE, second_pass: str = SECOND_PASS):
    """RDFC on the half buffers; returns Denoised(full=(a+b)/2, a, b) as float32 (H, W, 3).

    ``radius``: window radius of both passes (10 as the authors' paper scenes, 20 as fbksd's
    driver: docs/fidelity_rdfc.md); ``variance``: :func:`half_variance`'s mode;
    ``clamp_derivative``: :func:`candidate_filters`'s authors' rule; ``second_pass``: ``"ours"``
    (module docstring, 6.) or ``"authors"`` (the pass-1 buffers filtered again, code below)."""
    colors = {w: np.nan_to_num(np.asarray(buffers.layers["color" + s], dtype=np.float64))
              for w, s in (("a", "_a"), ("b", "_b"))}
    variances = {w: half_variance(buffers, w, variance) for w in ("a", "b")}
    stage_done = StageLog.for_image("rdfc", *colors["a"].shape[:2])    # prints on large images only
    feats = prefilter_features(buffers)
    stage_done("feature prefiltering")
    first, first_var = {}, {}
    for which in ("a", "b"):
        y, v = colors[which], variances[which]
        filt, deriv, ovar = candidate_filters(y, v, *feats[which], radius=radius,
                                              clamp_derivative=clamp_derivative)
        errors = sure(filt, deriv, y, v).sum(axis=3)
        first[which], first_var[which], _ = select_and_blend(filt, ovar, errors, y, v)
        stage_done(f"first pass of half buffer {which.upper()}")
    if second_pass not in ("ours", "authors"):
        raise ValueError(f"second_pass must be 'ours' or 'authors', got {second_pass!r}")
    final = authors_second_pass(first, feats, radius) if second_pass == "authors" else {}
    for which, other in (("a", "b"), ("b", "a")) if second_pass == "ours" else ():
        y, v = colors[which], variances[which]
        filt, deriv, ovar = candidate_filters(y, v, *feats[which], guide=first[other],
                                              guide_variance=first_var[other], radius=radius,
                                              clamp_derivative=clamp_derivative)
        errors = sure(filt, deriv, y, v).sum(axis=3)
        final[which], _, _ = select_and_blend(filt, ovar, errors, first[other], first_var[other])
    stage_done("second pass")
    a = np.nan_to_num(final["a"]).astype(np.float32)
    b = np.nan_to_num(final["b"]).astype(np.float32)
    full = ((a.astype(np.float64) + b) / 2.0).astype(np.float32)
    return Denoised(full=full, a=a, b=b)


METHOD = MethodSpec(kind="denoiser", label="#8 RDFC", run=denoise)
