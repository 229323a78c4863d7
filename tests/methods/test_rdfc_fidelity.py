"""RDFC against the authors' code (fbksd-package denoisers/RDFC, docs/fidelity_rdfc.md): the
constants and steps taken from it, each against a brute force or closed form whose constants are
written here from the authors' source (featurefilter.cu / multifilm.cpp line numbers), so a wrong
constant in methods/rdfc.py or mcbench/filters/smoothing.py fails a test."""

from __future__ import annotations

import numpy as np
import pytest

from mcbench.filters.smoothing import box_mean, pyramid_smooth
from mcbench.io.buffers import RenderBuffers
from methods import rdfc


def brute_box(image, r):
    """conv_box (featurefilter.cu:255-280) row pass then column pass, by loops."""
    h, w = image.shape[:2]
    tmp = np.zeros_like(image, dtype=np.float64)
    for y in range(h):
        for x in range(w):
            tmp[y, x] = image[y, max(0, x - r):min(w, x + r + 1)].mean(axis=0)
    out = np.zeros_like(tmp)
    for y in range(h):
        for x in range(w):
            out[y, x] = tmp[max(0, y - r):min(h, y + r + 1), x].mean(axis=0)
    return out


def brute_pyr(image, v=0.1353):
    """conv_pyr (featurefilter.cu:319-347) with the default tap of featurefilter.h:148, by loops."""
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


def test_box_and_pyramid_match_the_authors_kernels():
    rng = np.random.default_rng(0)
    image = rng.random((13, 30, 3))
    np.testing.assert_allclose(box_mean(image, 10), brute_box(image, 10), rtol=1e-12)
    np.testing.assert_allclose(box_mean(image[..., 0], 2), brute_box(image[..., 0], 2), rtol=1e-12)
    np.testing.assert_allclose(pyramid_smooth(image), brute_pyr(image), rtol=1e-12)


