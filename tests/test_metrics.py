"""Metrics against hand-computed values and closed forms."""

import numpy as np
import pytest
from skimage.metrics import structural_similarity

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


def test_dssim_is_one_minus_skimage_ssim_on_tonemapped_images():
    rng = np.random.default_rng(2)
    reference = rng.gamma(2.0, 0.5, size=(40, 48, 3))
    image = reference * rng.uniform(0.5, 1.5, size=reference.shape)
    expected = 1.0 - structural_similarity(tonemap(image), tonemap(reference), channel_axis=2,
                                           data_range=1.0, gaussian_weights=True, sigma=1.5,
                                           use_sample_covariance=False)
    assert dssim(image, reference) == pytest.approx(expected, rel=1e-12)


def test_shape_mismatch_is_refused():
    with pytest.raises(ValueError, match="shape"):
        relmse(np.zeros((4, 4, 3)), np.zeros((4, 5, 3)))
