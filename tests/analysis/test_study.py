"""The 39-candidate study (mcbench.analysis.study; Zheng et al. 2021 Sec. 5.3) against independent truth:
hand-made tables whose answers are known, the paper's numbers typed from its Table 3, a normal
sample of known sd for the bootstrap, brute-force pair counts for Kendall's tau."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mcbench import BenchError

from mcbench.analysis import pool

from mcbench.analysis import study
from mcbench.analysis.ranking import ranking_table

ALL = [c.name for c in pool.POOL]
# Everything below the top lists: ensembles by descending ID, then the bases, then the noisy input.
REST = [n for n in reversed(ALL) if not pool.candidate(n).is_base] + [n for n in ALL if pool.candidate(n).is_base]
FAST = study.Resampling(n_resamples=400, seed=7)


def _tidy(rows):
    return pd.DataFrame(rows, columns=["scene", "spp", "candidate", "metric", "value"])


def _from_orders(order, *, scenes, spps, metric="relmse", names=None):
    """A tidy table in which ``order(scene, spp)`` (best first) leads each case, then REST, then
    noisy; the error is the position (1 = best), so the scores are known exactly: best of 40 = 40."""
    names = ALL if names is None else names
    rows = []
    for scene in scenes:
        for spp in spps:
            top = order(scene, spp)
            ranked = top + [n for n in REST if n not in top and n in names] + ["noisy"]
            rows += [(scene, spp, name, metric, float(i + 1)) for i, name in enumerate(ranked)]
    return _tidy(rows)


def _rec(table, scope, key):
    row = table[(table["scope"] == scope) & (table["key"] == str(key))]
    assert len(row) == 1
    return row.iloc[0]


# --------------------------------------------------------------------------------------------
# data and averaging
# --------------------------------------------------------------------------------------------

def test_avg_is_the_ranking_tables_avg_and_a_missing_candidate_is_named():
    rng = np.random.default_rng(1)
    rows = [(f"s{s}", spp, n, "relmse", float(rng.uniform(0.1, 1.0)))
            for s in range(3) for spp in (4, 8, 16) for n in ALL + ["noisy"]]
    metrics = _tidy(rows)
    data = study.study_data(metrics, "relmse")
    assert data.entries == 40 and data.names[-1] == "noisy"
    ours = study.ranking_from(data)
    theirs = ranking_table(metrics, "relmse")
    pd.testing.assert_series_equal(ours["Avg."].sort_index(), theirs["Avg."].sort_index(), check_exact=False)
    dropped = metrics[~((metrics["scene"] == "s1") & (metrics["spp"] == 8) & (metrics["candidate"] == "ens27"))]
    with pytest.raises(BenchError, match="ens27"):
        study.study_data(dropped, "relmse", source="metrics.csv")
    no_spp = metrics[~((metrics["scene"] == "s2") & (metrics["spp"] == 16))]
    with pytest.raises(BenchError, match="s2"):
        study.study_data(no_spp, "relmse")


# --------------------------------------------------------------------------------------------
# the bootstrap
# --------------------------------------------------------------------------------------------

def test_bootstrap_interval_width_and_coverage_match_the_normal_theory():
    rng = np.random.default_rng(123)
    n, sd, mu, repeats = 40, 2.0, 5.0, 300
    samples = rng.normal(mu, sd, size=(n, repeats))   # 300 independent data sets of 40 "scenes"
    found = study.bootstrap_ci(samples, resampling=study.Resampling(n_resamples=1000, seed=3))
    assert (found["ci_method"] == "BCa").all()
    width = (found["ci_high"] - found["ci_low"]).mean()
    assert width == pytest.approx(2 * 1.96 * sd / math.sqrt(n), rel=0.1)
    coverage = ((found["ci_low"] < mu) & (mu < found["ci_high"])).mean()
    assert 0.89 <= coverage <= 0.99


def test_bootstrap_is_reproducible_and_degenerate_data_falls_back_or_gives_no_interval():
    x = np.random.default_rng(0).normal(size=(8, 2))
    first = study.bootstrap_ci(x, resampling=FAST)
    assert first.equals(study.bootstrap_ci(x, resampling=FAST))
    other = study.bootstrap_ci(x, resampling=study.Resampling(n_resamples=400, seed=8))
    assert not first["ci_low"].equals(other["ci_low"])
    constant = study.bootstrap_ci(np.full((8, 1), 40.0), resampling=FAST).iloc[0]
    assert constant["ci_method"] == "percentile (BCa degenerate)"
    assert constant["ci_low"] == constant["ci_high"] == 40.0
    single = study.bootstrap_ci(np.ones((1, 1)), resampling=FAST).iloc[0]
    assert pd.isna(single["ci_low"]) and pd.isna(single["ci_high"]) and single["ci_method"].startswith("none")
    assert study.is_real(0.1, 2.0) and study.is_real(-3.0, -0.5)
    assert study.is_real(-0.1, 2.0) is False and study.is_real(None, 1.0) is None


def test_place_fractions_match_the_binomial_probability():
    # 4 scenes; in 3, column 0 is 1 above column 1, in the 4th 1 below; column 2 always last.
    # Column 0 is top when the reversed scene is drawn 0 or 1 times of 4 (p = 1/4), tied at 2.
    per_scene = np.array([[2.0, 1.0, 0.0]] * 3 + [[1.0, 2.0, 0.0]])
    indices = study.resample_indices(4, resampling=study.Resampling(n_resamples=20000, seed=5))
    top = study.place_fractions(per_scene, indices, place=1)
    p = 0.75 ** 4 + 4 * 0.25 * 0.75 ** 3 + 0.5 * 6 * 0.25 ** 2 * 0.75 ** 2
    assert top[0] == pytest.approx(p, abs=0.015)
    assert top[1] == pytest.approx(1 - p, abs=0.015) and top[2] == 0.0
    second = study.place_fractions(per_scene, indices, place=2)
    assert second.sum() == pytest.approx(1.0) and second[1] == pytest.approx(p, abs=0.015)


# --------------------------------------------------------------------------------------------
# beside the paper
# --------------------------------------------------------------------------------------------

def _paper_like_ranking(spps=pool.PAPER_TABLE3_SPP, drop=()):
    """Ours = the paper's value + 1 (typed independently below), for every Table 3 candidate."""
    table = pd.DataFrame({str(s): [pool.PAPER_TABLE3[c][s] + 1.0 for c in pool.PAPER_TABLE3] for s in spps},
                         index=[pool.candidate_name(c) for c in pool.PAPER_TABLE3])
    table["Avg."] = table.mean(axis=1)
    return table.drop(index=list(drop))


