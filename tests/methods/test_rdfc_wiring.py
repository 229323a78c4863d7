"""RDFC's wiring (methods/rdfc.py): which arrays reach each NL-means call of one ``denoise``.

Every call of the kernel entry point (``rdfc.nl_means``) is intercepted and its arrays recorded
by value: the data buffers, the guide, the guide's numerator / denominator variances (Vn, Vd) and
each feature's value, variance and threshold. Each is compared with an array this test computes
from the render layers (or from the recorded *outputs* of the earlier calls, the only thing taken
from our code) following the authors' driver: fbksd/fbksd-package ``denoisers/RDFC/src/`` at
3059e1480bf7d0eb5cd4a8a106e37fc06078c59f (``F`` = multifilm.cpp, ``C`` = featurefilter.cu; file:line):

* prefilter, one call per feature (F:311-348 with ``use_ld_samples`` true, M:34): data = the
  feature's two buffers, guide = their mean (``PushGuide`` C:933-960, ``GetDataMean`` C:954),
  Vn = Vd = the feature's sample variance rescaled by box21((A-B)^2/4) / (1e-10 + box21(var))
  (``GetScaledSampleVariance`` C:1392-1412, C:155-162);
* the prefiltered feature (``PushFeature`` C:867-871): value = the mean of the two filtered buffers,
  variance (A~ - B~)^2/4 pyramid-smoothed (``GetDataMeanVariance`` C:1415-1429);
* candidates (F:716-746): data = colour buffers A, B; guide y = (A + B)/2, Vn = Vd = rescaled V;
  features with tau 1e-3 (FIRST, SECOND) and 1e-4 (THIRD), position maxPos^2 tau (F:328-333,729-733);
* error filter (F:635-648): data = the three SURE maps (F:427-434,639; y = full mean, sigma^2 = the
  rescaled V, F:723,746; dF/dy from the candidates' outputs, C:132-141,1339-1369), guide y and the
  rescaled V (still pushed, F:718), no features (F:644);
* selection filter (F:664-677): data = the binary maps of the argmin rule (F:651-672), same guide;
* second pass (F:409-423): data = the blended buffers (F:598-627), guide = their mean,
  Vn = Vd = (A~ - B~)^2/4 pyramid-smoothed (``PushGuide(BufferSet)`` C:900-916), tau 1e-4.

The synthetic render has noisy features (A != B), non-uniform feature and colour variances that do
not match the buffers' spread (so every rescaling changes its array), albedo above 1 in places and
a non-constant visibility, so that swapping any of these arrays for another fails the test."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from mcbench.io.buffers import RenderBuffers
from methods import rdfc
from tests.methods.test_rdfc_fidelity import brute_box, brute_pyr

H, W = 20, 22
RADIUS = 3
XYZ_TO_RGB = np.array([[3.240479, -1.537150, -0.498535],      # F:117-119
                       [-0.969256, 1.875991, 0.041556],
                       [0.055648, -0.204043, 1.057311]])


def wiring_case(make_render_buffers, seed=11):
    """A small render whose every layer differs between A and B and whose variances are neither
    uniform nor the buffers' own spread."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    region = xx + 0.4 * yy > 0.55
    truth = np.where(region[..., None], np.stack([0.7 * xx + 0.1, 0.3 + 0.4 * yy, 0.5 + 0 * xx], -1),
                     np.stack([0.2 + 0.1 * yy, 0.6 + 0 * xx, 0.1 + 0.5 * xx], -1))
    layers = dict(make_render_buffers(truth, half_std=0.08, seed=seed, spp=8).layers)
    layers["variance"] = (0.003 * (0.3 + rng.random((H, W, 3)))).astype(np.float32)

    def pair(base, noise):
        return [(base + noise * rng.standard_normal(base.shape)).astype(np.float32) for _ in range(2)]

    normal = np.stack([0.3 * region - 0.1, 0.2 * yy, 0.9 + 0 * xx], -1)
    albedo = np.where(region[..., None], [0.8, 0.3, 0.5], [0.2, 0.6, 0.1]) * (1 + 0.8 * (xx > 0.8))[..., None]
    position = np.stack([xx, yy, 1.0 + 0.5 * region], -1)
    visibility = (xx + yy > 0.7).astype(np.float64)
    for name, base, noise in (("normal", normal, 0.05), ("albedo", albedo, 0.03), ("position", position, 0.02),
                              ("visibility", visibility, 0.2)):
        layers[name + "_a"], layers[name + "_b"] = pair(base, noise)
        layers[name] = ((layers[name + "_a"].astype(np.float64) + layers[name + "_b"]) / 2).astype(np.float32)
        layers[name + "_variance"] = (noise ** 2 * (0.2 + rng.random(base.shape))).astype(np.float32)
    return RenderBuffers(layers=layers, spp=8)


