"""mcbench.analysis.study_figures: the 39-candidate study's figures, checked against independent truth
(brute-force Pareto fronts, closed-form equal-time power laws, hand-computed means, a toy DAG)
and the PNGs they write for a tiny synthetic study."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from mcbench.io.exr import write_layers
from mcbench.analysis.ranking import case_scores
from mcbench.analysis.study_figures import (STUDY_FIGURES, average_scores, closure_seconds, equal_time_curves,
                                   equal_time_table, input_closure, loglog_interp, own_seconds, pareto_front,
                                   read_render_seconds, score_curves, score_size_points, score_size_summary,
                                   speed_score_points, study_figure_paths, write_study_figures)

SCENES = ["box", "glass_room"]
SPPS = [4, 8, 16, 32]
# pool names: bases #1 KPCN, #4 NFOR, #8 RDFC, #5 KPCN-DC (takes kpcn); ensembles #10 {1,4}, #18 {1,4,8}
METHODS = ["kpcn", "nfor", "rdfc", "kpcn_dc", "ens10", "ens18"]
INPUTS = {"kpcn_dc": ["kpcn"], "ens10": ["kpcn", "nfor"], "ens18": ["kpcn", "nfor", "rdfc"]}
OWN = {"kpcn": 2.0, "nfor": 3.0, "rdfc": 0.5, "kpcn_dc": 1.0, "ens10": 0.25, "ens18": 0.125}
RENDER_SECONDS_PER_SPP = 0.05
NOISY_CONSTANT = 0.8  # noisy relmse = NOISY_CONSTANT / spp


def synthetic_study(seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Metrics (relmse, dssim) and timings of a tiny study: the noisy relmse is an exact power
    law, the methods' errors random below it; each method's seconds are its OWN value in every
    case (timed twice, once 10 % faster and once 10 % slower)."""
    rng = np.random.default_rng(seed)
    rows = []
    for scene, spp in itertools.product(SCENES, SPPS):
        for metric in ("relmse", "dssim"):
            rows.append({"scene": scene, "spp": spp, "candidate": "noisy", "metric": metric,
                         "value": NOISY_CONSTANT / spp})
            for name in METHODS:
                rows.append({"scene": scene, "spp": spp, "candidate": name, "metric": metric,
                             "value": float(rng.uniform(0.05, 0.9)) * NOISY_CONSTANT / spp})
    metrics = pd.DataFrame(rows).sample(frac=1.0, random_state=seed)  # row order must not matter
    timings = pd.DataFrame([{"scene": scene, "spp": spp, "method": name, "seconds": OWN[name] * factor}
                            for scene, spp, name, factor in itertools.product(SCENES, SPPS, METHODS, (0.9, 1.1))])
    return metrics, timings


def render_times(scale: float = RENDER_SECONDS_PER_SPP) -> pd.DataFrame:
    return pd.DataFrame([{"scene": scene, "spp": spp, "seconds": scale * spp, "source": "exr"}
                         for scene, spp in itertools.product(SCENES, SPPS)])


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
        by_hand = sum(scores[(scores.scene == scene) & (scores.spp == spp) & (scores.candidate == name)]["score"].item()
                      for scene in SCENES) / len(SCENES)
        assert curves.loc[spp, name] == pytest.approx(by_hand)
    averages = average_scores(scores)
    for name in ["noisy"] + METHODS:
        rows = scores[scores.candidate == name]
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


# ----------------------------------------------------------------------------- equal time


def test_loglog_interp_is_exact_on_power_laws_inside_and_beyond():
    xp = np.array([4.0, 8.0, 16.0, 32.0])
    values, beyond = loglog_interp([4.0, 6.0, 20.0, 100.0, 2.0], xp, 3.0 * xp ** -1.5)
    assert np.allclose(values, 3.0 * np.array([4.0, 6.0, 20.0, 100.0, 2.0]) ** -1.5)
    assert beyond.tolist() == [False, False, False, True, True]
    single, _ = loglog_interp(20.0, [10.0], [5.0])  # one point: proportional
    assert single[0] == pytest.approx(10.0)


def test_equal_time_on_synthetic_power_laws():
    """time = a spp, noisy error = c / spp: a candidate costing m seconds at spp has the equal-time
    spp spp + m / a and the noisy error there c / (spp + m / a), in range or beyond it."""
    metrics, timings = synthetic_study()
    table = equal_time_table(metrics, timings, render_times(), metric="relmse", inputs=INPUTS)
    assert len(table) == len(SCENES) * len(SPPS) * len(METHODS)
    totals = {"kpcn": 2.0, "nfor": 3.0, "rdfc": 0.5, "kpcn_dc": 3.0, "ens10": 5.25, "ens18": 5.625}
    relmse = metrics[metrics.metric == "relmse"].set_index(["scene", "spp", "candidate"])["value"]
    for row in table.itertuples():
        cost = totals[row.candidate]
        equal_spp = row.spp + cost / RENDER_SECONDS_PER_SPP
        assert row.method_seconds == pytest.approx(cost)
        assert row.render_seconds == pytest.approx(RENDER_SECONDS_PER_SPP * row.spp)
        assert row.equal_spp == pytest.approx(equal_spp)
        assert row.noisy_error == pytest.approx(NOISY_CONSTANT / equal_spp)
        assert row.ratio == pytest.approx(relmse[(row.scene, row.spp, row.candidate)] * equal_spp / NOISY_CONSTANT)
        assert row.extrapolated == (equal_spp > max(SPPS))
    assert table["extrapolated"].any() and not table["extrapolated"].all()
    numeric = table.drop(columns=["scene", "candidate", "extrapolated"]).to_numpy(np.float64)
    assert np.isfinite(numeric).all()

    ratios, beyond = equal_time_curves(table, candidates=["kpcn", "ens18"])
    for spp, name in itertools.product(SPPS, ["kpcn", "ens18"]):
        per_scene = table[(table.spp == spp) & (table.candidate == name)]["ratio"]
        assert ratios.loc[spp, name] == pytest.approx(float(np.exp(np.log(per_scene).mean())))
    assert beyond.dtypes.eq(bool).all() and not ratios.isna().any().any()


