"""RDFC against the authors' code (fbksd-package denoisers/RDFC at 3059e14, docs/fidelity_rdfc.md):
every step against a brute force or closed form written here from the authors' source (``C`` =
featurefilter.cu, ``F`` = multifilm.cpp; file:line), never from our code, so a wrong constant in
mcbench/filters/rdfc_filter.py, mcbench/filters/smoothing.py or methods/rdfc.py fails a test."""

from __future__ import annotations

import numpy as np
import pytest

from mcbench.filters import rdfc_filter as rf
from mcbench.io.buffers import RenderBuffers
from mcbench.filters.smoothing import box_mean, pyramid_smooth
from methods import rdfc


# ----------------------------------------------------------------------------- brute forces

def brute_box(image, r):
    """conv_box (C:255-280): row pass then column pass, mean over the in-image taps, by loops."""
    image = np.asarray(image, dtype=np.float64)
    h, w = image.shape[:2]
    tmp = np.zeros_like(image)
    for y in range(h):
        for x in range(w):
            tmp[y, x] = image[y, max(0, x - r):min(w, x + r + 1)].mean(axis=0)
    out = np.zeros_like(tmp)
    for y in range(h):
        for x in range(w):
            out[y, x] = tmp[max(0, y - r):min(h, y + r + 1), x].mean(axis=0)
    return out


def brute_pyr(image, v=0.1353):
    """conv_pyr (C:319-347) with the default tap of featurefilter.h:148, by loops."""
    out = np.asarray(image, dtype=np.float64)
    for axis in (0, 1):
        src, res = np.moveaxis(out, axis, 0), np.zeros_like(np.moveaxis(out, axis, 0))
        n = src.shape[0]
        for i in range(n):
            acc = wsum = 0.0
            for j, k in ((i - 1, v), (i, 1.0), (i + 1, v)):
                if 0 <= j < n:
                    acc = acc + k * src[j]
                    wsum += k
            res[i] = acc / wsum
        out = np.moveaxis(res, 0, axis)
    return out


def mirror(p, n):
    """CLAMP_MIRROR (C:40-41)."""
    return -p if p < 0 else (2 * n - p - 2 if p >= n else p)


def pixel_distances(img, vn, vd, y, x, y1, x1, y2, x2, k2, diff, scale=1.0):
    """distance / distance_delta / dist_wgt_feat (C:361-394,409-464,575-608) at one pixel: the
    channel means of d(n1), d(n2), d(sym), the centre value multiplied by ``scale``."""
    out = np.zeros(3)
    nc = img.shape[2]
    for c in range(nc):
        varC = vn[y, x, c]
        varN1 = min(varC, vn[y1, x1, c])
        varN2 = min(varC, vn[y2, x2, c])
        dC, dN1, dN2 = vd[y, x, c], vd[y1, x1, c], vd[y2, x2, c]
        val = scale * img[y, x, c]
        num = [(val - img[y1, x1, c]) ** 2 - (varC + varN1),
               (val - img[y2, x2, c]) ** 2 - (varC + varN2),
               (val - (img[y1, x1, c] + img[y2, x2, c]) / 2) ** 2 - (varC + (varN1 + varN2) / 4)]
        if diff:
            den = [1e-10 + k2 * (dC + dN1), 1e-10 + k2 * (dC + dN2), 1e-10 + k2 * (dC + (dN1 + dN2) / 4)]
        else:
            den = [1e-10 + k2 * (dC * 2)] * 3
        out += np.array(num) / np.array(den)
    return out / nc


def sym_blend(d1, d2, w1, w2, ws, a=0.0, max_d2=25.0):
    """keep_valid_sym_weights (C:479-491): returns blended (w1, w2, a); ``max_d2`` = MAX_D2 (C:19),
    -inf for the filter without the blend."""
    if d1 < max_d2 and d2 < max_d2:
        a = min(1.0, max(0.0, ws / (w1 + w2) - 1))
    return a * ws + (1 - a) * w1, a * ws + (1 - a) * w2, a


