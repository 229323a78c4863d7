"""Metrics against hand-computed values and closed forms."""

import numpy as np
import pytest

from mcbench.metrics import aces_filmic, dssim, relmse, smape, srgb_encode, tonemap


def test_relmse_hand_computed():
    reference = np.zeros((1, 2, 3))
    reference[0, 0] = 1.0  # first pixel r = 1, second r = 0
    image = reference.copy()
    image[0, 0, 0] = 2.0   # (2-1)^2 / (1 + 0.01)
    image[0, 1, 2] = 0.5   # 0.25 / (0 + 0.01) = 25
    expected = (1.0 / 1.01 + 25.0) / 6.0
    assert relmse(image, reference) == pytest.approx(expected, rel=1e-12)


def test_smape_hand_computed():
    reference = np.full((1, 1, 3), 1.0)
    image = np.array([[[1.0, 3.0, 0.0]]])
    # |0|/... = 0 ; |3-1|/(3+1+0.01) ; |0-1|/(0+1+0.01)
    expected = (0.0 + 2.0 / 4.01 + 1.0 / 1.01) / 3.0
    assert smape(image, reference) == pytest.approx(expected, rel=1e-12)


def test_errors_zero_for_identical_images_and_positive_otherwise():
    rng = np.random.default_rng(1)
    reference = rng.gamma(1.0, 1.0, size=(32, 32, 3))
    assert relmse(reference, reference) == 0.0
    assert smape(reference, reference) == 0.0
    assert dssim(reference, reference) == pytest.approx(0.0, abs=1e-12)
    noisy = reference + rng.normal(0, 0.3, size=reference.shape)
    assert relmse(noisy, reference) > 0 and smape(noisy, reference) > 0 and dssim(noisy, reference) > 0.01


def test_aces_narkowicz_values():
    # x = 1: (2.51 + 0.03) / (2.43 + 0.59 + 0.14) = 2.54 / 3.16
    assert aces_filmic(1.0) == pytest.approx(2.54 / 3.16, rel=1e-12)
    assert aces_filmic(0.0) == 0.0
    assert aces_filmic(-5.0) == 0.0
    assert aces_filmic(1e6) == 1.0  # clamped (limit 2.51/2.43 > 1)
    x = np.linspace(0, 20, 200)
    assert np.all(np.diff(aces_filmic(x)) >= 0)


def test_srgb_encoding_values():
    assert srgb_encode(0.0) == 0.0
    assert srgb_encode(1.0) == pytest.approx(1.0)
    assert srgb_encode(0.002) == pytest.approx(12.92 * 0.002)
    assert srgb_encode(0.5) == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055)


def ssim_by_hand(x, y, *, sigma=1.5, radius=5, k1=0.01, k2=0.03, data_range=1.0):
    """SSIM of Wang et al. 2004 written out: at every pixel whose 11 x 11 window lies inside the
    image, Gaussian-weighted (sigma 1.5, normalised window) means, population variances and
    covariance of each channel, then mean over those pixels and the channels. x, y: (H, W, C)."""
    offsets = np.arange(-radius, radius + 1)
    window = np.exp(-(offsets[:, None] ** 2 + offsets[None, :] ** 2) / (2 * sigma ** 2))
    window /= window.sum()
    c1, c2 = (k1 * data_range) ** 2, (k2 * data_range) ** 2
    h, w, channels = x.shape
    values = []
    for py in range(radius, h - radius):
        for px in range(radius, w - radius):
            for c in range(channels):
                xs = x[py - radius:py + radius + 1, px - radius:px + radius + 1, c]
                ys = y[py - radius:py + radius + 1, px - radius:px + radius + 1, c]
                mx, my = np.sum(window * xs), np.sum(window * ys)
                vx = np.sum(window * (xs - mx) ** 2)
                vy = np.sum(window * (ys - my) ** 2)
                cxy = np.sum(window * (xs - mx) * (ys - my))
                values.append((2 * mx * my + c1) * (2 * cxy + c2)
                              / ((mx * mx + my * my + c1) * (vx + vy + c2)))
    return float(np.mean(values))


def test_dssim_equals_hand_computed_ssim_on_tonemapped_images():
    """DSSIM = 1 - SSIM (Wang et al. 2004: 11 x 11 Gaussian window, sigma 1.5, population
    covariances, K1 = 0.01, K2 = 0.03, data range 1) of the ACES + sRGB tone-mapped images."""
    rng = np.random.default_rng(2)
    reference = rng.gamma(2.0, 0.5, size=(17, 19, 3))
    image = reference * rng.uniform(0.5, 1.5, size=reference.shape)
    expected = 1.0 - ssim_by_hand(tonemap(image), tonemap(reference))
    assert dssim(image, reference) == pytest.approx(expected, rel=1e-9, abs=1e-12)
    # the reference computation is sensitive to the settings it pins down
    assert abs(1.0 - ssim_by_hand(tonemap(image), tonemap(reference), sigma=2.0) - expected) > 1e-3
    assert abs(1.0 - ssim_by_hand(tonemap(image), tonemap(reference), k2=0.05) - expected) > 1e-3
    # and DSSIM compares tone-mapped, not linear, images
    assert abs(1.0 - ssim_by_hand(image, reference) - expected) > 1e-3


def test_dssim_of_constant_images_is_the_ssim_luminance_term():
    """Constant images: variances and covariance vanish, so SSIM is the luminance term
    (2 mu_x mu_y + C1) / (mu_x^2 + mu_y^2 + C1) of the tone-mapped values, per channel."""
    level_image = np.array([0.2, 1.0, 4.0])
    level_reference = np.array([0.5, 1.0, 0.1])
    image = np.broadcast_to(level_image, (16, 16, 3))
    reference = np.broadcast_to(level_reference, (16, 16, 3))
    mx, my = tonemap(level_image), tonemap(level_reference)
    c1 = 0.01 ** 2
    expected = 1.0 - np.mean((2 * mx * my + c1) / (mx ** 2 + my ** 2 + c1))
    assert expected > 0.05
    assert dssim(image, reference) == pytest.approx(expected, rel=1e-9)
    assert dssim(reference, reference) == pytest.approx(0.0, abs=1e-12)


def test_shape_mismatch_is_refused():
    with pytest.raises(ValueError, match="shape"):
        relmse(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))