def test_equal_time_ignores_a_render_time_that_falls():
    metrics, timings = synthetic_study()
    times = render_times()
    slow = (times.scene == "box") & (times.spp == 8)
    times.loc[slow, "seconds"] = 10.0  # timing noise: 8 spp slower than 16 and 32
    table = equal_time_table(metrics, timings, times, metric="relmse", inputs=INPUTS, candidates=["rdfc"])
    box = table[table.scene == "box"].set_index("spp")
    assert box.loc[16, "render_seconds"] == pytest.approx(10.0)  # raised to the running maximum
    assert (box["equal_spp"] >= box.index.to_numpy()).all()
    assert np.isfinite(table["ratio"]).all()


def test_equal_time_names_a_missing_render_time():
    metrics, timings = synthetic_study()
    times = render_times()
    times = times[~((times.scene == "glass_room") & (times.spp == 16))]
    with pytest.raises(ValueError, match="no render time for scene 'glass_room' at 16 spp"):
        equal_time_table(metrics, timings, times, metric="relmse", inputs=INPUTS)


def write_records(tmp_path) -> list[str]:
    """Render records of the synthetic study: benchmark TSVs for every case and, for box at 4
    spp, an EXR whose header time differs (the EXR's must win)."""
    paths = []
    for scene, spp in itertools.product(SCENES, SPPS):
        path = tmp_path / "benchmarks" / "render_noisy" / f"{scene}_spp{spp}.tsv"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("s\th:m:s\tmax_rss\tcpu_time\n"
                        f"{RENDER_SECONDS_PER_SPP * spp:.6f}\t0:00:00\t10.0\t{RENDER_SECONDS_PER_SPP * spp:.6f}\n")
        paths.append(str(path))
    exr = tmp_path / "renders" / "box" / "spp4.exr"
    exr.parent.mkdir(parents=True, exist_ok=True)
    write_layers(exr, {"color": np.ones((2, 2, 3), np.float32)}, metadata={"scene": "box", "spp": 4, "seconds": 0.1})
    return paths + [str(exr)]


def test_read_render_seconds_prefers_the_exr_header(tmp_path):
    frame = read_render_seconds(write_records(tmp_path))
    assert len(frame) == len(SCENES) * len(SPPS)
    box4 = frame[(frame.scene == "box") & (frame.spp == 4)].iloc[0]
    assert box4["seconds"] == pytest.approx(0.1) and box4["source"] == "exr"
    glass = frame[(frame.scene == "glass_room") & (frame.spp == 32)].iloc[0]
    assert glass["seconds"] == pytest.approx(RENDER_SECONDS_PER_SPP * 32) and glass["source"] == "benchmark"
    with pytest.raises(ValueError, match="neither a render"):
        read_render_seconds([str(tmp_path / "x.txt")])


# ----------------------------------------------------------------------------- figures


def test_write_study_figures_writes_every_png(tmp_path):
    metrics, timings = synthetic_study()
    metrics_csv, timings_csv = tmp_path / "metrics.csv", tmp_path / "timings.csv"
    metrics.to_csv(metrics_csv, index=False)
    timings.to_csv(timings_csv, index=False)
    paths = study_figure_paths(tmp_path / "figures" / "study", "relmse")
    assert list(paths) == list(STUDY_FIGURES)
    assert all(p.endswith(f"{key}_relmse.png") for key, p in paths.items())
    ci = pd.DataFrame({"candidate": METHODS, "ci_low": [1.0] * 6, "ci_high": [7.0] * 6})
    table = write_study_figures(str(metrics_csv), str(timings_csv), write_records(tmp_path), paths, metric="relmse",
                                candidates=METHODS, curves=["kpcn", "nfor", "rdfc", "ens10", "ens18"],
                                recommended=["ens18"], labels={"noisy": "Noisy", "kpcn": "KPCN"}, inputs=INPUTS,
                                ci=ci)
    for path in paths.values():
        with open(path, "rb") as handle:
            assert handle.read(8) == b"\x89PNG\r\n\x1a\n"
    assert len(table) == len(SCENES) * len(SPPS) * len(METHODS)
    assert np.isfinite(table.drop(columns=["scene", "candidate", "extrapolated"]).to_numpy(np.float64)).all()


def test_write_study_figures_refuses_an_unknown_figure(tmp_path):
    with pytest.raises(ValueError, match="unknown study figure"):
        write_study_figures("m.csv", "t.csv", [], {"pie": str(tmp_path / "pie.png")}, metric="relmse",
                            candidates=METHODS, curves=METHODS)


def test_paper_recommended_and_curve_candidates():
    from mcbench.analysis.study_figures import curve_candidates, paper_recommended

    assert paper_recommended() == ["ens27", "ens20", "ens10", "ens18"]
    assert curve_candidates(["ens20", "kpcn", "ens20"]) == ["kpcn", "nfor_dc", "mcgan", "nfor", "kpcn_dc", "oidn",
                                                           "optix_ae", "rdfc", "ens20"]


def test_equal_time_refuses_a_render_time_that_is_not_positive():
    metrics, timings = synthetic_study()
    times = render_times()
    times.loc[0, "seconds"] = 0.0
    with pytest.raises(ValueError, match="must be positive"):
        equal_time_table(metrics, timings, times, metric="relmse", inputs=INPUTS)
