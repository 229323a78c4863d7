"""NL-means (Rousselle et al. 2012) against a brute-force per-pixel loop, the compiled filter
against the NumPy reference path, and NFOR's window weights against the weight maps."""

import numpy as np
import pytest

from mcbench.filters import nlmeans
from mcbench.filters.nlmeans import nl_means_filter, nl_means_filter_reference


def brute_force(values, guide, variance, radius, patch_radius, k, alpha, epsilon=1e-10):
    h, w, _ = guide.shape
    out = np.zeros_like(values)
    for y in range(h):
        for x in range(w):
            total, weight_sum = 0.0, 0.0
            for qy in range(max(0, y - radius), min(h, y + radius + 1)):
                for qx in range(max(0, x - radius), min(w, x + radius + 1)):
                    d, count = 0.0, 0
                    for ny in range(-patch_radius, patch_radius + 1):
                        for nx in range(-patch_radius, patch_radius + 1):
                            # edge replication, as scipy's mode="nearest"
                            py, px = min(max(y + ny, 0), h - 1), min(max(x + nx, 0), w - 1)
                            sy = min(max(py + qy - y, 0), h - 1)
                            sx = min(max(px + qx - x, 0), w - 1)
                            vp, vq = variance[py, px], variance[sy, sx]
                            num = (guide[py, px] - guide[sy, sx]) ** 2 - alpha * (vp + np.minimum(vp, vq))
                            d += np.mean(num / (epsilon + k * k * (vp + vq)))
                            count += 1
                    weight = np.exp(-max(0.0, d / count))
                    total = total + weight * values[qy, qx]
                    weight_sum += weight
            out[y, x] = total / weight_sum
    return out


def test_matches_brute_force_interior_and_borders():
    rng = np.random.default_rng(3)
    guide = rng.random((9, 8, 3))
    variance = rng.random((9, 8, 3)) * 0.05
    values = rng.random((9, 8, 2))
    expected = brute_force(values, guide, variance, radius=2, patch_radius=1, k=0.7, alpha=1.0)
    got = nl_means_filter(values, guide, variance, radius=2, patch_radius=1, k=0.7, alpha=1.0)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)


def test_constant_image_is_unchanged_and_noise_is_reduced():
    flat = np.full((16, 16, 3), 0.3)
    np.testing.assert_allclose(nl_means_filter(flat, flat, np.zeros_like(flat)), flat)
    rng = np.random.default_rng(4)
    truth = np.zeros((48, 48, 3))
    truth[:, 24:] = 1.0
    noisy = truth + rng.normal(0, 0.2, truth.shape)
    out = nl_means_filter(noisy, noisy, np.full_like(noisy, 0.04))
    assert np.mean((out - truth) ** 2) < 0.1 * np.mean((noisy - truth) ** 2)


def relmse(got, expected):
    return float(np.mean((got - expected) ** 2 / (expected ** 2 + 1e-2)))


@pytest.mark.parametrize("radius, patch_radius, k, channels", [(2, 1, 0.7, 3), (5, 3, 0.5, 1), (3, 0, 1.0, 2),
                                                                (4, 2, 1.0, 3)])
def test_compiled_filter_equals_numpy_reference(radius, patch_radius, k, channels):
    """The compiled filter against the NumPy path (scipy box filters) on random images whose
    height is not a multiple of the band, with zero-variance pixels and a flat region."""
    rng = np.random.default_rng(radius * 10 + patch_radius)
    h, w = nlmeans.BAND_ROWS + 7, 13
    guide = rng.random((h, w, channels))
    variance = rng.random((h, w, channels)) * 0.05
    variance[:4] = 0.0
    guide[:3, :5] = 0.25
    values = rng.random((h, w, 4)) * 10
    expected = nl_means_filter_reference(values, guide, variance, radius=radius, patch_radius=patch_radius, k=k)
    got = nl_means_filter(values, guide, variance, radius=radius, patch_radius=patch_radius, k=k)
    assert relmse(got, expected) < 1e-12
    # rtol 1e-6, not 1e-12: zero-variance pixels give distances ~ diff^2 / epsilon ~ 1e9, and
    # scipy's running box sums keep ~1e-16 of those in their neighbours' sums (the compiled
    # path sums each patch directly, as the brute force does)
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-12)
    # (H, W) inputs keep their shape
    got_2d = nl_means_filter(values[..., 0], guide[..., 0], variance[..., 0], radius=radius,
                             patch_radius=patch_radius, k=k)
    expected_2d = nl_means_filter_reference(values[..., 0], guide[..., 0], variance[..., 0], radius=radius,
                                            patch_radius=patch_radius, k=k)
    assert got_2d.shape == (h, w)
    np.testing.assert_allclose(got_2d, expected_2d, rtol=1e-6, atol=1e-12)


def test_shape_errors_name_the_arrays():
    with pytest.raises(ValueError, match="guide .* and guide_variance"):
        nl_means_filter(np.zeros((4, 4)), np.zeros((4, 4, 3)), np.zeros((4, 4, 2)))
    with pytest.raises(ValueError, match="values .* and guide"):
        nl_means_filter(np.zeros((4, 5)), np.zeros((4, 4)), np.zeros((4, 4)))


def planes(array):
    return np.ascontiguousarray(np.moveaxis(array, 2, 0))


def test_window_weights_match_weight_maps():
    """The compiled pixel-major weights of every offset equal the NumPy weight maps, and a row
    block gives the rows of the whole image."""
    rng = np.random.default_rng(1)
    guide, variance = rng.random((10, 12, 3)), rng.random((10, 12, 3)) * 0.05
    weights = nlmeans.nl_means_window_weights(planes(guide), planes(variance), 0, 10, 3, 2, 0.7, 1.0, 1e-10, 1e4)
    for dy, dx, expected, _ in nlmeans.nl_means_weight_maps(guide, variance, 3, 2, 0.7):
        np.testing.assert_allclose(weights[..., (dy + 3) * 7 + dx + 3], expected, atol=1e-12)
    # a row block gives the same weights as the whole image
    np.testing.assert_array_equal(nlmeans.nl_means_window_weights(planes(guide), planes(variance), 3, 7, 3, 2, 0.7,
                                                                  1.0, 1e-10, 1e4), weights[3:7])