def record_calls(monkeypatch):
    """Replace rdfc.nl_means by a spy; returns the list it fills with (arguments by name, copies
    of the arrays, result)."""
    real = rdfc.nl_means
    signature = inspect.signature(real)
    calls = []

    def spy(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        arguments = dict(bound.arguments)
        for key in ("buffers", "guide", "guide_variance", "guide_variance_den"):
            if arguments[key] is not None:
                arguments[key] = np.array(arguments[key], dtype=np.float64)
        arguments["features"] = [(np.array(f.value, np.float64), np.array(f.variance, np.float64), f.tau)
                                 for f in arguments["features"]]
        result = real(*args, **kwargs)
        calls.append((arguments, result))
        return result

    monkeypatch.setattr(rdfc, "nl_means", spy)
    return calls


def chan(x):
    x = np.asarray(x, np.float64)
    return x[..., None] if x.ndim == 2 else x


def rescaled(a, b, var):
    """GetScaledSampleVariance (C:1392-1412): var box21((a-b)^2/4) / (1e-10 + box21(var))."""
    return var * brute_box((a - b) ** 2 / 4, 10) / (1e-10 + brute_box(var, 10))


def residual(a, b):
    """GetDataMeanVariance (C:1415-1429): (a-b)^2/4, pyramid [0.1353, 1, 0.1353] (H:148)."""
    return brute_pyr((a - b) ** 2 / 4)


def expected_features(layers):
    """F:107-136 per pixel (docs/fidelity_rdfc.md, departure 2): {name: (A, B, variance)}, maxPos."""
    out = {}
    for name in rdfc.FEATURES:
        a, b, var = (chan(layers[name + s]) for s in ("_a", "_b", "_variance"))
        if name == "normal":
            a, b, var = (a + 1) / 2, (b + 1) / 2, var / 4
        elif name == "albedo":
            m = np.maximum(1, ((a + b) / 2).max(-1, keepdims=True))
            a, b = a / np.maximum(1, a.max(-1, keepdims=True)), b / np.maximum(1, b.max(-1, keepdims=True))
            var = var / m ** 2
        elif name == "position":
            a, b = np.einsum("ij,hwj->hwi", XYZ_TO_RGB, a), np.einsum("ij,hwj->hwi", XYZ_TO_RGB, b)
            var = np.einsum("ij,hwj->hwi", XYZ_TO_RGB ** 2, var)
        out[name] = (a, b, var)
    pos = (out["position"][0] + out["position"][1]) / 2
    return out, max(0.0, float(pos[np.isfinite(pos)].max()))


def selection_rule(err, d_first, d_second):
    """F:651-662 by loops: last to first, strict <, FIRST only if mean dF/dy(FIRST) <= the mean of
    SECOND's flat entries pix..pix+2 (the authors' index), sel_map starting at 0 (F:87)."""
    k, h, w = err.shape
    flat = np.concatenate([d_second.reshape(-1), np.zeros(2)])
    first = d_first.reshape(-1)
    sel = np.zeros(h * w, dtype=int)
    e = err.reshape(k, -1)
    for pix in range(h * w):
        best = np.inf
        for i in range(k - 1, -1, -1):
            if e[i, pix] < best:
                if i > 0 or first[3 * pix:3 * pix + 3].mean() <= flat[pix:pix + 3].mean():
                    best, sel[pix] = e[i, pix], i
    return sel.reshape(h, w)


def close(ours, expected, what):
    ours, expected = np.asarray(ours, np.float64), np.asarray(expected, np.float64)
    assert ours.shape == expected.shape, (what, ours.shape, expected.shape)
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-13, err_msg=what)


def check_guide(call, guide, variance, what):
    close(call["guide"], guide, what + ": guide")
    close(call["guide_variance"], variance, what + ": guide variance (Vn)")
    vd = call["guide_variance"] if call["guide_variance_den"] is None else call["guide_variance_den"]
    close(vd, variance, what + ": guide variance (Vd)")


