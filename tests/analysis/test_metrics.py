"""Metrics against hand-computed values and closed forms."""

import numpy as np
import pytest

from mcbench.analysis.metrics import (FLIP_MIN_LUMINANCE, aces_filmic, dssim, flip, flip_exposure_range, flip_map,
                             relmse, relmse_map, smape, srgb_encode, tonemap)


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


def test_relmse_map_hand_computed_and_its_mean_is_relmse():
    reference = np.zeros((1, 2, 3))
    reference[0, 0] = 1.0
    image = reference.copy()
    image[0, 0, 0] = 2.0   # pixel 0: (1 / 1.01 + 0 + 0) / 3
    image[0, 1, 2] = 0.5   # pixel 1: (0 + 0 + 25) / 3
    expected = np.array([[1.0 / 1.01 / 3.0, 25.0 / 3.0]])
    values = relmse_map(image, reference)
    assert values.shape == (1, 2) and values.dtype == np.float64
    np.testing.assert_allclose(values, expected, rtol=1e-12)
    rng = np.random.default_rng(4)
    reference = rng.gamma(1.0, 1.0, size=(9, 7, 3))
    image = reference + rng.normal(0, 0.2, size=reference.shape)
    assert np.mean(relmse_map(image, reference)) == pytest.approx(relmse(image, reference), rel=1e-12)


def flip_pair(seed=5, shape=(24, 20, 3), noise=0.2):
    """A non-degenerate HDR pair: gamma-distributed radiance (median ~0.7, a long bright tail)
    and the same image with additive Gaussian noise clamped at 0."""
    rng = np.random.default_rng(seed)
    reference = rng.gamma(1.0, 1.0, size=shape)
    image = np.maximum(reference + rng.normal(0, noise, size=shape), 0.0)
    return image, reference


def test_flip_is_zero_for_identical_images_and_grows_with_the_perturbation():
    _, reference = flip_pair()
    assert flip(reference, reference) == 0.0
    assert np.all(flip_map(reference, reference) == 0.0)
    values = [flip(flip_pair(noise=noise)[0], reference) for noise in (0.02, 0.1, 0.3, 1.0)]
    assert all(a < b for a, b in zip(values, values[1:])), values
    # HDR-FLIP's exposure range follows the reference: scaling both images by 2^k changes nothing
    image, reference = flip_pair()
    assert flip(8.0 * image, 8.0 * reference) == pytest.approx(flip(image, reference), rel=1e-4)


def test_flip_exposure_range_is_the_packages_own():
    """Our c_start, c_stop (Andersson et al. 2021 Sec. 4, used for black references) equal
    the range the package computes from a reference, on odd and even pixel counts."""
    import flip_evaluator

    for shape in [(7, 9, 3), (8, 8, 3), (5, 40, 3)]:
        image, reference = flip_pair(shape=shape)
        _, _, used = flip_evaluator.evaluate(reference, image, "HDR", applyMagma=False)
        start, stop = flip_exposure_range(reference)
        assert start == pytest.approx(used["startExposure"], abs=1e-5)
        assert stop == pytest.approx(used["stopExposure"], abs=1e-5)
    # more than half the pixels black: the median is floored at float32's epsilon (2^-23)
    reference = np.zeros((4, 4, 3))
    reference[0] = 1.0
    start, stop = flip_exposure_range(reference)
    assert stop - start == pytest.approx(23.0, abs=1e-9)
    with pytest.raises(ValueError, match="luminance"):
        flip_exposure_range(np.zeros((4, 4, 3)))


def test_flip_degenerate_inputs_give_finite_values_in_this_process():
    """Inputs on which flip_evaluator's C++ core calls exit() (a black or near-black reference:
    "Start exposure must be smaller than stop exposure!") return a value here; if the process
    had exited, this test would not report at all."""
    import flip_evaluator

    black = np.zeros((16, 16, 3))
    assert flip(black, black) == 0.0
    assert flip(black + 0.1 * FLIP_MIN_LUMINANCE, black) == pytest.approx(flip(black, black + 0.1 * FLIP_MIN_LUMINANCE))
    image, _ = flip_pair(shape=(16, 16, 3))
    # black reference, non-black image: the exposure range comes from the image
    start, stop = flip_exposure_range(image)
    _, expected, _ = flip_evaluator.evaluate(black.astype(np.float32), image.astype(np.float32), "HDR",
                                             applyMagma=False, parameters={"startExposure": start,
                                                                           "stopExposure": stop})
    assert flip(image, black) == pytest.approx(expected, rel=5e-6)
    assert 0.5 < flip(image, black) <= 1.0
    # a dim reference (below FLIP_MIN_LUMINANCE, where the package's own range is reversed)
    assert np.isfinite(flip(image, black + 1e-30))
    # both nearly black but different: the range of a uniform FLIP_MIN_LUMINANCE image
    tiny = np.zeros((16, 16, 3))
    tiny[4:8, 4:8] = 0.5 * FLIP_MIN_LUMINANCE
    assert 0.0 < flip(tiny, black) <= 1.0
    np.testing.assert_array_equal(np.isfinite(flip_map(tiny, black)), True)
    # a single pixel, and negative radiance clamped to 0
    assert 0.0 < flip(np.full((1, 1, 3), 0.5), np.ones((1, 1, 3))) < 1.0
    negative = image.copy()
    negative[0, 0] = -3.0
    clamped = negative.copy()
    clamped[0, 0] = 0.0
    assert flip(negative, image) == flip(clamped, image)


