"""mcbench.analysis.study.recommendations on hand-made tables whose answers are known: per scope,
among the paper-named ensembles, and by relMSE and DSSIM together (Zheng et al. 2021 Sec. 5.3.5-5.3.6)."""

from __future__ import annotations


import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.analysis import pool
from mcbench.analysis.study.data import Resampling, study_data
from mcbench.analysis.study.recommendations import BOTH_COLUMNS, recommendations, recommendations_both
from mcbench.analysis.study.markdown import (recommendation_sentences, recommendations_both_markdown,
                                             recommendations_markdown)
from tests.analysis.study.synthetic import FAST, FASTER, from_fixed_order, from_orders


def _rec(table, scope, key):
    row = table[(table["scope"] == scope) & (table["key"] == str(key))]
    assert len(row) == 1
    return row.iloc[0]


SPPS = (4, 16, 64, 128, 512)
TOPS = {4: ["ens20", "ens27", "ens18"], 16: ["ens20", "ens27", "ens18"], 64: ["ens27", "ens20", "ens18"],
        128: ["ens27", "ens20", "ens18"], 512: ["ens18", "ens27", "ens20"]}


def test_recommendations_on_a_table_with_a_known_answer():
    # scores (40 = best): ens27 39+39+40+40+39 = 197, ens20 40+40+39+39+38 = 196, ens18 38*4+40 = 192
    metrics = from_orders(lambda scene, spp: TOPS[spp], scenes=["a", "b", "c"], spps=SPPS)
    data = study_data(metrics, "relmse")
    table = recommendations(data, resampling=FAST)
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
    sentences = recommendation_sentences(table, n_resamples=400)
    low = next(s for s in sentences if s.startswith("For 4–32 spp"))
    assert "#20 KPCN+OIDN+RDFC" in low and "top in 100 %" in low and "the paper recommends the same, #20" in low
    assert any("the paper recommends #10" in s and "really different" in s for s in sentences)


def test_recommendation_fraction_under_scene_resampling():
    # 3 scenes favour ens27 over ens20 by one place at every spp, the 4th the reverse: the
    # resample fraction in which ens27 is top is the binomial probability of the place test.
    order = lambda scene, spp: ["ens27", "ens20"] if scene != "d" else ["ens20", "ens27"]  # noqa: E731
    metrics = from_orders(order, scenes=["a", "b", "c", "d"], spps=(4, 512))
    resampling = Resampling(n_resamples=8000, seed=11)
    best = _rec(recommendations(study_data(metrics, "relmse"), resampling=resampling), "overall", "best")
    p = 0.75 ** 4 + 4 * 0.25 * 0.75 ** 3 + 0.5 * 6 * 0.25 ** 2 * 0.75 ** 2
    assert best["ours"] == "ens27" and best["ours_fraction"] == pytest.approx(p, abs=0.02)
    assert best["paper"] == "ens27" and best["agrees"] == "yes"
    second = _rec(recommendations(study_data(metrics, "relmse"), resampling=resampling), "overall",
                  "second")
    assert second["ours"] == "ens20" and second["ours_fraction"] == pytest.approx(p, abs=0.02)


def _row(table, scope, key, which=None):
    chosen = (table["scope"] == scope) & (table["key"] == str(key))
    if which is not None:
        chosen &= table["set"] == which
    assert chosen.sum() == 1
    return table[chosen].iloc[0]


def test_pick_among_paper_named_ensembles_differs_when_a_filled_one_leads():
    # #34 (filled) first everywhere, then #27, then #33: all 31 -> #34; paper-named only -> #27
    data = study_data(from_fixed_order(["ens34", "ens27", "ens33"]), "relmse")
    table = recommendations(data, resampling=FASTER)
    best = _row(table, "overall", "best")
    assert best["ours"] == "ens34" and best["named"] == "ens27"
    assert best["agrees"] == "no" and best["named_agrees"] == "yes"
    assert best["ours_score"] == 40.0 and best["named_score"] == 39.0 and best["named_fraction"] == 1.0
    assert best["candidates"] == 31 and best["named_candidates"] == len(pool.PAPER_NAMED_IDS) == 12
    assert _row(table, "size", 5)["named"] == "ens33"          # #33 is the paper's only size-5 set
    assert _row(table, "overall", "second")["ours"] == "ens27" and _row(table, "overall", "second")["named"] == "ens33"
    # fewer than 4 members: REST has #24 first among sizes 2-3 (descending IDs #24, #23, ...)
    fewer = _row(table, "overall", "fewer")
    assert fewer["ours"] == "ens24" and fewer["named"] == "ens24" and fewer["paper"] == "ens20"
    assert any("among only the paper's named ensembles: #27" in s for s in recommendation_sentences(table))
    assert "ours (paper-named only)" in recommendations_markdown(table)


def test_both_metrics_side_by_side_and_the_combined_rule_of_ours():
    # relMSE: #20, #27 lead; DSSIM: #18, #27 lead. With 40 entries (place p scores 41 - p) and
    # REST by descending ID: relMSE places #18 22nd (after #20, #27, #39..#28 (12), #26..#21 (6),
    # #19) -> score 19; DSSIM places #20 21st (after #18, #27, #39..#28, #26..#21) -> score 20.
    # Combined (mean of the two scores): #27 39, #39 38, #20 (40 + 20) / 2 = 30, #18 (19 + 40) / 2
    # = 29.5, #24 (24 + 24) / 2 = 24.
    relmse = study_data(from_fixed_order(["ens20", "ens27"]), "relmse")
    dssim = study_data(from_fixed_order(["ens18", "ens27"], metric="dssim"), "dssim")
    table = recommendations_both({"relmse": relmse, "dssim": dssim}, resampling=FASTER)
    assert list(table.columns) == BOTH_COLUMNS
    best = _row(table, "overall", "best", "all")
    assert (best["relmse"], best["dssim"], best["combined"]) == ("ens20", "ens18", "ens27")
    assert best["relmse_score"] == 40.0 and best["dssim_score"] == 40.0
    assert best["combined_score"] == 39.0 and best["combined_fraction"] == 1.0 and best["agrees"] == "yes"
    second = _row(table, "overall", "second", "all")
    assert second["combined"] == "ens39" and second["combined_score"] == 38.0
    # second among the paper-named: #39 is named too; and the paper's #20 scores 30 combined
    assert _row(table, "overall", "second", "paper-named")["combined"] == "ens39"
    size3 = _row(table, "size", 3, "all")
    assert size3["combined"] == "ens20" and size3["combined_score"] == 30.0 and size3["agrees"] == "yes"
    high = _row(table, "band", "high", "paper-named")
    assert high["combined"] == "ens27" and high["paper"] == "ens18" and high["agrees"] == "no"
    assert high["paper_combined_score"] == 29.5 and high["spp"] == "512"
    assert _row(table, "band", "low", "all")["spp"] == "4"
    text = recommendations_both_markdown(table)
    assert "ours, not the paper's" in text and "combined pick (ours)" in text and "nan" not in text.lower()
    # a metric missing: an empty table that says so
    empty = recommendations_both({"relmse": relmse}, resampling=FASTER)
    assert empty.empty and list(empty.columns) == BOTH_COLUMNS
    assert "Needs both relmse and dssim" in recommendations_both_markdown(empty)
    other = study_data(from_fixed_order(["ens18"], scenes=("a", "b"), metric="dssim"), "dssim")
    with pytest.raises(BenchError, match="different scenes"):
        recommendations_both({"relmse": relmse, "dssim": other})