def test_paper_side_reads_the_papers_table3():
    table = study.paper_comparison(_paper_like_ranking()).set_index(["id", "spp"])
    assert table.loc[(33, "Avg."), "paper"] == 29.0
    assert table.loc[(24, "4"), "paper"] == 28.6
    assert table.loc[(8, "1024"), "paper"] == 18.1
    assert table.loc[(3, "64"), "paper"] == 7.8
    assert table.loc[(24, "4"), "ours"] == pytest.approx(29.6)
    assert table.loc[(24, "4"), "difference"] == pytest.approx(1.0)
    assert sorted({i for i, _ in table.index}) == [1, 3, 4, 6, 7, 8, 16, 24, 30, 33, 35]


def test_paper_side_handles_missing_spp_and_candidates_honestly():
    ranking = _paper_like_ranking(spps=(4, 8), drop=["ens33"])
    table = study.paper_comparison(ranking).set_index(["id", "spp"])
    assert pd.isna(table.loc[(1, "16"), "ours"]) and pd.isna(table.loc[(1, "16"), "difference"])
    assert table.loc[(1, "16"), "note"] == "spp not in our data"
    assert table.loc[(1, "Avg. (common spp)"), "paper"] == pytest.approx((16.5 + 15.0) / 2)
    assert table.loc[(1, "Avg. (common spp)"), "ours"] == pytest.approx((17.5 + 16.0) / 2)
    assert "over 4–1024" in table.loc[(1, "Avg."), "note"]
    assert pd.isna(table.loc[(33, "4"), "ours"]) and "not in our ranking" in table.loc[(33, "4"), "note"]
    text = study.paper_comparison_markdown(ranking)
    assert "not on the same scale" in text and "nan" not in text.lower()
    assert "same scale" in study.paper_comparison_markdown(ranking, entries=40)
    assert "not on the same scale" not in study.paper_comparison_markdown(ranking, entries=40)