def brute_filter(data, guide, vn, vd, feats, *, R, f, fw, k, colour=True, diff=True, kf=0.6, diff_f=None,
                 delta=False, max_d2=25.0):
    """FilterData (C:1138-1178) / FilterDataDelta (C:1181-1237) by loops. data (B, H, W, C);
    guide, vn, vd (H, W, Cg); feats: list of (value, Vn, Vd) (H, W, C); ``max_d2``: the symmetric
    blend's threshold (-inf: no blend). Returns (out, wmax/wsum,
    scaled filter of the guide or None)."""
    diff_f = diff if diff_f is None else diff_f
    B, H, W, C = data.shape
    k2, kf2 = k * k, kf * kf
    wmax = np.full((H, W), 1e-3)
    wsum = np.zeros((H, W))
    acc = np.zeros_like(data)
    wmax_s = np.full((H, W), 1e-3)
    wsum_s = np.zeros((H, W))
    acc_s = np.zeros_like(guide)
    wc = 1.0 / (1 + 2 * f) / (1 + 2 * f)
    for dy in range(-R, 1):
        for dx in range(-R, (-1 if dy == 0 else R) + 1):
            idx = [[(mirror(y + dy, H), mirror(x + dx, W), mirror(y - dy, H), mirror(x - dx, W))
                    for x in range(W)] for y in range(H)]
            w1, w2 = np.ones((H, W)), np.ones((H, W))
            w1s, w2s = np.ones((H, W)), np.ones((H, W))
            if colour:
                b = np.zeros((3, H, W))
                s = np.zeros((3, H, W))
                for y in range(H):
                    for x in range(W):
                        b[:, y, x] = pixel_distances(guide, vn, vd, y, x, *idx[y][x], k2, diff)
                        s[:, y, x] = pixel_distances(guide, vn, vd, y, x, *idx[y][x], k2, diff, scale=1.01)
                d = np.stack([brute_box(m, f) for m in b]) if f > 0 else b
                wgt = np.exp(-np.maximum(0, d))
                if delta:
                    ds_ = d + wc * (s - b)                                  # C:655-657
                    wgt_s = np.exp(-np.maximum(0, ds_))
                    for y in range(H):
                        for x in range(W):
                            c1, c2, a = sym_blend(d[0, y, x], d[1, y, x], *wgt[:, y, x], max_d2=max_d2)
                            t1, t2, _ = sym_blend(ds_[0, y, x], ds_[1, y, x], *wgt_s[:, y, x], a=a,
                                                  max_d2=max_d2)
                            w1[y, x], w2[y, x] = min(w1[y, x], c1), min(w2[y, x], c2)
                            w1s[y, x], w2s[y, x] = min(w1s[y, x], t1), min(w2s[y, x], t2)
                else:
                    if fw > 0:
                        wgt = np.stack([brute_box(m, fw) for m in wgt])     # C:1455-1458
                    for y in range(H):
                        for x in range(W):
                            c1, c2, _ = sym_blend(d[0, y, x], d[1, y, x], *wgt[:, y, x], max_d2=max_d2)
                            w1[y, x], w2[y, x] = min(w1[y, x], c1), min(w2[y, x], c2)
            for value, fvn, fvd in feats:
                for y in range(H):
                    for x in range(W):
                        dd = pixel_distances(value, fvn, fvd, y, x, *idx[y][x], kf2, diff_f)
                        c1, c2, _ = sym_blend(dd[0], dd[1], *np.exp(-np.maximum(0, dd)), max_d2=max_d2)
                        w1[y, x], w2[y, x] = min(w1[y, x], c1), min(w2[y, x], c2)
                        w1s[y, x], w2s[y, x] = min(w1s[y, x], c1), min(w2s[y, x], c2)
            for y in range(H):
                for x in range(W):
                    y1, x1, y2, x2 = idx[y][x]
                    wmax[y, x] = max(wmax[y, x], w1[y, x], w2[y, x])
                    wsum[y, x] += w1[y, x] + w2[y, x]
                    acc[:, y, x] += data[:, y1, x1] * w1[y, x] + data[:, y2, x2] * w2[y, x]
                    wmax_s[y, x] = max(wmax_s[y, x], w1s[y, x], w2s[y, x])
                    wsum_s[y, x] += w1s[y, x] + w2s[y, x]
                    acc_s[y, x] += guide[y1, x1] * w1s[y, x] + guide[y2, x2] * w2s[y, x]
    out = (acc + data * wmax[None, :, :, None]) / (wsum + wmax)[None, :, :, None]
    scaled = (acc_s + 1.01 * guide * wmax_s[..., None]) / (wsum_s + wmax_s)[..., None] if delta else None
    return out, wmax / (1e-10 + (wsum + wmax)), scaled                 # ratio (C:150,1339)


def brute_normaliser(feature, var, tau):
    """sqr_gradient + get_var_th (C:212-252): per channel max(var, max(grad^2, tau)) by loops."""
    h, w, nc = feature.shape
    out = np.zeros_like(feature)
    for y in range(h):
        for x in range(w):
            for c in range(nc):
                gh = gv = 0.0
                if 0 < x < w - 1:
                    gh = min(((feature[y, x - 1, c] - feature[y, x, c]) / 2) ** 2,
                             ((feature[y, x + 1, c] - feature[y, x, c]) / 2) ** 2)
                if 0 < y < h - 1:
                    gv = min(((feature[y - 1, x, c] - feature[y, x, c]) / 2) ** 2,
                             ((feature[y + 1, x, c] - feature[y, x, c]) / 2) ** 2)
                out[y, x, c] = max(var[y, x, c], max(gh + gv, tau))
    return out