def render(h=24, w=26, seed=1):
    rng = np.random.default_rng(seed)
    truth = np.broadcast_to(np.linspace(0.2, 0.8, w)[None, :, None], (h, w, 3))
    layers = {}
    for s in ("_a", "_b"):
        layers["color" + s] = truth + rng.normal(size=(h, w, 3)) * 0.1
        layers["variance" + s] = rng.random((h, w, 3)) * 0.02
    layers["color"] = (layers["color_a"] + layers["color_b"]) / 2
    layers["variance"] = (layers["variance_a"] + layers["variance_b"]) / 4
    albedo = np.where(np.arange(w)[None, :, None] < w // 2, 0.3, 0.7) * np.ones((h, w, 3))
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    for s in ("", "_a", "_b"):
        layers["albedo" + s], layers["normal" + s], layers["depth" + s] = albedo, normal, np.ones((h, w))
    return RenderBuffers(layers=layers, spp=4)


def test_rescaled_variance_is_the_authors_21_pixel_dual_buffer_rescaling():
    """featurefilter.cu:1392-1412 (conv_box radius 10, ratio + 1e-10) on the half buffers."""
    buffers = render()
    a, b, va = buffers.color_a, buffers.color_b, buffers.variance_a
    expected = va * brute_box((a - b) ** 2 / 2, 10) / (1e-10 + brute_box(va, 10))
    np.testing.assert_allclose(rdfc.half_variance(buffers, "a", "rescaled"), expected, rtol=1e-10)
    np.testing.assert_array_equal(rdfc.half_variance(buffers, "a", "raw"), va)


def test_derivative_clamp_is_the_authors_rule():
    """featurefilter.cu:1339, 1354-1369: where any channel of dF/dy leaves [0, 1], all three become
    w_pp / sum w; elsewhere unchanged. w_pp / sum w is measured independently as the filter's
    response at p to a unit impulse at p, with the same (guided) weights."""
    rng = np.random.default_rng(5)
    h, w = 14, 15
    y = rng.random((h, w, 3))
    y[7, 7] = 20.0                                     # an outlier: derivatives leave [0, 1]
    v = rng.random((h, w, 3)) * 0.01
    feats, fvars = [np.ones((h, w, 3)) * 0.5], [np.zeros((h, w))]
    kw = dict(radius=3, patch_radii=(1, 3, 0), k_colors=(0.45, 0.45, np.inf))
    _, raw, _ = rdfc.candidate_filters(y, v, feats, fvars, clamp_derivative=False, **kw)
    _, clamped, _ = rdfc.candidate_filters(y, v, feats, fvars, clamp_derivative=True, **kw)
    invalid = np.any((raw < 0) | (raw > 1), axis=-1)
    assert invalid[:2].any(), "the test needs pixels to clamp"
    np.testing.assert_array_equal(clamped[~invalid], raw[~invalid])
    for k, py, px in list(zip(*np.nonzero(invalid)))[:6]:
        impulse = np.zeros((h, w, 3))
        impulse[py, px] = 1.0
        response = rdfc.candidate_filters(impulse, v, feats, fvars, guide=y, guide_variance=v, **kw)[0]
        np.testing.assert_allclose(clamped[k, py, px], response[k, py, px], rtol=1e-10)
    # THIRD with constant features: every weight 1, so dF/dy = 1 / (pixels in the window), in [0, 1]
    assert not invalid[2].any()
    np.testing.assert_allclose(clamped[2, 7, 7], 1.0 / 49)


def test_authors_second_pass_constants():
    """multifilm.cpp:409-423 and featurefilter.cu:900-916, 1415-1429: guide = mean of the pass-1
    buffers, variance (A~ - B~)^2 / 4 pyramid-smoothed, f = 3, k_c = 0.45, k_f = 0.6, window
    radius / 2, feature threshold 1e-4, the pass-1 buffer itself as data; nothing else."""
    buffers = render()
    rng = np.random.default_rng(2)
    first = {w: buffers.layers["color_" + w] * 0.5 + 0.2 + rng.random((24, 26, 3)) * 0.05 for w in "ab"}
    feats = rdfc.prefilter_features(buffers)
    out = rdfc.authors_second_pass(first, feats, radius=8)
    guide = (first["a"] + first["b"]) / 2
    gvar = brute_pyr((first["a"] - first["b"]) ** 2 / 4)
    for w in "ab":
        expected = rdfc.candidate_filters(first[w], gvar, *feats[w], guide=guide, guide_variance=gvar, radius=4,
                                          patch_radii=(3,), k_colors=(0.45,), k_f=0.6, tau=1e-4)[0][0]
        np.testing.assert_allclose(out[w], expected, rtol=1e-12)


def test_defaults_are_the_documented_ones():
    """The defaults docs/fidelity_rdfc.md states (a changed default must change the doc too)."""
    assert (rdfc.WINDOW_RADIUS, rdfc.K_COLOR, rdfc.K_FEATURE, rdfc.TAU, rdfc.TAU_SECOND) == (10, 0.45, 0.6, 1e-3, 1e-4)
    assert rdfc.CANDIDATE_PATCH_RADII[:2] == (1, 3) and rdfc.CANDIDATE_K_COLOR[2] == np.inf
    assert (rdfc.SECOND_PASS, rdfc.CLAMP_DERIVATIVE, rdfc.VARIANCE, rdfc.VARIANCE_BOX) == ("authors", True, "raw", 10)


@pytest.mark.parametrize("second_pass", ["ours", "authors"])
def test_denoise_runs_both_second_passes(second_pass):
    out = rdfc.denoise(render(16, 16), radius=3, second_pass=second_pass)
    assert all(np.all(np.isfinite(getattr(out, n))) for n in ("full", "a", "b"))
    with pytest.raises(ValueError):
        rdfc.denoise(render(8, 8), radius=2, second_pass="both")