def _brute_tau(x, y):
    """Kendall tau-b by counting pairs."""
    concordant = discordant = ties_x = ties_y = 0
    for i, j in itertools.combinations(range(len(x)), 2):
        dx, dy = np.sign(x[i] - x[j]), np.sign(y[i] - y[j])
        if dx == 0 and dy == 0:
            continue
        if dx == 0:
            ties_x += 1
        elif dy == 0:
            ties_y += 1
        elif dx == dy:
            concordant += 1
        else:
            discordant += 1
    untied = concordant + discordant
    return (concordant - discordant) / math.sqrt((untied + ties_x) * (untied + ties_y))


@pytest.mark.parametrize("ours", [
    [3.0, 1.0, 2.0, 5.0, 4.0, 9.0, 7.0, 8.0, 6.0, 11.0, 10.0],
    [3.0, 1.0, 1.0, 5.0, 4.0, 9.0, 9.0, 8.0, 6.0, 11.0, 10.0],   # with ties
])
def test_kendall_tau_equals_a_pair_count(ours):
    ranking = pd.DataFrame({"4": ours, "Avg.": ours}, index=[pool.candidate_name(c) for c in pool.PAPER_TABLE3])
    paper = [pool.PAPER_TABLE3[c]["Avg."] for c in pool.PAPER_TABLE3]
    found = study.paper_kendall(ranking).set_index("basis")
    assert found.loc["Avg.", "n"] == 11
    assert found.loc["Avg.", "tau"] == pytest.approx(_brute_tau(ours, paper))
    assert 0.0 < found.loc["Avg.", "p_value"] <= 1.0
    common = [pool.PAPER_TABLE3[c][4] for c in pool.PAPER_TABLE3]
    assert found.loc["Avg. (common spp)", "tau"] == pytest.approx(_brute_tau(ours, common))
    # the bases alone: the six rows of IDs <= 8, nothing else
    bases = [i for i, c in enumerate(pool.PAPER_TABLE3) if c <= 8]
    assert study.PAPER_TABLE3_BASES == (1, 3, 4, 6, 7, 8)
    found = study.paper_kendall(ranking, ids=study.PAPER_TABLE3_BASES).set_index("basis")
    assert found.loc["Avg.", "n"] == 6
    assert found.loc["Avg.", "tau"] == pytest.approx(_brute_tau([ours[i] for i in bases], [paper[i] for i in bases]))
    assert "among its bases alone (IDs 1, 3, 4, 6, 7, 8), by Avg.: tau = " \
        f"{found.loc['Avg.', 'tau']:.3f}" in study.paper_comparison_markdown(ranking)


# --------------------------------------------------------------------------------------------
# recommendations
# --------------------------------------------------------------------------------------------

SPPS = (4, 16, 64, 128, 512)
TOPS = {4: ["ens20", "ens27", "ens18"], 16: ["ens20", "ens27", "ens18"], 64: ["ens27", "ens20", "ens18"],
        128: ["ens27", "ens20", "ens18"], 512: ["ens18", "ens27", "ens20"]}


