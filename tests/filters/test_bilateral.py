"""Tests of mcbench.filters.bilateral: the cross-bilateral filter (Zheng et al. 2021 Eq. 32-34) against a
brute-force loop in float64 and float32, across its parallel bands and for vectors of channels;
its exponential against math.exp; the "sum" colour distance against the "mean" one; and the
public code's passes around it: the Gaussian blur against scipy.ndimage and the closed form of
OpenCV's kernel, the outlier removal against a direct loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from mcbench.filters import bilateral
from mcbench.filters.bilateral import cross_bilateral_filter, cross_bilateral_filter_vectors


# ---------------------------------------------------------------------------------------
# cross-bilateral filter vs brute force
# ---------------------------------------------------------------------------------------
def brute_force_cbf(values, guide, gvar, features, sigmas, ss, sg, radius):
    K, H, W = values.shape
    out = np.zeros_like(values)
    for y in range(H):
        for x in range(W):
            acc = np.zeros(K)
            wsum = 0.0
            for qy in range(max(0, y - radius), min(H, y + radius + 1)):
                for qx in range(max(0, x - radius), min(W, x + radius + 1)):
                    k = np.exp(-((qy - y) ** 2 + (qx - x) ** 2) / (2 * ss ** 2))
                    for f, sf in zip(features, sigmas):
                        f = f if f.ndim == 3 else f[:, :, None]
                        k *= np.exp(-np.sum((f[y, x] - f[qy, qx]) ** 2) / (2 * sf ** 2))
                    if guide is not None:
                        terms = []
                        for c in range(guide.shape[2]):
                            num = (guide[y, x, c] - guide[qy, qx, c]) ** 2
                            den = gvar[y, x, c] + gvar[qy, qx, c]
                            if den <= 1e-20:
                                terms.append(0.0 if num == 0 else np.inf)
                            else:
                                terms.append(num / den)
                        k *= np.exp(-np.mean(terms) / (2 * sg ** 2))
                    acc += k * values[:, qy, qx]
                    wsum += k
            out[:, y, x] = acc / wsum
    return out


def test_cross_bilateral_matches_brute_force():
    rng = np.random.default_rng(15)
    H, W, K = 9, 11, 2
    values = rng.normal(size=(K, H, W))
    guide = rng.uniform(0, 1, (H, W, 3))
    gvar = rng.uniform(0, 0.05, (H, W, 3))
    gvar[2:4, 3:6] = 0.0  # exercise the zero-variance guard
    guide[2:4, 3:5] = 0.5
    feats = [rng.uniform(0, 1, (H, W, 3)), rng.uniform(0, 1, (H, W))]
    sig = [0.4, 0.3]
    got = cross_bilateral_filter(values, guide, gvar, feats, sig, 2.0, 1.5, 3)
    ref = brute_force_cbf(values, guide, gvar, feats, sig, 2.0, 1.5, 3)
    assert got.shape == (K, H, W) and got.dtype == np.float64
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12)
    got2 = cross_bilateral_filter(values, None, None, [], [], 1.0, 1.0, 2)
    ref2 = brute_force_cbf(values, None, None, [], [], 1.0, 1.0, 2)
    np.testing.assert_allclose(got2, ref2, rtol=1e-10, atol=1e-12)


def random_guided_case(rng, H, W, K):
    values = rng.normal(size=(K, H, W))
    guide = rng.uniform(0, 1, (H, W, 3))
    gvar = rng.uniform(0, 0.05, (H, W, 3))
    gvar[2:4, 3:6] = 0.0      # the zero-variance guard: equal guides (term 0) and unequal (kernel 0)
    guide[2:4, 3:5] = 0.5
    feats = [rng.uniform(0, 1, (H, W, 3)), rng.uniform(0, 1, (H, W))]
    return values, guide, gvar, feats


@pytest.mark.parametrize("dtype,rtol", [(np.float64, 1e-10), (np.float32, 2e-5)])
def test_bands_and_float32_match_brute_force(dtype, rtol):
    """An image taller than one parallel band (pairs across band borders are evaluated by both
    bands) equals the brute-force loop; float32 to its rounding."""
    rng = np.random.default_rng(16)
    H, W, K = bilateral.BAND_ROWS + 9, 7, 2
    values, guide, gvar, feats = random_guided_case(rng, H, W, K)
    got = cross_bilateral_filter(values, guide, gvar, feats, [0.4, 0.3], 2.0, 1.5, 3, dtype=dtype)
    ref = brute_force_cbf(values, guide, gvar, feats, [0.4, 0.3], 2.0, 1.5, 3)
    assert got.dtype == dtype
    np.testing.assert_allclose(got, ref, rtol=rtol, atol=rtol)
    assert np.abs(got - values).max() > 0.1                      # it does filter


def test_vectors_share_the_kernel_of_their_maps():
    """G maps of C-vectors (the ensemble's (N, H, W, 3) weights) give what filtering each of the
    G x C maps alone gives."""
    rng = np.random.default_rng(17)
    H, W = 12, 10
    _, guide, gvar, feats = random_guided_case(rng, H, W, 1)
    vectors = rng.dirichlet(np.ones(3), size=(H, W, 3)).transpose(3, 0, 1, 2)   # (3, H, W, 3)
    got = cross_bilateral_filter_vectors(vectors, guide, gvar, feats, [0.4, 0.3], 3.0, 2.0, 7)
    for g in range(3):
        for c in range(3):
            alone = cross_bilateral_filter(vectors[g, :, :, c], guide, gvar, feats, [0.4, 0.3],
                                           3.0, 2.0, 7)[0]
            np.testing.assert_allclose(got[g, :, :, c], alone, rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("dtype,rtol", [(np.float64, 1e-13), (np.float32, 4e-7)])
def test_kernel_is_the_exponential_of_the_exponent(dtype, rtol):
    """Two pixels with values 0 and 1: the first one's output is k / (1 + k) with
    k = exp(-e), e = 1 (spatial, sigma_s = 1/sqrt(2)) + d^2 (feature difference d,
    sigma_f = 1/sqrt(2)); k recovered from the output matches math.exp over the whole range,
    and a kernel past the cutoff exp(-87) is exactly 0. (In float32 the exponent itself is
    rounded, so k's relative error grows like e times the rounding.)"""
    exponents = np.linspace(1.0, 86.0, 400)
    for e in exponents:
        feature = np.array([[0.0, math.sqrt(e - 1.0)]])
        out = cross_bilateral_filter(np.array([[0.0, 1.0]]), None, None, [feature],
                                     [1 / math.sqrt(2)], 1 / math.sqrt(2), 1.0, 1, dtype=dtype)
        k = float(out[0, 0, 0]) / (1.0 - float(out[0, 0, 0]))
        assert k == pytest.approx(math.exp(-e), rel=rtol * (1 if dtype == np.float64 else e)), e
    beyond = cross_bilateral_filter(np.array([[0.0, 1.0]]), None, None, [np.array([[0.0, 9.5]])],
                                    [1 / math.sqrt(2)], 1 / math.sqrt(2), 1.0, 1, dtype=dtype)
    assert beyond[0, 0, 0] == 0.0 and beyond[0, 0, 1] == 1.0


def test_sum_colour_distance_is_mean_with_a_smaller_sigma():
    """D^2 summed over C = 3 channels is 3 times their mean: "sum" at sigma_g equals "mean" at
    sigma_g / sqrt(3), and differs from "mean" at sigma_g."""
    rng = np.random.default_rng(18)
    values, guide, gvar, feats = random_guided_case(rng, 10, 11, 2)
    summed = cross_bilateral_filter(values, guide, gvar, feats, [0.4, 0.3], 2.0, 1.5, 3,
                                    colour_distance="sum")
    mean = cross_bilateral_filter(values, guide, gvar, feats, [0.4, 0.3], 2.0, 1.5 / math.sqrt(3),
                                  3, colour_distance="mean")
    np.testing.assert_allclose(summed, mean, rtol=1e-12, atol=1e-14)
    same_sigma = cross_bilateral_filter(values, guide, gvar, feats, [0.4, 0.3], 2.0, 1.5, 3)
    assert np.abs(same_sigma - summed).max() > 1e-3
    with pytest.raises(ValueError, match="colour_distance"):
        cross_bilateral_filter(values, guide, gvar, feats, [0.4, 0.3], 2.0, 1.5, 3,
                               colour_distance="max")


def test_gaussian_kernel_is_opencvs_sigma_zero_kernel():
    """OpenCV 4.6's getGaussianKernel(k, 0) (measured: the program of the golden files was built
    with it): fixed tables of 1/256 for k <= 9 ([4, 13, 30, 51, 60, 51, 30, 13, 4] / 256 for 9,
    which differ from the sigma-1.7 rule by up to 0.5/256), the rule sigma = 0.3 ((k - 1) / 2 - 1)
    + 0.8 above; taps normalised."""
    taps = bilateral.gaussian_kernel(9)
    np.testing.assert_array_equal(taps * 256, [4, 13, 30, 51, 60, 51, 30, 13, 4])
    x = np.arange(-4, 5)
    rule = np.exp(-x ** 2 / (2 * 1.7 ** 2))
    assert np.abs(rule / rule.sum() - taps).max() > 1e-3          # the rule is not what OpenCV uses
    x = np.arange(-5, 6)
    expected = np.exp(-x ** 2 / (2 * 2.0 ** 2))
    np.testing.assert_allclose(bilateral.gaussian_kernel(11), expected / expected.sum(), rtol=1e-14)
    assert taps.sum() == pytest.approx(1.0, abs=1e-15)
    with pytest.raises(ValueError):
        bilateral.gaussian_kernel(8)


def test_gaussian_blur_matches_scipy_reflect_101():
    """Separable blur with reflect-101 borders (scipy's "mirror" mode), on a colour image, a
    single-channel one and one with a 1-pixel axis (constant)."""
    rng = np.random.default_rng(19)
    taps = bilateral.gaussian_kernel(9)
    for image in (rng.uniform(0, 1, (13, 17, 3)), rng.uniform(0, 1, (6, 5))):
        expected = ndimage.correlate1d(ndimage.correlate1d(image, taps, axis=0, mode="mirror"),
                                       taps, axis=1, mode="mirror")
        np.testing.assert_allclose(bilateral.gaussian_blur(image, kernel_size=9), expected,
                                   rtol=1e-12, atol=1e-14)
    row = rng.uniform(0, 1, (1, 12, 3))
    expected = ndimage.correlate1d(row, taps, axis=1, mode="mirror")
    np.testing.assert_allclose(bilateral.gaussian_blur(row), expected, rtol=1e-12, atol=1e-14)


def outliers_by_loop(maps, radius, threshold):
    """Direct loop: per map, pixel, channel the mean and population std of the other pixels of
    the clipped window; a value further than threshold std from the mean becomes the mean."""
    out = maps.copy()
    G, H, W, C = maps.shape
    for g in range(G):
        for y in range(H):
            for x in range(W):
                for c in range(C):
                    others = [maps[g, qy, qx, c]
                              for qy in range(max(0, y - radius), min(H, y + radius + 1))
                              for qx in range(max(0, x - radius), min(W, x + radius + 1))
                              if (qy, qx) != (y, x)]
                    if not others:
                        continue
                    mean, std = np.mean(others), np.std(others)
                    if abs(maps[g, y, x, c] - mean) > threshold * std:
                        out[g, y, x, c] = mean
    return out


def test_remove_outliers_matches_direct_loop():
    rng = np.random.default_rng(20)
    maps = rng.normal(0.5, 0.05, (2, 9, 11, 3))
    maps[0, 4, 5, 1] = 3.0                     # clear outliers, one at a border
    maps[1, 0, 0, 2] = -2.0
    got = bilateral.remove_outliers(maps, radius=3, threshold=2.5)
    expected = outliers_by_loop(maps, 3, 2.5)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)
    assert got[0, 4, 5, 1] < 1.0 and got[1, 0, 0, 2] > 0.0
    replaced = (got != maps).mean()
    assert 0 < replaced < 0.2                 # plain noise stays mostly as it is
    single = bilateral.remove_outliers(maps[0, :1, :1])      # a 1 x 1 map has no neighbours
    np.testing.assert_array_equal(single, maps[0, :1, :1])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_zero_variance_guard_sees_float64_guides(dtype):
    """Var = 0 and guides that differ by 1e-12 (rounding noise of a weighted sum, invisible in
    float32): the neighbour is excluded in either working precision, as in float64; equal guides
    keep it."""
    values = np.array([[0.0, 1.0]])
    zero_var = np.zeros((1, 2, 3))
    apart = np.full((1, 2, 3), 0.5)
    apart[0, 1] += 1e-12
    out = cross_bilateral_filter(values, apart, zero_var, [], [], 1.0, 2.0, 1, dtype=dtype)
    assert out[0, 0, 0] == 0.0 and out[0, 0, 1] == 1.0
    equal = cross_bilateral_filter(values, np.full((1, 2, 3), 0.5), zero_var, [], [], 1.0, 2.0, 1,
                                   dtype=dtype)
    assert float(equal[0, 0, 0]) == pytest.approx(math.exp(-0.5) / (1 + math.exp(-0.5)), rel=1e-6)


def _reflect101(i, n):
    return -i if i < 0 else 2 * (n - 1) - i if i >= n else i


def brute_force_outlier_pixels(image, radius, threshold):
    """filter.h's remove_outliers<radius>(image, threshold) as its text says, pixel by pixel in
    float64: 7 x 7 OpenCV blur (fixed taps, reflected), the 48 reflected neighbours' mean and
    sqrt((1 - 1/n)(E[x^2] - E[x]^2)); any channel with |c - mean| >= threshold sigma -> the blur."""
    h, w, c = image.shape
    taps = np.array([1, 3.5, 7, 9, 7, 3.5, 1]) / 32 if radius == 3 else None
    blurred = np.zeros_like(image)
    for y in range(h):
        for x in range(w):
            for ky in range(-radius, radius + 1):
                for kx in range(-radius, radius + 1):
                    blurred[y, x] += (taps[ky + radius] * taps[kx + radius]
                                      * image[_reflect101(y + ky, h), _reflect101(x + kx, w)])
    out = image.copy()
    n = (2 * radius + 1) ** 2 - 1
    for y in range(h):
        for x in range(w):
            values = np.array([image[_reflect101(y + dy, h), _reflect101(x + dx, w)]
                               for dy in range(-radius, radius + 1) for dx in range(-radius, radius + 1)
                               if (dy, dx) != (0, 0)])
            mean = values.mean(axis=0)
            spread = (1 - 1 / n) * ((values ** 2).mean(axis=0) - mean ** 2)
            sigma = np.sqrt(np.maximum(spread, 0))
            if np.any(np.abs(image[y, x] - mean) >= threshold * sigma):
                out[y, x] = blurred[y, x]
    return out


def test_gaussian_kernel_7_is_opencvs_fixed_table():
    """OpenCV's getGaussianKernel(7, 0) is the fixed table [1, 3.5, 7, 9, 7, 3.5, 1] / 32, not the
    sigma rule (0.3 * 2 + 0.8 = 1.4 would give other taps), the blur of filter.h's outlier pass."""
    np.testing.assert_array_equal(bilateral.gaussian_kernel(7), np.array([1, 3.5, 7, 9, 7, 3.5, 1]) / 32)
    x = np.arange(7) - 3.0
    rule = np.exp(-x ** 2 / (2 * 1.4 ** 2))
    assert np.abs(rule / rule.sum() - bilateral.gaussian_kernel(7)).max() > 1e-3


def test_public_code_outlier_pass_matches_brute_force():
    """remove_outlier_pixels equals filter.h's pass written out (whole pixel -> 7 x 7 blur when any
    channel is >= 2.5 sigma off its 48 reflected neighbours), on maps with planted outliers,
    also when computed for a band of rows from a tile; a strict '>' or the neighbour-mean
    replacement gives another result."""
    rng = np.random.default_rng(5)
    maps = rng.uniform(0.3, 0.4, (2, 11, 9, 3))
    maps[0, 0, 0, 1] = 0.9          # corner: reflected window
    maps[0, 5, 4, 2] = 0.05
    maps[1, 10, 8] = 0.0
    maps[1, 3, 3] = maps[1, 3, 2]   # a pixel equal to a neighbour stays
    expected = np.stack([brute_force_outlier_pixels(m, 3, 2.5) for m in maps])
    got = bilateral.remove_outlier_pixels(maps, radius=3, threshold=2.5)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)
    assert (np.abs(got - maps).max(axis=-1) > 0).sum() >= 3        # the planted ones were replaced
    band = bilateral.remove_outlier_pixels(maps[:, 2:11], radius=3, threshold=2.5, first_row=2,
                                           height=11, rows=(5, 11))
    np.testing.assert_allclose(band, expected[:, 5:11], rtol=1e-12, atol=1e-14)
    ours = bilateral.remove_outliers(maps, radius=3, threshold=2.5)
    assert np.abs(ours - expected).max() > 1e-3
