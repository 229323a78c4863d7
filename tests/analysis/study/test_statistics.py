"""mcbench.analysis.study.statistics: the scene bootstrap against a normal sample of known sd and
the binomial probability of a place; the verdict rule both ways."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from mcbench.analysis.study.data import Resampling
from mcbench.analysis.study.statistics import (INCONCLUSIVE, NOT_REPRODUCED, REPRODUCED, bootstrap_ci, ci_verdict,
                                               is_real, place_fractions, resample_indices)
from tests.analysis.study.synthetic import FAST


def test_bootstrap_interval_width_and_coverage_match_the_normal_theory():
    rng = np.random.default_rng(123)
    n, sd, mu, repeats = 40, 2.0, 5.0, 300
    samples = rng.normal(mu, sd, size=(n, repeats))   # 300 independent data sets of 40 "scenes"
    found = bootstrap_ci(samples, resampling=Resampling(n_resamples=1000, seed=3))
    assert (found["ci_method"] == "BCa").all()
    width = (found["ci_high"] - found["ci_low"]).mean()
    assert width == pytest.approx(2 * 1.96 * sd / math.sqrt(n), rel=0.1)
    coverage = ((found["ci_low"] < mu) & (mu < found["ci_high"])).mean()
    assert 0.89 <= coverage <= 0.99


def test_bootstrap_is_reproducible_and_degenerate_data_falls_back_or_gives_no_interval():
    x = np.random.default_rng(0).normal(size=(8, 2))
    first = bootstrap_ci(x, resampling=FAST)
    assert first.equals(bootstrap_ci(x, resampling=FAST))
    other = bootstrap_ci(x, resampling=Resampling(n_resamples=400, seed=8))
    assert not first["ci_low"].equals(other["ci_low"])
    constant = bootstrap_ci(np.full((8, 1), 40.0), resampling=FAST).iloc[0]
    assert constant["ci_method"] == "percentile (BCa degenerate)"
    assert constant["ci_low"] == constant["ci_high"] == 40.0
    single = bootstrap_ci(np.ones((1, 1)), resampling=FAST).iloc[0]
    assert pd.isna(single["ci_low"]) and pd.isna(single["ci_high"]) and single["ci_method"].startswith("none")
    assert is_real(0.1, 2.0) and is_real(-3.0, -0.5)
    assert is_real(-0.1, 2.0) is False and is_real(None, 1.0) is None


def test_place_fractions_match_the_binomial_probability():
    # 4 scenes; in 3, column 0 is 1 above column 1, in the 4th 1 below; column 2 always last.
    # Column 0 is top when the reversed scene is drawn 0 or 1 times of 4 (p = 1/4), tied at 2.
    per_scene = np.array([[2.0, 1.0, 0.0]] * 3 + [[1.0, 2.0, 0.0]])
    indices = resample_indices(4, resampling=Resampling(n_resamples=20000, seed=5))
    top = place_fractions(per_scene, indices, place=1)
    p = 0.75 ** 4 + 4 * 0.25 * 0.75 ** 3 + 0.5 * 6 * 0.25 ** 2 * 0.75 ** 2
    assert top[0] == pytest.approx(p, abs=0.015)
    assert top[1] == pytest.approx(1 - p, abs=0.015) and top[2] == 0.0
    second = place_fractions(per_scene, indices, place=2)
    assert second.sum() == pytest.approx(1.0) and second[1] == pytest.approx(p, abs=0.015)


def test_ci_verdict_rule_both_ways():
    assert ci_verdict(0.5, 2.0) == REPRODUCED
    assert ci_verdict(-2.0, -0.5) == NOT_REPRODUCED
    assert ci_verdict(-0.5, 2.0) == INCONCLUSIVE
    assert ci_verdict(None, 2.0) == INCONCLUSIVE
    assert ci_verdict(0.02, 0.08, claim="below", threshold=0.1) == REPRODUCED
    assert ci_verdict(0.12, 0.3, claim="below", threshold=0.1) == NOT_REPRODUCED