def test_recommendations_on_a_table_with_a_known_answer():
    # scores (40 = best): ens27 39+39+40+40+39 = 197, ens20 40+40+39+39+38 = 196, ens18 38*4+40 = 192
    metrics = _from_orders(lambda scene, spp: TOPS[spp], scenes=["a", "b", "c"], spps=SPPS)
    data = study.study_data(metrics, "relmse")
    table = study.recommendations(data, resampling=FAST)
    # overall fewer (size < 4): ens20 (40+40+39+39+38)/5 = 39.2 above ens18 (38*4+40)/5 = 38.4
    expected = {("size", 2): "ens16", ("size", 3): "ens20", ("size", 4): "ens27", ("size", 5): "ens34",
                ("size", 6): "ens38", ("size", 8): "ens39", ("band", "low"): "ens20", ("band", "medium"): "ens27",
                ("band", "high"): "ens18", ("overall", "best"): "ens27", ("overall", "second"): "ens20",
                ("overall", "fewer"): "ens20"}
    # among only the paper's named ensembles (#10 #16 #18 #20 #24 #27-#30 #33 #35 #39) the filled
    # leaders of sizes 5 and 6 (#34, #38; REST has them first) give way to #33 and #35
    named = {**expected, ("size", 5): "ens33", ("size", 6): "ens35"}
    assert len(table) == len(expected)
    for (scope, key), name in expected.items():
        row = _rec(table, scope, key)
        assert row["ours"] == name, (scope, key)
        assert row["ours_fraction"] == 1.0     # every scene agrees
        assert row["named"] == named[(scope, key)], (scope, key)
        assert row["named_fraction"] == 1.0
    assert _rec(table, "overall", "best")["ours_score"] == pytest.approx(197 / 5)
    assert _rec(table, "band", "medium")["spp"] == "64 128"
    assert _rec(table, "band", "high")["spp"] == "512"
    size2 = _rec(table, "size", 2)
    assert size2["paper"] == "ens10" and size2["agrees"] == "no" and size2["real_difference"] == "yes"
    assert size2["paper_fraction"] == 0.0 and size2["difference"] > 0
    for scope, key in (("size", 3), ("size", 4), ("band", "low"), ("band", "medium"), ("band", "high"),
                       ("overall", "best"), ("overall", "second"), ("overall", "fewer")):
        assert _rec(table, scope, key)["agrees"] == "yes" and _rec(table, scope, key)["named_agrees"] == "yes"
    assert _rec(table, "size", 2)["named_agrees"] == "no"               # #16 among the named, not #10
    assert _rec(table, "size", 5)["named_candidates"] == 1 and _rec(table, "size", 2)["named_candidates"] == 2
    assert pd.isna(_rec(table, "size", 5)["paper"]) and pd.isna(_rec(table, "size", 5)["agrees"])
    assert not any(n in set(table["ours"]) for n in pool.BASES.values())   # bases never recommended
    sentences = study.recommendation_sentences(table, n_resamples=400)
    low = next(s for s in sentences if s.startswith("For 4–32 spp"))
    assert "#20 KPCN+OIDN+RDFC" in low and "top in 100 %" in low and "the paper recommends the same, #20" in low
    assert any("the paper recommends #10" in s and "really different" in s for s in sentences)


def test_recommendation_fraction_under_scene_resampling():
    # 3 scenes favour ens27 over ens20 by one place at every spp, the 4th the reverse: the
    # resample fraction in which ens27 is top is the binomial probability of the place test.
    order = lambda scene, spp: ["ens27", "ens20"] if scene != "d" else ["ens20", "ens27"]  # noqa: E731
    metrics = _from_orders(order, scenes=["a", "b", "c", "d"], spps=(4, 512))
    resampling = study.Resampling(n_resamples=8000, seed=11)
    best = _rec(study.recommendations(study.study_data(metrics, "relmse"), resampling=resampling), "overall", "best")
    p = 0.75 ** 4 + 4 * 0.25 * 0.75 ** 3 + 0.5 * 6 * 0.25 ** 2 * 0.75 ** 2
    assert best["ours"] == "ens27" and best["ours_fraction"] == pytest.approx(p, abs=0.02)
    assert best["paper"] == "ens27" and best["agrees"] == "yes"
    second = _rec(study.recommendations(study.study_data(metrics, "relmse"), resampling=resampling), "overall",
                  "second")
    assert second["ours"] == "ens20" and second["ours_fraction"] == pytest.approx(p, abs=0.02)


# --------------------------------------------------------------------------------------------
# findings and verdicts
# --------------------------------------------------------------------------------------------

def test_ci_verdict_rule_both_ways():
    assert study.ci_verdict(0.5, 2.0) == study.REPRODUCED
    assert study.ci_verdict(-2.0, -0.5) == study.NOT_REPRODUCED
    assert study.ci_verdict(-0.5, 2.0) == study.INCONCLUSIVE
    assert study.ci_verdict(None, 2.0) == study.INCONCLUSIVE
    assert study.ci_verdict(0.02, 0.08, claim="below", threshold=0.1) == study.REPRODUCED
    assert study.ci_verdict(0.12, 0.3, claim="below", threshold=0.1) == study.NOT_REPRODUCED


