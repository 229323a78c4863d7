"""Tests of mcbench.filters.bilateral: the cross-bilateral filter (Zheng et al. 2021 Eq. 32-34) against a
brute-force loop in float64 and float32, across its parallel bands and for vectors of channels;
its exponential against math.exp; the "sum" colour distance against the "mean" one."""

from __future__ import annotations

import math

import numpy as np
import pytest

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
