"""The reference-agreement test (mcbench.analysis.reference_check) on synthetic renders whose
statistics are known: a true image T, a "local render" of N samples per pixel and a "reference"
of many more, each with the variance of its mean estimated from its own samples.

Measured false-alarm rates (alpha = 1e-4, 64 x 64 images, 16-pixel blocks; this file's
``test_the_false_alarm_rate_*``): Gaussian samples 0 of 200 renders; log-normal samples
(sigma 1, a heavy tail) 0 of 100; rare bright paths that most pixels miss (a caustic: 30 % of
the mean from events of probability 1e-5 per sample, shared by the three channels) 0 of 40 with
the reference's per-sample variance as the render's floor, 47 of 50 without it. A reference
biased by 2 % in one channel over a 16 x 16 region (aligned with the blocks or not) or rendered
from a scene 1 % brighter is refused every time.
"""

from __future__ import annotations

import numpy as np
import pytest

from mcbench.analysis.reference_check import reference_agreement

SIZE = 64


def true_image(size: int = SIZE) -> np.ndarray:
    """A smooth positive (H, W, 3) image: gradients and a sine pattern, no channel alike."""
    y, x = np.mgrid[0:size, 0:size] / size
    return np.stack([0.3 + 0.5 * x, 0.2 + 0.4 * y, 0.25 + 0.2 * np.sin(6.0 * x + 3.0 * y) ** 2], axis=-1)


def gaussian_estimate(truth: np.ndarray, samples: int, rng, *, relative_std: float = 1.0):
    """(mean, variance of the mean) of ``samples`` Gaussian samples per pixel and channel with
    mean ``truth`` and standard deviation ``relative_std * truth`` (the sample variance drawn
    from its chi-square law, as a renderer's moment estimate is)."""
    sigma2 = (relative_std * truth) ** 2
    mean = truth + rng.standard_normal(truth.shape) * np.sqrt(sigma2 / samples)
    sample_variance = sigma2 * rng.chisquare(samples - 1, truth.shape) / (samples - 1)
    return mean, sample_variance / samples


def lognormal_estimate(truth: np.ndarray, samples: int, rng, *, sigma: float = 1.0):
    """(mean, variance of the mean) of ``samples`` log-normal samples per pixel and channel
    with mean ``truth`` (heavy-tailed: occasional fireflies, often missed at low counts)."""
    draws = rng.lognormal(-0.5 * sigma * sigma, sigma, size=(samples, *truth.shape)).astype(np.float32)
    draws *= truth.astype(np.float32)
    mean = draws.mean(axis=0, dtype=np.float64)
    variance = draws.var(axis=0, ddof=1, dtype=np.float64) / samples
    return mean, variance


def rare_path_estimate(truth: np.ndarray, samples: int, rng, *, probability: float = 1e-5, share: float = 0.3):
    """(mean, variance of the mean) of ``samples`` samples per pixel of a caustic-like law with
    mean ``truth``: (1 - share) of it from Gaussian samples (relative standard deviation 1),
    ``share`` from rare paths of ``probability`` per sample and value ``share / probability``. One
    draw per pixel serves all three channels (the same paths carry every channel). At 1024
    samples a 16 x 16 block expects 2.6 rare paths and misses all in 7 % of blocks: its mean is
    then 30 % low and its own sample variance knows nothing of the paths it missed."""
    shape = (samples, *truth.shape[:2], 1)
    draws = (1.0 - share) * (1.0 + rng.standard_normal(shape, dtype=np.float32))
    draws += np.float32(share / probability) * (rng.random(shape, dtype=np.float32) < probability)
    mean = draws.mean(axis=0, dtype=np.float64) * truth
    variance = draws.var(axis=0, ddof=1, dtype=np.float64) * truth * truth / samples
    return mean, variance


def rare_path_variance(truth: np.ndarray, *, probability: float = 1e-5, share: float = 0.3) -> np.ndarray:
    """The per-sample variance of :func:`rare_path_estimate`'s law, in closed form."""
    return ((1.0 - share) ** 2 + share * share * (1.0 - probability) / probability) * truth * truth


def agreement(reference, render, *, spp=(65536, 1024), **kwargs):
    """The test with the sample counts behind the (reference, render) pair; ``spp=None``: without."""
    counts = {} if spp is None else {"reference_spp": spp[0], "render_spp": spp[1]}
    return reference_agreement(reference[0], reference[1], render[0], render[1], **counts, **kwargs)


def test_a_reference_of_the_same_scene_passes_and_the_false_alarm_rate_is_at_most_alpha():
    """Calibration: at alpha = 0.05 each statistic rejects about 5 % of agreeing pairs (Bonferroni
    makes the local one conservative); at alpha = 1e-4 none of 200."""
    truth = true_image()
    local_rejections = global_rejections = strict = 0
    trials = 200
    for seed in range(trials):
        rng = np.random.default_rng(seed)
        reference, render = gaussian_estimate(truth, 65536, rng), gaussian_estimate(truth, 1024, rng)
        loose = agreement(reference, render, alpha=0.05)
        local_rejections += loose.max_z > loose.local_threshold
        global_rejections += loose.global_statistic > loose.global_threshold
        strict += not agreement(reference, render).passed
    assert local_rejections <= 0.05 * trials * 1.6
    assert 0.05 * trials * 0.4 <= global_rejections <= 0.05 * trials * 1.6
    assert strict == 0