def _finding(table, finding, prefix):
    rows = table[(table["finding"] == finding) & table["quantity"].str.startswith(prefix)]
    assert len(rows) == 1, (finding, prefix, list(table.loc[table["finding"] == finding, "quantity"]))
    return rows.iloc[0]


@pytest.mark.parametrize("first,verdict", [("ens27", study.REPRODUCED), ("ens29", study.NOT_REPRODUCED),
                                           ("mixed", study.INCONCLUSIVE)])
def test_dc_verdict_from_constructed_data(first, verdict):
    def order(scene, spp):
        if first == "mixed":   # half the scenes each way: the interval straddles 0
            return ["ens27", "ens29"] if scene in "ab" else ["ens29", "ens27"]
        return [first, "ens29" if first == "ens27" else "ens27"]
    metrics = _from_orders(order, scenes=list("abcd"), spps=(4, 64))
    table = study.findings(study.study_data(metrics, "relmse"), resampling=FAST)
    assert _finding(table, "d", "mean of #27 - #29")["verdict"] == verdict


@pytest.mark.parametrize("learned_low,verdict", [(True, study.REPRODUCED), (False, study.NOT_REPRODUCED)])
def test_learned_vs_classical_verdicts_from_constructed_data(learned_low, verdict):
    learned = [pool.candidate_name(i) for i in study.LEARNED_BASES]
    classical = [pool.candidate_name(i) for i in study.CLASSICAL_BASES]

    def order(scene, spp):
        low_first = learned + classical if learned_low else classical + learned
        return low_first if spp <= 32 else low_first[::-1]
    metrics = _from_orders(order, scenes=list("abc"), spps=(4, 8, 512, 1024))
    table = study.findings(study.study_data(metrics, "relmse"), resampling=FAST)
    assert _finding(table, "e", "low band")["verdict"] == verdict
    assert _finding(table, "e", "high band")["verdict"] == verdict
    assert _finding(table, "e", "medium band")["verdict"] == ""          # no claim, no spp
    assert _finding(table, "e", "low band")["estimate"] * (1 if learned_low else -1) > 0


def test_ensemble_against_members_fractions_on_a_toy():
    # pool subset: bases kpcn (#1), nfor (#4), rdfc (#8); ensembles ens10 {1,4}, ens11 {1,8}, ens18 {1,4,8}
    names = ["kpcn", "nfor", "rdfc", "ens10", "ens11", "ens18"]
    values = {  # (scene, spp) -> errors; ens worse than members where marked
        4: {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 2.0, "ens11": 0.5, "ens18": 4.0},
        64: {"kpcn": 2.0, "nfor": 1.0, "rdfc": 3.0, "ens10": 0.5, "ens11": 0.5, "ens18": 0.5},
    }
    rows = [(scene, spp, n, "relmse", v) for scene in ("a", "b") for spp, case in values.items()
            for n, v in case.items()] + [(s, spp, "noisy", "relmse", 9.0) for s in ("a", "b") for spp in values]
    table = study.findings(study.study_data(_tidy(rows), "relmse", candidates=names), resampling=FAST)
    # (b) as the paper states it, on the size-2 ensembles ens10, ens11 only. 4 spp: ens10 (2.0)
    # loses to kpcn (1.0), beats nfor (3.0); ens11 (0.5) beats kpcn and rdfc: 3 of 4 comparisons,
    # 1 of 2 pairs beats both. 64 spp: both pairs (0.5) beat every member: 4/4, 2/2.
    assert _finding(table, "b", "4 spp: fraction of (size-2 ensemble, member)")["estimate"] == pytest.approx(3 / 4)
    assert _finding(table, "b", "4 spp: fraction of size-2 ensembles outperforming both")["estimate"] == 0.5
    assert _finding(table, "b", "64 spp: fraction of (size-2 ensemble, member)")["estimate"] == 1.0
    decision = _finding(table, "b", "all spp: fraction of (case, size-2 ensemble, member)")
    assert decision["estimate"] == pytest.approx(7 / 8)
    assert decision["verdict"] == study.NOT_REPRODUCED       # 0.875 in every scene: below 0.90
    assert "#10 vs #1 (not reproduced)" in decision["note"] and "#11" not in decision["note"]
    assert _finding(table, "b", "all spp: fraction of (case, size-2 ensemble) outperforming both")["estimate"] == \
        pytest.approx(3 / 4)
    lost = _finding(table, "b", "#10 KPCN+NFOR vs member #1 KPCN")
    assert lost["estimate"] == 0.5 and lost["verdict"] == study.NOT_REPRODUCED
    assert "2 of 4 cases: a@4, b@4" in lost["note"]
    assert _finding(table, "b", "#11 KPCN+RDFC (filled) vs member #8 RDFC")["verdict"] == study.REPRODUCED
    # ours, secondary, every size pooled (ens18 too), no verdict: 4 spp (1 + 0 + 3) / 7 lost, 64 spp 0
    pooled = _finding(table, "b", "ours, secondary (3 ensembles of every size pooled; not the paper's claim): "
                                  "fraction of (case, ensemble, member)")
    assert pooled["estimate"] == pytest.approx((4 / 7 + 0) / 2) and pooled["verdict"] == ""
    assert _finding(table, "b", "ours, secondary (3 ensembles of every size pooled; not the paper's claim): "
                                "fraction of (case, ensemble) with the ensemble worse than its best")["estimate"] == \
        pytest.approx((2 / 3 + 0) / 2)
    # f: Avg. scores -- 7 entries; ens18's margin over kpcn is negative at 4 spp, positive at 64
    assert (table["verdict"].isin([study.REPRODUCED, study.NOT_REPRODUCED, study.INCONCLUSIVE, ""])).all()
    assert _finding(table, "c", "heterogeneous - homogeneous")["verdict"] == study.INCONCLUSIVE  # no such sizes


