"""Tests of mcbench.filters.blur_and_outliers, the public code's passes around the cross-bilateral
filter: the Gaussian blur against scipy.ndimage and the closed form of OpenCV's kernel, the outlier
removal against a direct loop, the public code's outlier pass against filter.h written out."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from mcbench.filters import blur_and_outliers


def test_gaussian_kernel_is_opencvs_sigma_zero_kernel():
    """OpenCV 4.6's getGaussianKernel(k, 0) (measured: the program of the golden files was built
    with it): fixed tables of 1/256 for k <= 9 ([4, 13, 30, 51, 60, 51, 30, 13, 4] / 256 for 9,
    which differ from the sigma-1.7 rule by up to 0.5/256), the rule sigma = 0.3 ((k - 1) / 2 - 1)
    + 0.8 above; taps normalised."""
    taps = blur_and_outliers.gaussian_kernel(9)
    np.testing.assert_array_equal(taps * 256, [4, 13, 30, 51, 60, 51, 30, 13, 4])
    x = np.arange(-4, 5)
    rule = np.exp(-x ** 2 / (2 * 1.7 ** 2))
    assert np.abs(rule / rule.sum() - taps).max() > 1e-3          # the rule is not what OpenCV uses
    x = np.arange(-5, 6)
    expected = np.exp(-x ** 2 / (2 * 2.0 ** 2))
    np.testing.assert_allclose(blur_and_outliers.gaussian_kernel(11), expected / expected.sum(), rtol=1e-14)
    assert taps.sum() == pytest.approx(1.0, abs=1e-15)
    with pytest.raises(ValueError):
        blur_and_outliers.gaussian_kernel(8)


def test_gaussian_blur_matches_scipy_reflect_101():
    """Separable blur with reflect-101 borders (scipy's "mirror" mode), on a colour image, a
    single-channel one and one with a 1-pixel axis (constant)."""
    rng = np.random.default_rng(19)
    taps = blur_and_outliers.gaussian_kernel(9)
    for image in (rng.uniform(0, 1, (13, 17, 3)), rng.uniform(0, 1, (6, 5))):
        expected = ndimage.correlate1d(ndimage.correlate1d(image, taps, axis=0, mode="mirror"),
                                       taps, axis=1, mode="mirror")
        np.testing.assert_allclose(blur_and_outliers.gaussian_blur(image, kernel_size=9), expected,
                                   rtol=1e-12, atol=1e-14)
    row = rng.uniform(0, 1, (1, 12, 3))
    expected = ndimage.correlate1d(row, taps, axis=1, mode="mirror")
    np.testing.assert_allclose(blur_and_outliers.gaussian_blur(row), expected, rtol=1e-12, atol=1e-14)


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
    got = blur_and_outliers.remove_outliers(maps, radius=3, threshold=2.5)
    expected = outliers_by_loop(maps, 3, 2.5)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)
    assert got[0, 4, 5, 1] < 1.0 and got[1, 0, 0, 2] > 0.0
    replaced = (got != maps).mean()
    assert 0 < replaced < 0.2                 # plain noise stays mostly as it is
    single = blur_and_outliers.remove_outliers(maps[0, :1, :1])      # a 1 x 1 map has no neighbours
    np.testing.assert_array_equal(single, maps[0, :1, :1])


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
    np.testing.assert_array_equal(blur_and_outliers.gaussian_kernel(7), np.array([1, 3.5, 7, 9, 7, 3.5, 1]) / 32)
    x = np.arange(7) - 3.0
    rule = np.exp(-x ** 2 / (2 * 1.4 ** 2))
    assert np.abs(rule / rule.sum() - blur_and_outliers.gaussian_kernel(7)).max() > 1e-3


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
    got = blur_and_outliers.remove_outlier_pixels(maps, radius=3, threshold=2.5)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-14)
    assert (np.abs(got - maps).max(axis=-1) > 0).sum() >= 3        # the planted ones were replaced
    band = blur_and_outliers.remove_outlier_pixels(maps[:, 2:11], radius=3, threshold=2.5, first_row=2,
                                           height=11, rows=(5, 11))
    np.testing.assert_allclose(band, expected[:, 5:11], rtol=1e-12, atol=1e-14)
    ours = blur_and_outliers.remove_outliers(maps, radius=3, threshold=2.5)
    assert np.abs(ours - expected).max() > 1e-3
