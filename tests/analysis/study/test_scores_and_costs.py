"""mcbench.analysis.study.scores_and_costs against independent truth: brute-force Pareto fronts,
hand-computed means, a toy DAG of inputs."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from mcbench.analysis.error_speed_figures import input_closure
from mcbench.analysis.ranking import case_scores
from mcbench.analysis.study.scores_and_costs import (average_scores, closure_seconds, own_seconds, pareto_front,
                                                     score_curves, score_size_points, score_size_summary,
                                                     speed_score_points)
from tests.analysis.study.synthetic_timings import SCENES, SPPS, METHODS, INPUTS, OWN, synthetic_study


# ----------------------------------------------------------------------------- Pareto


def brute_force_front(cost, score) -> np.ndarray:
    n = len(cost)
    return np.array([not any(cost[j] <= cost[i] and score[j] >= score[i] and (cost[j] < cost[i] or score[j] > score[i])
                             for j in range(n)) for i in range(n)])


@pytest.mark.parametrize("seed", range(6))
def test_pareto_front_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    cost = rng.integers(1, 8, size=40).astype(float)  # small integers: many ties in cost and score
    score = rng.integers(1, 8, size=40).astype(float)
    assert np.array_equal(pareto_front(cost, score), brute_force_front(cost, score))


def test_pareto_front_of_a_constructed_set():
    # (cost, score): a staircase of three, a dominated point, a duplicate of a front point
    cost = [1.0, 2.0, 4.0, 3.0, 2.0, 5.0]
    score = [10.0, 20.0, 30.0, 15.0, 20.0, 30.0]
    assert pareto_front(cost, score).tolist() == [True, True, True, False, True, False]


# ----------------------------------------------------------------------------- costs


def test_closure_counts_a_shared_base_once():
    # ens over kpcn and kpcn_dc: kpcn is an input of both, run once
    inputs = {"kpcn_dc": ["kpcn"], "ens": ["kpcn", "kpcn_dc", "nfor"], "meta": ["ens", "kpcn"]}
    own = {"kpcn": 2.0, "kpcn_dc": 1.0, "nfor": 3.0, "ens": 0.5, "meta": 0.25}
    assert sorted(input_closure("ens", inputs)) == ["ens", "kpcn", "kpcn_dc", "nfor"]
    totals = closure_seconds(own, inputs)
    assert totals == {"kpcn": 2.0, "kpcn_dc": 3.0, "nfor": 3.0, "ens": 6.5, "meta": 6.75}
    with pytest.raises(ValueError, match="no timing for method.*nfor"):
        closure_seconds({"ens": 1.0, "kpcn": 1.0, "kpcn_dc": 1.0}, inputs, names=["ens"])
    with pytest.raises(ValueError, match="takes itself"):
        input_closure("a", {"a": ["b"], "b": ["a"]})


def test_own_seconds_mean_of_case_means():
    timings = pd.DataFrame({"scene": ["a", "a", "a"], "spp": [4, 4, 8], "method": ["m"] * 3,
                            "seconds": [1.0, 3.0, 6.0]})
    assert own_seconds(timings) == {"m": pytest.approx((2.0 + 6.0) / 2)}


def test_speed_score_points():
    metrics, timings = synthetic_study()
    scores = case_scores(metrics, "relmse")
    points = speed_score_points(scores, timings, inputs=INPUTS)
    assert "noisy" not in points.index and set(points.index) == set(METHODS)
    totals = {"kpcn": 2.0, "nfor": 3.0, "rdfc": 0.5, "kpcn_dc": 3.0, "ens10": 5.25, "ens18": 5.625}
    for name, total in totals.items():
        assert points.loc[name, "total_seconds"] == pytest.approx(total)
        assert points.loc[name, "seconds"] == pytest.approx(OWN[name])
    assert points["size"].to_dict() == {"kpcn": 1, "nfor": 1, "rdfc": 1, "kpcn_dc": 1, "ens10": 2, "ens18": 3}
    expected = brute_force_front(points["total_seconds"].to_numpy(), points["score"].to_numpy())
    assert np.array_equal(points["pareto"].to_numpy(), expected)
    assert np.isfinite(points.drop(columns="pareto").to_numpy(np.float64)).all()


# ----------------------------------------------------------------------------- scores


def test_score_curves_and_averages_are_hand_computed_means():
    metrics, _ = synthetic_study()
    scores = case_scores(metrics, "relmse")
    curves = score_curves(scores, candidates=["kpcn", "ens18"])
    assert list(curves.columns) == ["kpcn", "ens18"] and list(curves.index) == SPPS
    for spp, name in itertools.product(SPPS, ["kpcn", "ens18"]):
        by_hand = sum(scores[(scores.scene == scene) & (scores.spp == spp) & (scores.entry == name)]["score"].item()
                      for scene in SCENES) / len(SCENES)
        assert curves.loc[spp, name] == pytest.approx(by_hand)
    averages = average_scores(scores)
    for name in ["noisy"] + METHODS:
        rows = scores[scores.entry == name]
        by_hand = np.mean([rows[rows.spp == spp]["score"].mean() for spp in SPPS])
        assert averages[name] == pytest.approx(by_hand)
    assert list(averages) == sorted(averages, reverse=True)
    # the noisy input is above every method's error here: scored 1 in every case
    assert averages["noisy"] == 1.0


def test_score_size_points_and_summary():
    metrics, _ = synthetic_study()
    scores = case_scores(metrics, "dssim")
    points = score_size_points(scores)
    assert "noisy" not in points.index
    averages = average_scores(scores)
    summary = score_size_summary(points)
    assert list(summary.index) == [1, 2, 3] and list(summary["n"]) == [4, 1, 1]
    bases = [averages[n] for n in ["kpcn", "nfor", "rdfc", "kpcn_dc"]]
    assert summary.loc[1, "mean"] == pytest.approx(np.mean(bases))
    assert summary.loc[1, "std"] == pytest.approx(np.std(bases, ddof=1))
    assert summary.loc[2, "std"] == 0.0 and summary.loc[3, "mean"] == pytest.approx(averages["ens18"])
    assert np.isfinite(summary.to_numpy(np.float64)).all()
    # sizes given explicitly win over the pool's
    assert score_size_points(scores, sizes={"ens18": 7}).loc["ens18", "size"] == 7