def _size_order(means):
    """Order by a quality per size (higher first), ties by descending ID: means[size] per ensemble."""
    ranked = sorted((n for n in ALL if not pool.candidate(n).is_base),
                    key=lambda n: (-means[pool.candidate(n).size], -pool.candidate(n).id))
    return lambda scene, spp: ranked   # noqa: E731


@pytest.mark.parametrize("means,grows,levels", [
    ({2: 1, 3: 2, 4: 3, 5: 5, 6: 4, 8: 4.5}, study.REPRODUCED, study.REPRODUCED),     # grows, then drops
    ({2: 1, 3: 2, 4: 3, 5: 4, 6: 5, 8: 6}, study.REPRODUCED, study.NOT_REPRODUCED),   # keeps growing
    ({2: 3, 3: 2, 4: 1, 5: 4, 6: 5, 8: 6}, study.NOT_REPRODUCED, study.NOT_REPRODUCED),
])
def test_size_verdicts_from_constructed_data(means, grows, levels):
    # the bases (size 1) are always below the ensembles; noise-free, so every interval is a point
    metrics = _from_orders(_size_order(means), scenes=list("abc"), spps=(4, 64))
    table = study.findings(study.study_data(metrics, "relmse"), resampling=FAST)
    steps = table[(table["finding"] == "a") & table["quantity"].str.startswith("gain size")]
    assert list(steps["quantity"]) == ["gain size 1 -> 2", "gain size 2 -> 3", "gain size 3 -> 4", "gain size 4 -> 5"]
    assert _finding(table, "a", "gains grow up to size 5")["verdict"] == grows
    assert _finding(table, "a", "levels off past size 5")["verdict"] == levels


def test_growth_up_to_size_5_is_inconclusive_when_sizes_are_missing():
    # only the bases and the size-2 ensembles: the one step 1 -> 2 grows, but 2 -> 5 is unseen
    names = [n for n in ALL if pool.candidate(n).size <= 2]
    metrics = _from_orders(lambda scene, spp: [n for n in names if not pool.candidate(n).is_base],
                           scenes=list("abc"), spps=(4, 64), names=names)
    table = study.findings(study.study_data(metrics, "relmse", candidates=names), resampling=FAST)
    assert _finding(table, "a", "gain size 1 -> 2")["verdict"] == study.REPRODUCED
    row = _finding(table, "a", "gains grow up to size 5")
    assert row["verdict"] == study.INCONCLUSIVE and "3, 4, 5 missing" in row["note"]


# --------------------------------------------------------------------------------------------
# the writer
# --------------------------------------------------------------------------------------------

