"""NL-means (Rousselle et al. 2012) against a brute-force per-pixel loop."""

import numpy as np

from mcbench.nlmeans import nl_means_filter


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