def test_the_false_alarm_rate_on_heavy_tailed_samples():
    truth = true_image()
    false_alarms = 0
    for seed in range(100):
        rng = np.random.default_rng(1000 + seed)
        reference = gaussian_estimate(truth, 65536, rng, relative_std=np.sqrt(np.e - 1.0))
        render = lognormal_estimate(truth, 256, rng)
        false_alarms += not agreement(reference, render, spp=(65536, 256)).passed
    assert false_alarms == 0


def test_rare_bright_paths_pass_with_the_reference_variance_as_floor_and_fail_without():
    """The render's own variance misses the paths its pixels missed (module docstring, Eq. 1): the
    reference's per-sample variance (from 64 times more samples; here its closed form) is the
    floor that keeps a correct reference from being refused."""
    truth = true_image()
    with_floor = without_floor = 0
    trials = 40
    for seed in range(trials):
        rng = np.random.default_rng(2000 + seed)
        reference_variance = rare_path_variance(truth) / 65536
        reference = (truth + rng.standard_normal(truth.shape) * np.sqrt(reference_variance), reference_variance)
        render = rare_path_estimate(truth, 1024, rng)
        with_floor += not agreement(reference, render).passed
        without_floor += not agreement(reference, render, spp=None).passed
    assert with_floor == 0
    assert without_floor >= 0.8 * trials


def test_the_global_statistic_stays_calibrated_when_the_channels_move_together():
    """The same samples drive all three channels (as a renderer's paths do): a chi-square over
    all channels at once would count each block three times and reject about 15 % at alpha = 0.05;
    one per channel with Bonferroni over the three rejects at most alpha."""
    truth = true_image()
    rejections = 0
    trials = 200
    for seed in range(trials):
        rng = np.random.default_rng(3000 + seed)
        reference = gaussian_estimate(truth, 65536, rng)
        shared = rng.standard_normal((*truth.shape[:2], 1))
        render = (truth + shared * truth / 32.0, truth * truth / 1024.0)
        loose = agreement(reference, render, alpha=0.05)
        rejections += loose.global_statistic > loose.global_threshold
    assert rejections <= 0.05 * trials * 1.6


@pytest.mark.parametrize("corner", [(16, 32), (20, 36)])
def test_a_reference_biased_by_two_percent_in_one_channel_over_a_block_is_refused(corner):
    truth = true_image()
    for seed in range(20):
        rng = np.random.default_rng(seed)
        reference, render = gaussian_estimate(truth, 65536, rng), gaussian_estimate(truth, 1024, rng)
        biased = reference[0].copy()
        r, c = corner
        biased[r:r + 16, c:c + 16, 1] *= 1.02
        result = agreement((biased, reference[1]), render)
        assert not result.passed, result.describe()
        assert result.channel == 1 and abs(result.block_row - r) <= 8 and abs(result.block_column - c) <= 8


def test_a_reference_of_a_slightly_different_scene_is_refused():
    truth = true_image()
    for seed in range(20):
        rng = np.random.default_rng(seed)
        other = gaussian_estimate(truth * 1.01, 65536, rng)
        result = agreement(other, gaussian_estimate(truth, 1024, rng))
        assert not result.passed and result.global_statistic > result.global_threshold, result.describe()


def test_sample_counts_must_come_in_pairs_of_positive_integers():
    truth = true_image()
    rng = np.random.default_rng(0)
    reference, render = gaussian_estimate(truth, 65536, rng), gaussian_estimate(truth, 1024, rng)
    for spp in [(65536, 0), (65536, 1024.0), (True, 1024)]:
        with pytest.raises(ValueError, match="positive integers"):
            agreement(reference, render, spp=spp)
    with pytest.raises(ValueError, match="positive integers"):
        reference_agreement(*reference, *render, reference_spp=65536)


def test_a_wrong_variance_scale_breaks_the_calibration():
    """The test can fail: the variance of a block mean without its 1/n (here emulated by
    variances n = 256 times too small) rejects agreeing pairs."""
    truth = true_image()
    rng = np.random.default_rng(0)
    reference, render = gaussian_estimate(truth, 65536, rng), gaussian_estimate(truth, 1024, rng)
    assert agreement(reference, render).passed
    assert not agreement((reference[0], reference[1] / 256), (render[0], render[1] / 256)).passed


def test_blocks_without_variance_compare_exactly_and_bad_inputs_are_refused():
    background = np.full((32, 32, 3), 0.5)
    zero = np.zeros_like(background)
    assert agreement((background, zero), (background, zero)).passed
    assert not agreement((background, zero), (background * 1.01, zero)).passed
    assert agreement((background, zero), (background * (1 + 1e-6), zero)).passed      # within the floor
    with pytest.raises(ValueError, match="one shape"):
        reference_agreement(background, zero, background[:16], zero[:16])
    with pytest.raises(ValueError, match="NaN"):
        reference_agreement(background, zero, np.full_like(background, np.nan), zero)
    with pytest.raises(ValueError, match="smaller than one block"):
        reference_agreement(background[:8], zero[:8], background[:8], zero[:8])