def test_writer_writes_the_declared_files_without_nan_and_skips_absent_metrics(tmp_path):
    rng = np.random.default_rng(4)
    quality = {n: rng.normal() for n in ALL}
    rows = [(f"s{s}", spp, n, "relmse", float(np.exp(-quality[n] + rng.normal(0, 0.3))))
            for s in range(4) for spp in (4, 64, 512) for n in ALL]
    rows += [(f"s{s}", spp, "noisy", "relmse", 100.0) for s in range(4) for spp in (4, 64, 512)]
    path = tmp_path / "metrics.csv"
    _tidy(rows).to_csv(path, index=False)
    out = tmp_path / "study"
    study.write_study_tables(str(path), out, metrics=("relmse", "dssim"), n_resamples=300, seed=1)
    declared = {Path(p).name for p in study.study_outputs(out, ("relmse", "dssim"))}
    # every declared file, and besides them only their hidden checksum side files (mcbench.io.checksums)
    assert {p.name for p in out.iterdir() if not p.name.endswith(".crc32")} == declared
    assert {p.name for p in out.iterdir() if p.name.endswith(".crc32")} == {f".{name}.crc32" for name in declared}
    for name in declared:
        text = (out / name).read_text()
        assert "nan" not in text.lower().replace("nano", "") and "inf " not in text.lower(), name
    assert list(pd.read_csv(out / "scores_ci_dssim.csv").columns) == study.SCORE_CI_COLUMNS
    assert len(pd.read_csv(out / "scores_ci_dssim.csv")) == 0
    assert "dssim: no values" in (out / "summary.md").read_text()
    cis = pd.read_csv(out / "scores_ci_relmse.csv")
    assert len(cis) == 40 and (cis["avg_ci_low"] <= cis["avg"]).all() and (cis["avg"] <= cis["avg_ci_high"]).all()
    paper = pd.read_csv(out / "paper_table3.csv")
    assert set(paper["id"]) == set(pool.PAPER_TABLE3)
    broken = _tidy(rows)
    broken = broken[~((broken["candidate"] == "ens31") & (broken["scene"] == "s0") & (broken["spp"] == 64))]
    broken.to_csv(path, index=False)
    with pytest.raises(BenchError, match="ens31"):
        study.write_study_tables(str(path), out, metrics=("relmse",), n_resamples=100)


def test_reference_noise_effect_names_the_spp_where_the_ranking_really_moves():
    # raw: the same order everywhere; corrected: #10 and #15 swap at 1024 spp in every scene (the
    # reference noise had hidden #15's lead there) -> a real change at 1024 only
    names = [n for n in ALL if pool.candidate(n).size <= 2]
    head = [n for n in names if not pool.candidate(n).is_base]

    def raw_order(scene, spp):
        return head

    def corrected_order(scene, spp):
        if spp != 1024:
            return head
        swap = {"ens10": "ens15", "ens15": "ens10"}
        return [swap.get(n, n) for n in head]
    raw = study.study_data(_from_orders(raw_order, scenes=list("abcd"), spps=(4, 1024), names=names), "relmse",
                           candidates=names)
    corrected = study.study_data(_from_orders(corrected_order, scenes=list("abcd"), spps=(4, 1024), names=names,
                                              metric="relmse_corrected"), "relmse_corrected", candidates=names)
    table = study.reference_noise_effect(raw, corrected, resampling=FAST).set_index("spp")
    assert table.loc["4", "agree"] == "yes" and table.loc["4", "kendall_tau"] == pytest.approx(1.0)
    assert table.loc["1024", "agree"] == "no"
    assert set(table.loc["1024", "changed"].split()) == {"ens10", "ens15"}
    gap = head.index("ens15") - head.index("ens10")                      # places between them
    assert table.loc["1024", "max_abs_change"] == pytest.approx(gap)
    assert head.index("ens10") < 3 and table.loc["1024", "top_corrected"].split()[head.index("ens10")] == "ens15"
    text = study.reference_noise_markdown(table.reset_index())
    assert "really changes scores at spp 1024" in text
    with pytest.raises(Exception, match="different"):
        study.reference_noise_effect(raw, study.study_data(_from_orders(raw_order, scenes=list("ab"), spps=(4,),
                                                                        names=names), "relmse", candidates=names))