def check_features(call, prefiltered, taus, what):
    assert len(call["features"]) == len(prefiltered), what
    for (value, var, tau), (name, (ev, evar)), t in zip(call["features"], prefiltered.items(), taus):
        close(value, ev, f"{what}: feature {name} value")
        close(var, evar, f"{what}: feature {name} variance")
        assert tau == pytest.approx(t, rel=1e-12), (what, name, tau, t)


def test_every_filter_gets_the_authors_arrays(make_render_buffers, monkeypatch):
    buffers = wiring_case(make_render_buffers)
    calls = record_calls(monkeypatch)
    out = rdfc.denoise(buffers, radius=RADIUS)
    assert len(calls) == 9, [sorted(c[0]) for c in calls]
    layers = buffers.layers
    a, b = chan(layers["color_a"]), chan(layers["color_b"])
    y = (a + b) / 2
    v = rescaled(a, b, chan(layers["variance"]))
    assert not np.allclose(v, chan(layers["variance"]), rtol=0.05)            # the rescaling acts

    # prefilter (F:311-348): one call per feature, in the authors' order
    feats, max_pos = expected_features(layers)
    prefiltered = {}
    for (call, result), name in zip(calls[:4], rdfc.FEATURES):
        fa, fb, fvar = feats[name]
        close(call["buffers"], np.stack([fa, fb]), f"prefilter {name}: data")
        guide_var = rescaled(fa, fb, fvar)
        assert not np.allclose(guide_var, fvar, rtol=0.05), name
        check_guide(call, (fa + fb) / 2, guide_var, f"prefilter {name}")
        assert call["features"] == [], name
        filt = result.buffers
        prefiltered[name] = ((filt[0] + filt[1]) / 2, residual(filt[0], filt[1]))   # C:869-870

    def taus(t):
        return [t, t, max_pos ** 2 * t, t]                                    # F:729-733, F:416-420

    # candidates (F:716-746)
    (cand, firsts), (third, third_res) = calls[4], calls[5]
    for call, what, tau in ((cand, "FIRST/SECOND", 1e-3), (third, "THIRD", 1e-4)):
        close(call["buffers"], np.stack([a, b]), what + ": data")
        check_guide(call, y, v, what)
        check_features(call, prefiltered, taus(tau), what)
    assert third["use_colour"] is False and cand["delta"] is True

    # SURE maps from the candidates' outputs (C:1335-1370, F:427-434,639)
    def clamp(d, centre):
        bad = ((d < 0) | (d > 1)).any(-1, keepdims=True)
        return np.where(bad, centre[..., None], d)

    results = list(firsts) + [third_res]
    means = [res.buffers.mean(axis=0) for res in results]
    den = 1e-10 + y - 1.01 * y
    derivs = [clamp(means[i] / den - results[i].scaled / den, results[i].centre) for i in range(2)]
    derivs.append(clamp(np.repeat(third_res.centre[..., None], 3, -1), third_res.centre))
    sure = np.stack([((m - y) ** 2 + 2 * d * v - v).mean(-1) for m, d in zip(means, derivs)])

    (err, err_res), (sel, sel_res), (p2, p2_res) = calls[6:]
    close(err["buffers"], sure[..., None], "error filter: data (SURE maps)")
    check_guide(err, y, v, "error filter")
    assert err["features"] == []

    choice = selection_rule(err_res.buffers[..., 0], derivs[0], derivs[1])
    assert len(np.unique(choice)) > 1                                           # the maps are not trivial
    onehot = np.stack([(choice == i).astype(float) for i in range(3)])[..., None]
    close(sel["buffers"], onehot, "selection filter: data (binary maps)")
    check_guide(sel, y, v, "selection filter")
    assert sel["features"] == []

    # second pass (F:409-423)
    weights = sel_res.buffers[..., 0]
    blend = sum(weights[s][None, ..., None] * results[s].buffers for s in range(3)) / weights.sum(0)[None, ..., None]
    close(p2["buffers"], blend, "second pass: data (blended buffers)")
    check_guide(p2, blend.mean(0), residual(blend[0], blend[1]), "second pass")
    check_features(p2, prefiltered, taus(1e-4), "second pass")

    # the output is the second pass's two buffers and their mean (F:480-491, C:1318-1321)
    close(out.a, p2_res.buffers[0].astype(np.float32), "output a")
    close(out.b, p2_res.buffers[1].astype(np.float32), "output b")