def small_case(h=7, w=9, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.random((h, w, 3))
    b = a + 0.1 * rng.standard_normal((h, w, 3))
    guide = (a + b) / 2
    var = 0.02 * (0.5 + rng.random((h, w, 3)))
    f1 = np.where(np.arange(w)[None, :, None] < w // 2, 0.2, 0.7) + 0.01 * rng.standard_normal((h, w, 3))
    f2 = (np.arange(h)[:, None, None] > h // 2) * np.ones((h, w, 1)) + 0.05 * rng.random((h, w, 1))
    feats = [rf.Feature(f1, 1e-4 * rng.random((h, w, 3)), 1e-3), rf.Feature(f2, 1e-3 * rng.random((h, w, 1)), 1e-3)]
    return a, b, guide, var, feats


def ramp_case(h=7, w=9, seed=0):
    """Linear ramps (colour and a 3-channel feature) with small noise: the symmetric pair's
    midpoint matches the centre, so the blend of C:479-491 acts (on :func:`small_case` with patch 3
    it never does)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    base = (0.3 * xx + 0.2 * yy)[..., None] * np.array([1.0, 0.8, 0.6]) / 3
    a = base + 0.01 * rng.standard_normal((h, w, 3))
    b = base + 0.01 * rng.standard_normal((h, w, 3))
    var = 1e-4 * (0.5 + rng.random((h, w, 3)))
    f1 = np.stack([0.1 * xx, 0.05 * yy, 0.1 * xx + 0.05 * yy], -1) + 1e-3 * rng.standard_normal((h, w, 3))
    return a, b, (a + b) / 2, var, [rf.Feature(f1, 1e-6 * rng.random((h, w, 3)), 1e-4)]


def brute_feats(feats):
    return [(f.value, f.variance, brute_normaliser(f.value, f.variance, f.tau)) for f in feats]


# ----------------------------------------------------------------------------- kernels

def test_box_and_pyramid_match_the_authors_kernels():
    rng = np.random.default_rng(0)
    image = rng.random((13, 30, 3))
    np.testing.assert_allclose(box_mean(image, 10), brute_box(image, 10), rtol=1e-12)
    np.testing.assert_allclose(box_mean(image[..., 0], 2), brute_box(image[..., 0], 2), rtol=1e-12)
    np.testing.assert_allclose(pyramid_smooth(image), brute_pyr(image), rtol=1e-12)


@pytest.mark.parametrize(("R", "f", "fw", "k", "diff", "with_feats"), [
    (2, 3, 2, 1.0, True, False),      # the prefilter / error / selection filters (C:1029, F:302-305,642-646)
    (2, 3, 2, 0.45, False, True),     # the second pass (F:410-415, use_diff_var false)
    (3, 1, 0, 0.45, True, True),      # no weight box
])
def test_nl_means_is_the_authors_filter_data(R, f, fw, k, diff, with_feats):
    """FilterData: mirrored neighbours, patch box, weight box, symmetric weights, min with the
    features (p+q or 2p denominators), centre weight = max neighbour weight floored at 1e-3."""
    a, b, guide, var, feats = small_case()
    feats = feats if with_feats else []
    ours = rf.nl_means(np.stack([a, b]), guide, var, radius=R, patch_radius=f, weight_radius=fw, k=k,
                       use_diff_var=diff, features=feats)
    out, centre, _ = brute_filter(np.stack([a, b]), guide, var, var, brute_feats(feats), R=R, f=f, fw=fw, k=k,
                                  diff=diff)
    np.testing.assert_allclose(ours.buffers, out, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(ours.centre, centre, rtol=1e-10)


def test_feature_only_filter_is_the_authors_third_candidate():
    """THIRD: feat_only (C:1046-1048, 1157): colour skipped, features with p+q denominators."""
    a, b, guide, var, feats = small_case(seed=2)
    ours = rf.nl_means(np.stack([a, b]), guide, var, radius=3, patch_radius=3, weight_radius=0, k=1.0,
                       use_colour=False, features=feats)
    out, centre, _ = brute_filter(np.stack([a, b]), guide, var, var, brute_feats(feats), R=3, f=3, fw=0, k=1.0,
                                  colour=False)
    np.testing.assert_allclose(ours.buffers, out, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(ours.centre, centre, rtol=1e-10)


@pytest.mark.parametrize("f", [1, 3, (1, 3)])
def test_delta_filter_and_derivative_are_the_authors(f):
    """FilterDataDelta (C:1181-1237): 1.01-scaled centre in the n = 0 patch term (weight
    1/(2f+1)^2, C:1529) and in the centre value, no weight box; derivative (C:132-141)."""
    a, b, guide, var, feats = small_case(seed=3)
    results = rf.nl_means(np.stack([a, b]), guide, var, radius=2, patch_radius=f, weight_radius=0, k=0.45,
                          features=feats, delta=True)
    if isinstance(f, tuple):      # FIRST and SECOND in one call: each as its own brute force
        for ours, fi in zip(results, f):
            out, _, scaled = brute_filter(np.stack([a, b]), guide, var, var, brute_feats(feats), R=2, f=fi, fw=0,
                                          k=0.45, delta=True)
            np.testing.assert_allclose(ours.buffers, out, rtol=1e-10, atol=1e-13)
            np.testing.assert_allclose(ours.scaled, scaled, rtol=1e-10, atol=1e-13)
        return
    ours = results
    out, centre, scaled = brute_filter(np.stack([a, b]), guide, var, var, brute_feats(feats), R=2, f=f, fw=0,
                                       k=0.45, delta=True)
    np.testing.assert_allclose(ours.buffers, out, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(ours.scaled, scaled, rtol=1e-10, atol=1e-13)
    mean = out.mean(axis=0)
    den = 1e-10 + guide - 1.01 * guide
    np.testing.assert_allclose(rf.finite_difference_derivative(mean, scaled, guide), mean / den - scaled / den,
                               rtol=1e-9)


@pytest.mark.parametrize(("R", "f", "fw", "k", "colour", "delta"), [
    (2, 3, 2, 1.0, True, False),      # FilterData with a weight box (prefilter / error / selection)
    (3, 3, 0, 1.0, False, False),     # THIRD (feat_only)
    (2, 1, 0, 0.45, True, True),      # FilterDataDelta (FIRST)
])
def test_nl_means_without_the_symmetric_blend(R, f, fw, k, colour, delta):
    """``max_d2=-inf``: the authors' filter with keep_valid_sym_weights (C:479-491,620-626,685-689)
    never blending, by the brute force with the blend's threshold at -inf; on ramps, where the blend
    acts (the default differs, and matches the brute force with the threshold 25)."""
    a, b, guide, var, feats = ramp_case()
    kw = dict(radius=R, patch_radius=f, weight_radius=fw, k=k, use_colour=colour, features=feats, delta=delta)
    ours = rf.nl_means(np.stack([a, b]), guide, var, max_d2=-np.inf, **kw)
    out, centre, scaled = brute_filter(np.stack([a, b]), guide, var, var, brute_feats(feats), R=R, f=f, fw=fw, k=k,
                                       colour=colour, delta=delta, max_d2=-np.inf)
    np.testing.assert_allclose(ours.buffers, out, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(ours.centre, centre, rtol=1e-10)
    if delta:
        np.testing.assert_allclose(ours.scaled, scaled, rtol=1e-10, atol=1e-13)
    default = rf.nl_means(np.stack([a, b]), guide, var, **kw)
    assert np.abs(default.buffers - ours.buffers).max() > 1e-2
    out25, _, _ = brute_filter(np.stack([a, b]), guide, var, var, brute_feats(feats), R=R, f=f, fw=fw, k=k,
                               colour=colour, delta=delta)
    np.testing.assert_allclose(default.buffers, out25, rtol=1e-10, atol=1e-13)
    with pytest.raises(ValueError, match="max_d2"):
        rf.nl_means(np.stack([a, b]), guide, var, max_d2=np.nan, **kw)


def test_third_on_a_linear_ramp_with_and_without_the_symmetric_blend():
    """Closed form (the 'Known failure' of docs/fidelity_rdfc.md): feature f = s x (noise-free,
    tau << s^2/4, so Vd = grad^2 = s^2/4 inside, C:212-252), THIRD's filter (features only, k_f 0.6,
    window 2). A neighbour dx columns away has distance d = (s dx)^2 / (1e-10 + k_f^2 s^2/2)
    ~ 5.56 dx^2 (22.2 < 25 for dx = 2), the symmetric pair's distance 0 (the ramp is linear), so
    with the blend a = clip(1/(2 e^-d) - 1, 0, 1) = 1 and every neighbour gets weight 1: a bright
    pixel two columns away gets weight 1 and the output is the 5x5 window mean 1/25. Without the
    blend its weight is e^-d(2) and the output e^-d(2) / (1 + 4 + 10 e^-d(1) + 10 e^-d(2))."""
    h, w, s, kf = 5, 9, 0.1, 0.6
    ramp = np.broadcast_to(s * np.arange(w, dtype=np.float64)[None, :, None], (h, w, 1)).copy()
    feat = [rf.Feature(ramp, np.zeros((h, w, 1)), 1e-8)]
    data = np.zeros((1, h, w, 1))
    data[0, 2, 6] = 1.0                                    # the bright pixel, p = (2, 4)
    guide = np.zeros((h, w, 1))
    kw = dict(radius=2, patch_radius=3, weight_radius=0, k=1.0, use_colour=False, features=feat, feature_k=kf)
    d = [(s * dx) ** 2 / (1e-10 + kf ** 2 * (s * s / 4 + s * s / 4)) for dx in (1, 2)]
    assert d[1] < 25
    blend = rf.nl_means(data, guide, guide, **kw)
    assert blend.buffers[0, 2, 4, 0] == pytest.approx(1 / 25, rel=1e-12)
    plain = rf.nl_means(data, guide, guide, max_d2=-np.inf, **kw)
    expected = np.exp(-d[1]) / (1 + 4 + 10 * np.exp(-d[0]) + 10 * np.exp(-d[1]))
    assert plain.buffers[0, 2, 4, 0] == pytest.approx(expected, rel=1e-9)


def test_symmetric_weights_switch_reaches_every_filter(make_render_buffers, monkeypatch):
    """``denoise(symmetric_weights=False)`` passes max_d2 = -inf to every NL-means call (prefilter,
    candidates, error and selection filters, second pass); the default passes MAX_D2 = 25 (C:19)."""
    real = rdfc.nl_means
    for switch, expected in ((True, 25.0), (False, -np.inf)):
        seen = []

        def spy(buffers, guide, var, **kw):
            seen.append(kw.get("max_d2", "default"))
            return real(buffers, guide, var, **kw)

        monkeypatch.setattr(rdfc, "nl_means", spy)
        rdfc.denoise(make_render_buffers(height=8, width=9, seed=1), radius=2, symmetric_weights=switch)
        assert len(seen) == 9 and all(m == expected for m in seen), seen


def test_centre_weight_is_the_largest_neighbour_weight_floored():
    """An isolated pixel (every neighbour weight 0) keeps its value with weight 1e-3 (C:17,1148);
    equal neighbour weights w give the centre weight w: the plain window mean."""
    h = w = 5
    data = np.zeros((1, h, w, 3))
    data[0, 2, 2] = 1.0
    guide = np.zeros((h, w, 3))
    guide[2, 2] = 1e3                     # colour far from every neighbour, zero variance
    res = rf.nl_means(data, guide, np.zeros((h, w, 3)), radius=1, patch_radius=0, weight_radius=0, k=1.0)
    assert res.buffers[0, 2, 2, 0] == pytest.approx(1.0)
    assert res.centre[2, 2] == pytest.approx(1.0)
    flat = np.random.default_rng(1).random((1, h, w, 3))
    res = rf.nl_means(flat, np.zeros((h, w, 3)), np.ones((h, w, 3)), radius=1, patch_radius=0, weight_radius=0,
                      k=1.0)                # every distance <= 0: all weights 1, centre weight 1
    np.testing.assert_allclose(res.buffers[0, 2, 2], flat[0, 1:4, 1:4].mean(axis=(0, 1)), rtol=1e-12)
    assert res.centre[2, 2] == pytest.approx(1 / 9)


def test_normaliser_on_a_linear_ramp_is_a_squared_over_4_and_zero_at_the_border():
    """sqr_gradient (C:224-226): half-pixel differences, so f = a x gives (a/2)^2 inside and 0 in
    the first and last columns (C:221); get_var_th (C:250) takes max(var, max(grad^2, tau))."""
    a = 0.3
    ramp = np.broadcast_to(a * np.arange(8.0)[None, :, None], (5, 8, 3))
    norm = rf.feature_normaliser(ramp, np.zeros_like(ramp), 1e-9)
    np.testing.assert_allclose(norm[:, 1:-1], a * a / 4)
    np.testing.assert_allclose(norm[:, [0, -1]], 1e-9)
    rng = np.random.default_rng(4)
    f, v = rng.random((6, 7, 3)), 0.05 * rng.random((6, 7, 3))
    np.testing.assert_allclose(rf.feature_normaliser(f, v, 0.02), brute_normaliser(f, v, 0.02), rtol=1e-12)


def test_rescaled_variance_is_the_authors_21_pixel_dual_buffer_rescaling():
    """GetScaledSampleVariance (C:1392-1412): V box21((A-B)^2/4) / (1e-10 + box21(V))."""
    rng = np.random.default_rng(5)
    a, b, v = rng.random((25, 30, 3)), rng.random((25, 30, 3)), 0.1 * rng.random((25, 30, 3))
    expected = v * brute_box((a - b) ** 2 / 4, 10) / (1e-10 + brute_box(v, 10))
    np.testing.assert_allclose(rf.scaled_sample_variance(a, b, v), expected, rtol=1e-10)
    np.testing.assert_allclose(rf.dual_buffer_variance(a, b), brute_pyr((a - b) ** 2 / 4), rtol=1e-12)


def test_sure_clamp_and_selection_rule():
    """ComputeSURE (F:427-434) channel mean (F:639); the derivative clamp (C:1361-1369); the argmin
    loop of F:653-661: last to first, strict <, FIRST only if mean dF/dy(FIRST) <= the mean of
    derivatives[1][pix..pix+2] (the authors' index bug)."""
    rng = np.random.default_rng(6)
    F, y, d, v = (rng.random((4, 5, 3)) for _ in range(4))
    np.testing.assert_allclose(rf.sure(F, d, y, v), ((F - y) ** 2 + 2 * d * v - v).mean(axis=-1), rtol=1e-12)
    deriv = np.array([[[0.2, 0.5, 0.9], [0.2, -0.1, 0.3], [1.2, 0.5, 0.5]]])
    centre = np.array([[0.4, 0.6, 0.7]])
    np.testing.assert_allclose(rf.clamp_derivative(deriv, centre),
                               [[[0.2, 0.5, 0.9], [0.6, 0.6, 0.6], [0.7, 0.7, 0.7]]])
    # selection: 1 x 3 pixels, three candidates
    err = np.array([[[1.0, 2.0, 5.0]], [[1.0, 1.0, 5.0]], [[1.0, 3.0, 0.5]]])
    d0 = np.full((1, 3, 3), 0.5)
    d1 = np.full((1, 3, 3), 0.9)
    sel = rf.select_candidate(err, d0, d1)
    assert sel.tolist() == [[2, 1, 2]]                       # ties go to the higher index
    err = np.array([[[0.0, 0.0, 0.0]], [[1.0, 1.0, 1.0]], [[2.0, 2.0, 2.0]]])
    # SECOND's flat derivative: pixel 0 = (0.1, 0.1, 0.1), pixel 1 = (0.9, 0.9, 0.9), pixel 2 = (0.9, ...)
    d1 = np.array([[[0.1, 0.1, 0.1], [0.9, 0.9, 0.9], [0.9, 0.9, 0.9]]])
    # bug: pixel 0 reads flat[0:3] = 0.1 (< 0.5, FIRST barred); pixel 1 reads flat[1:4] = (0.1, 0.1, 0.9)
    # mean 0.367 (FIRST barred, though its own SECOND mean 0.9 would admit it); pixel 2: flat[2:5] mean 0.633
    assert rf.select_candidate(err, d0, d1).tolist() == [[1, 1, 0]]
    assert rf.select_candidate(err, d0, d1, index_bug=False).tolist() == [[1, 0, 0]]


# ----------------------------------------------------------------------------- the driver's constants

def test_denoise_runs_the_authors_filters_with_their_constants(make_render_buffers, monkeypatch):
    """Every NL-means call of one denoise with its parameters, written from F:300-423 and C:1029:
    prefilter (per feature) r 5, f 3, box 2, k 1; FIRST r R, f 1, k_c 0.45, tau 1e-3, delta; SECOND
    f 3; THIRD features only, tau 1e-4; error filter r 1, f 3, box 2, k 1; selection r 5, f 3, box 2,
    k 1; pass 2 r R/2, f 3, box 2, k 0.45, use_diff_var false, tau 1e-4; k_f 0.6; position tau x maxPos^2."""
    calls = []
    real = rdfc.nl_means

    def spy(buffers, guide, var, **kw):
        calls.append(dict(kw, nbuf=np.shape(buffers)[0]))
        return real(buffers, guide, var, **kw)

    monkeypatch.setattr(rdfc, "nl_means", spy)
    buffers = make_render_buffers(height=12, width=13, seed=1)
    rdfc.denoise(buffers)
    features, max_pos = rdfc.authors_features(buffers)
    R = 10
    pre = dict(radius=5, patch_radius=3, weight_radius=2, k=1.0)
    for call in calls[:4]:
        assert {key: call[key] for key in pre} == pre and "features" not in call and call["nbuf"] == 2

    def taus(call):
        return [f.tau for f in call["features"]]

    first_second, third, err, sel, p2 = calls[4:]
    first = dict(first_second, patch_radius=first_second["patch_radius"][0])
    second = dict(first_second, patch_radius=first_second["patch_radius"][1])
    expected_taus = lambda t: [t, t, max_pos ** 2 * t, t]       # normal, albedo, position, visibility
    assert (first["radius"], first["patch_radius"], first["weight_radius"], first["k"]) == (R, 1, 0, 0.45)
    assert first["delta"] and first.get("use_colour", True) and first["feature_k"] == 0.6
    assert taus(first) == pytest.approx(expected_taus(1e-3))
    assert (second["radius"], second["patch_radius"], second["weight_radius"], second["k"]) == (R, 3, 0, 0.45)
    assert second["delta"] and taus(second) == pytest.approx(expected_taus(1e-3))
    assert third["radius"] == R and third["use_colour"] is False and not third.get("delta", False)
    assert third["weight_radius"] == 0 and taus(third) == pytest.approx(expected_taus(1e-4))
    assert {key: err[key] for key in pre} == dict(pre, radius=1) and err["nbuf"] == 3
    assert {key: sel[key] for key in pre} == dict(pre, radius=5) and sel["nbuf"] == 3
    assert (p2["radius"], p2["patch_radius"], p2["weight_radius"], p2["k"]) == (R // 2, 3, 2, 0.45)
    assert p2["use_diff_var"] is False and p2["feature_k"] == 0.6
    assert taus(p2) == pytest.approx(expected_taus(1e-4))
    assert max_pos > 0


def test_features_are_the_authors(make_render_buffers):
    """F:107-136: normal (n+1)/2, albedo / max(1, max channel), position through the XYZ->sRGB matrix
    of F:117-119, visibility; maxPos the largest position component (F:328-333)."""
    rng = np.random.default_rng(7)
    h, w = 4, 5
    normal = rng.uniform(-1, 1, (h, w, 3))
    albedo = rng.uniform(0, 1.5, (h, w, 3))
    position = rng.uniform(-2, 3, (h, w, 3))
    buffers = make_render_buffers(height=h, width=w, normal=normal, albedo=albedo, position=position,
                                  visibility=rng.random((h, w)))
    layers = dict(buffers.layers)
    layers["position_variance"] = np.full((h, w, 3), 0.5, np.float32)
    buffers = type(buffers)(layers=layers, spp=buffers.spp)
    feats, max_pos = rdfc.authors_features(buffers)
    n32, a32, p32 = (np.asarray(x, np.float32).astype(np.float64) for x in (normal, albedo, position))
    np.testing.assert_allclose(feats["normal"][0], (n32 + 1) / 2, rtol=1e-12)
    np.testing.assert_allclose(feats["albedo"][0], a32 / np.maximum(1, a32.max(-1, keepdims=True)), rtol=1e-12)
    m = np.array([[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556],
                  [0.055648, -0.204043, 1.057311]])
    pos = np.einsum("ij,hwj->hwi", m, p32)
    np.testing.assert_allclose(feats["position"][0], pos, rtol=1e-12)
    np.testing.assert_allclose(feats["position"][2], np.full((h, w, 3), 0.5) @ (m ** 2).T, rtol=1e-12)
    assert feats["visibility"][0].shape == (h, w, 1)
    assert max_pos == pytest.approx(max(0.0, pos.max()))


def test_render_layers_are_declared():
    layers = rdfc.METHOD.render_layers
    for name in ("position", "visibility", "normal", "albedo"):
        assert {name + "_a", name + "_b", name + "_variance"} <= set(layers)
    assert "depth" not in " ".join(layers)


# ----------------------------------------------------------------------------- departures now as the authors' code

def test_selection_keeps_first_where_no_candidate_passes():
    """F:87 zero-initialises ``sel_map`` and F:653-661 only writes it when a SURE value beats the
    running minimum, which starts at +inf (F:652): where every eligible error is NaN or +inf the map
    keeps 0, FIRST, also when FIRST itself is barred by the derivative test."""
    nan, inf = np.nan, np.inf
    # pixel 0: all NaN; pixel 1: THIRD NaN, SECOND +inf, FIRST finite but barred; pixel 2: all +inf
    err = np.array([[[nan, 0.1, inf]], [[nan, inf, inf]], [[nan, nan, inf]]])
    d0 = np.full((1, 3, 3), 0.9)
    d1 = np.full((1, 3, 3), 0.1)                       # mean dF/dy(FIRST) 0.9 > 0.1: FIRST barred
    for bug in (True, False):
        assert rf.select_candidate(err, d0, d1, index_bug=bug).tolist() == [[0, 0, 0]]
    err[2, 0, 0] = 5.0                                 # one finite candidate is taken as before
    assert rf.select_candidate(err, d0, d1)[0, 0] == 2


def test_non_finite_derivative_is_kept_as_the_authors_kernel_gives_it():
    """``derivative`` (C:138-139) divides by 1e-10 + y - 1.01 y with no guard. Where that is 0
    (a y near 1e-8 whose roundings cancel, found here by search): F, F_s > 0 give inf - inf = NaN,
    which the clamp's comparisons (C:1364) let through; F > 0 > F_s gives +inf, which the clamp
    replaces by w_max / sum w. A NaN SURE is never selected (F:655)."""
    y0 = 1e-8
    while 1e-10 + y0 - 1.01 * y0 != 0.0:
        y0 = np.nextafter(y0, 0.0)
    y = np.full((1, 2, 3), y0)
    F = np.full((1, 2, 3), 0.5)
    Fs = np.array([[[0.25] * 3, [-0.25] * 3]])
    d = rf.finite_difference_derivative(F, Fs, y)
    assert np.isnan(d[0, 0]).all() and np.isposinf(d[0, 1]).all()
    clamped = rf.clamp_derivative(d, np.array([[0.3, 0.4]]))
    assert np.isnan(clamped[0, 0]).all()
    np.testing.assert_array_equal(clamped[0, 1], [0.4, 0.4, 0.4])
    err = np.stack([rf.sure(F, clamped, y, np.full_like(y, 0.01)), np.ones((1, 2)), np.full((1, 2), 2.0)])
    assert np.isnan(err[0, 0, 0])
    assert rf.select_candidate(err, np.zeros((1, 2, 3)), np.ones((1, 2, 3)))[0, 0] == 1


def test_centre_ratio_has_the_authors_epsilon():
    """``ratio`` (C:150, called at C:1339): w_max / (1e-10 + sum w). An isolated pixel has
    w_max = sum w = 1e-3 (C:17,1175-1177): 1e-3 / (1e-3 + 1e-10), not 1."""
    h = w = 5
    data = np.zeros((1, h, w, 3))
    guide = np.zeros((h, w, 3))
    guide[2, 2] = 1e3
    res = rf.nl_means(data, guide, np.zeros((h, w, 3)), radius=1, patch_radius=0, weight_radius=0, k=1.0)
    assert res.centre[2, 2] == pytest.approx(1e-3 / (1e-10 + 1e-3), rel=1e-14)
    assert res.centre[2, 2] < 1.0 - 5e-8


def test_second_pass_window_is_half_the_radius_rounded_down():
    """F:410 ``SetWndRad(wnd_rad / 2)``: for wnd_rad 1 the window radius is 0, the offset loop of
    FilterData (C:1150-1153) is empty and the output is the input (only the centre, weight 1e-3 /
    1e-3, C:1175-1177)."""
    rng = np.random.default_rng(8)
    blend = 0.5 + 0.02 * rng.standard_normal((2, 7, 9, 3))            # flat: a wider window averages
    prefiltered = {"f": (np.ones((7, 9, 3)), np.zeros((7, 9, 3)))}
    out = rdfc.second_pass(blend, prefiltered, 1.0, radius=1)
    np.testing.assert_allclose(out, blend, rtol=1e-15, atol=0)
    assert np.abs(rdfc.second_pass(blend, prefiltered, 1.0, radius=2) - blend).max() > 1e-3


def test_non_finite_layers_as_the_authors(make_render_buffers):
    """F:135-138,160-164: a NaN normal component is skipped (a pixel whose samples all are NaN
    keeps the buffer's initial 0, F:79, and M2 = 0: variance 0), after the (n + 1)/2 map; nothing
    else is guarded (NaN colour reaches the output). ``nonfinite="zero"``: nan_to_num everywhere."""
    buffers = make_render_buffers(height=10, width=11, seed=2)
    layers = dict(buffers.layers)
    for name in ("normal_a", "normal_variance"):
        layers[name] = layers[name].copy()
        layers[name][3, 4, 0] = np.nan
    feats, _ = rdfc.authors_features(RenderBuffers(layers=layers, spp=buffers.spp))
    assert feats["normal"][0][3, 4, 0] == 0.0 and feats["normal"][2][3, 4, 0] == 0.0
    zero, _ = rdfc.authors_features(RenderBuffers(layers=layers, spp=buffers.spp), nonfinite="zero")
    assert zero["normal"][0][3, 4, 0] == 0.5
    layers["color_a"] = layers["color_a"].copy()
    layers["color_a"][5, 5, 1] = np.nan
    broken = RenderBuffers(layers=layers, spp=buffers.spp)
    assert np.isnan(rdfc.denoise(broken, radius=2).full).any()
    assert np.isfinite(rdfc.denoise(broken, radius=2, nonfinite="zero").full).all()
    with pytest.raises(ValueError, match="nonfinite"):
        rdfc.denoise(broken, radius=2, nonfinite="clip")