def test_flip_refuses_what_it_cannot_compare():
    image, reference = flip_pair(shape=(8, 8, 3))
    bad = image.copy()
    bad[1, 1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or Inf"):
        flip(bad, reference)
    with pytest.raises(ValueError, match="NaN or Inf"):
        flip_map(image, np.where(bad > 0, np.inf, reference))
    # beyond float32's range (no EXR holds it) still finite: ACES saturates before x² overflows
    assert 0.0 < flip(image * 1e300, reference) <= 1.0
    with pytest.raises(ValueError, match="shape"):
        flip(image[:, :4], reference)
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        flip(image[..., :2], reference[..., :2])
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        flip(np.zeros((0, 4, 3)), np.zeros((0, 4, 3)))


def test_the_metric_plugins_point_to_these_functions():
    """Each metric's plugin (metrics/<name>.py) computes its value with this module's function."""
    from mcbench.analysis import metrics
    from mcbench.pipeline.registry import available_metrics, load_metric

    assert available_metrics() == ["dssim", "flip", "relmse", "relmse_corrected", "smape"]
    for name in available_metrics():
        assert load_metric(name).value is getattr(metrics, name)
    assert load_metric("flip").value_and_map is metrics.flip_with_map
    assert load_metric("relmse").error_map is metrics.relmse_map
    assert load_metric("relmse_corrected").reads_reference_variance


def test_relmse_corrected_is_unbiased_where_the_raw_one_is_not():
    """Synthetic truth μ, a fixed image y, references r = μ + e with known per-pixel variance v:
    over many reference draws the corrected relMSE averages to the true relMSE (y vs μ), while
    the raw relMSE is off by about the reference's noise floor mean(v / (μ² + 0.01))."""
    from mcbench.analysis.metrics import relmse_corrected

    rng = np.random.default_rng(7)
    mu = rng.uniform(0.2, 3.0, size=(16, 16, 3))
    y = mu * (1.0 + rng.normal(0.0, 0.05, size=mu.shape))          # a candidate with a small error
    v = (0.04 * mu) ** 2                                             # the reference's variance of the mean
    truth = relmse(y, mu)
    floor = float(np.mean(v / (mu * mu + 0.01)))
    raw, corrected = [], []
    for _ in range(400):
        r = mu + rng.normal(0.0, 1.0, size=mu.shape) * np.sqrt(v)
        raw.append(relmse(y, r))
        corrected.append(relmse_corrected(y, r, v))
    raw_bias, corrected_bias = np.mean(raw) - truth, np.mean(corrected) - truth
    assert raw_bias == pytest.approx(floor, rel=0.15)                 # the raw metric sees the noise
    assert abs(corrected_bias) < 0.05 * raw_bias                       # the corrected one does not
    # what remains is the ratio's second-order term, about 4 relMSE(y, μ) v / μ² per pixel
    residual = float(np.mean(4.0 * relmse(y, mu) * v / (mu * mu + 0.01)))
    assert abs(corrected_bias) < 3.0 * residual + 4.0 * np.std(corrected) / np.sqrt(400)


def test_relmse_corrected_reduces_to_relmse_for_a_noiseless_reference_and_checks_its_input():
    from mcbench.analysis.metrics import relmse_corrected, relmse_corrected_map

    rng = np.random.default_rng(3)
    r = rng.uniform(0.0, 2.0, size=(8, 8, 3))
    y = r + rng.normal(0.0, 0.1, size=r.shape)
    assert relmse_corrected(y, r, np.zeros_like(r)) == pytest.approx(relmse(y, r), rel=1e-12)
    # an image equal to the reference, whose noise is v: each term is -v / (r² - v + 0.01)
    v = np.full_like(r, 1e-3)
    expected = np.mean(-v / (np.maximum(r * r - v, 0.0) + 0.01), axis=-1)
    np.testing.assert_allclose(relmse_corrected_map(r, r, v), expected, rtol=1e-12)
    with pytest.raises(ValueError, match="variance shape"):
        relmse_corrected(y, r, v[:4])
    with pytest.raises(ValueError, match="NaN or Inf"):
        relmse_corrected(y, r, np.full_like(r, np.nan))
