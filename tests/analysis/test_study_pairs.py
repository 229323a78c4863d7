"""Finding (b) as Zheng et al. 2021 Sec. 5.3.4 states it (size-2 ensembles against each member)
and the recommendations among the paper-named ensembles and by relMSE and DSSIM together
(Sec. 5.3.5-5.3.6), on hand-made tables whose answers are computed by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.analysis import pool, study

ALL = [c.name for c in pool.POOL]
REST = [n for n in reversed(ALL) if not pool.candidate(n).is_base] + [n for n in ALL if pool.candidate(n).is_base]
FAST = study.Resampling(n_resamples=300, seed=7)
SIZE2 = ["ens09", "ens10", "ens11", "ens12", "ens13", "ens14", "ens15", "ens16"]


def _tidy(rows):
    return pd.DataFrame(rows, columns=["scene", "spp", "candidate", "metric", "value"])


def _finding(table, prefix):
    rows = table[(table["finding"] == "b") & table["quantity"].str.startswith(prefix)]
    assert len(rows) == 1, (prefix, list(table.loc[table["finding"] == "b", "quantity"]))
    return rows.iloc[0]


def _from_values(value, *, scenes=("a", "b", "c"), spps=(4, 64), metric="relmse"):
    """Every pool candidate and the noisy input with error ``value(name)`` in every case."""
    return _tidy([(scene, spp, name, metric, float(value(name) if name != "noisy" else 100.0))
                  for scene in scenes for spp in spps for name in ALL + ["noisy"]])


def test_the_pool_holds_eight_size_2_ensembles_and_115_member_comparisons():
    # hand count of pool.py: #9-#16 pairs, #17-#24 triples, #25-#31 quads, #32-#34 fives, #35-#38 sixes, #39 all 8
    assert [c.name for c in pool.POOL if not c.is_base and c.size == 2] == SIZE2
    assert sum(c.size for c in pool.POOL if not c.is_base) == 8 * 2 + 8 * 3 + 7 * 4 + 3 * 5 + 4 * 6 + 8 == 115


@pytest.mark.parametrize("case", ["pairs split, larger win", "pairs win, larger lose"])
def test_size_2_rule_and_the_pooled_rule_disagree_and_only_the_size_2_rule_is_the_papers(case):
    # Errors: base #i has error i (KPCN 1 ... RDFC 8).
    # "pairs split": each pair has the mean of its members' errors, so it beats its worse member and
    #   loses to its better one (1/2 of comparisons, never both); every larger ensemble has 0.5 and
    #   beats all its members. Paper's rule: 0.5 < 0.90 -> not reproduced. The pooled rule (every
    #   size, worse than a member in under 10 %): 8 lost of 115 comparisons = 7 % -> "reproduced".
    # "pairs win": pairs have 0.5 (beat both), larger ensembles 50 (lose to every member). Paper's
    #   rule: 1.0 -> reproduced; pooled: 99 of 115 lost -> "not reproduced".
    def value(name):
        c = pool.candidate(name)
        if c.is_base:
            return float(c.id)
        if c.size == 2:
            return float(np.mean(c.members)) if case.startswith("pairs split") else 0.5
        return 0.5 if case.startswith("pairs split") else 50.0
    data = study.study_data(_from_values(value), "relmse")
    table = study.findings(data, resampling=FAST)
    decision = _finding(table, "all spp: fraction of (case, size-2 ensemble, member) comparisons the pair wins")
    pooled = _finding(table, "ours, secondary (31 ensembles of every size pooled; not the paper's claim): "
                             "fraction of (case, ensemble, member)")
    wrong = study.ci_verdict(pooled["ci_low"], pooled["ci_high"], claim="below", threshold=study.ALMOST)
    assert pooled["verdict"] == ""                               # ours, secondary: no verdict of its own
    if case.startswith("pairs split"):
        assert decision["estimate"] == 0.5 and decision["verdict"] == study.NOT_REPRODUCED
        assert pooled["estimate"] == pytest.approx(8 / 115)
        assert wrong == study.REPRODUCED                         # the pooled rule would call it reproduced
        both = _finding(table, "all spp: fraction of (case, size-2 ensemble) outperforming both")
        assert both["estimate"] == 0.0
        # every pair fails against its better (lower-numbered) member and beats the other
        for name in SIZE2:
            better, worse = (pool.candidate_name(m) for m in pool.candidate(name).members)
            rows = table[table["quantity"].str.startswith(f"#{pool.candidate(name).id} ")]
            lost = rows[rows["quantity"].str.contains(f"vs member #{pool.candidate(better).id} ", regex=False)]
            won = rows[rows["quantity"].str.contains(f"vs member #{pool.candidate(worse).id} ", regex=False)]
            assert lost["estimate"].iloc[0] == 0.0 and lost["verdict"].iloc[0] == study.NOT_REPRODUCED
            assert won["estimate"].iloc[0] == 1.0 and won["verdict"].iloc[0] == study.REPRODUCED
    else:
        assert decision["estimate"] == 1.0 and decision["verdict"] == study.REPRODUCED
        assert pooled["estimate"] == pytest.approx(99 / 115)
        assert wrong == study.NOT_REPRODUCED                     # the pooled rule would call it not reproduced
        assert "pairs not reproduced against a member: none" in decision["note"]


def test_pair_members_counts_wins_per_spp_and_names_the_failing_cases():
    # bases kpcn (#1), nfor (#4), rdfc (#8); pairs ens10 {1,4}, ens11 {1,8}; scenes a, b, c; spp 4, 64
    names = ["kpcn", "nfor", "rdfc", "ens10", "ens11"]
    errors = {("a", 4): {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 2.0, "ens11": 0.5},
              ("b", 4): {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 0.9, "ens11": 1.0},   # ens11 ties kpcn
              ("c", 4): {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 0.9, "ens11": 0.5}}
    errors.update({(s, 64): {"kpcn": 2.0, "nfor": 1.0, "rdfc": 3.0, "ens10": 0.5, "ens11": 0.5} for s in "abc"})
    rows = [(s, spp, n, "dssim", v) for (s, spp), case in errors.items() for n, v in case.items()]
    rows += [(s, spp, "noisy", "dssim", 9.0) for s, spp in errors]
    data = study.study_data(_tidy(rows), "dssim", candidates=names)
    table = study.pair_members(data, resampling=FAST).set_index(["ensemble", "member", "spp"])
    assert list(table.columns) == [c for c in study.PAIR_COLUMNS if c not in ("ensemble", "member", "spp")]
    # ens10 vs kpcn: loses at a@4 only -> 4 spp 2/3, 64 spp 3/3, all 5/6
    assert table.loc[("ens10", "kpcn", "4"), ["cases", "wins"]].tolist() == [3, 2]
    assert table.loc[("ens10", "kpcn", "4"), "failures"] == "a@4"
    assert table.loc[("ens10", "kpcn", "all"), ["cases", "wins"]].tolist() == [6, 5]
    assert table.loc[("ens10", "kpcn", "all"), "fraction"] == pytest.approx(5 / 6)
    assert table.loc[("ens10", "nfor", "all"), "wins"] == 6 and table.loc[("ens10", "nfor", "all"), "failures"] == ""
    # ens11 vs kpcn: the tie at b@4 is not a win
    assert table.loc[("ens11", "kpcn", "all"), "wins"] == 5 and table.loc[("ens11", "kpcn", "all"), "failures"] == "b@4"
    assert table.loc[("ens11", "both", "4"), "wins"] == 2
    assert table.loc[("ens10", "both", "all"), "wins"] == 5 and pd.isna(table.loc[("ens10", "both", "all"), "member_id"])
    # every case won -> a point interval at 1 -> reproduced; interval of ens10 vs nfor is [1, 1]
    assert table.loc[("ens10", "nfor", "all"), "verdict"] == study.REPRODUCED
    assert table.loc[("ens10", "nfor", "all"), "ci_low"] == 1.0
    assert set(table["verdict"]) <= {study.REPRODUCED, study.NOT_REPRODUCED, study.INCONCLUSIVE}
    text = study.pair_members_markdown(table.reset_index())
    assert "| #10 KPCN+NFOR | #1 KPCN† | 2/3 | 3/3 | 5/6 | 0.833 |" in text
    assert "does not outperform #1 KPCN† in: a@4" in text and "nan" not in text.lower()
    # the findings agree with the table: (b)'s deciding row is the mean over scenes of the per-scene
    # fraction of comparisons won. 4 spp: a 3/4 (ens10 loses to kpcn), b 3/4 (ens11's tie with kpcn),
    # c 4/4; 64 spp 4/4 everywhere -> per scene 7/8, 7/8, 1 -> mean 22/24
    decision = _finding(study.findings(data, resampling=FAST), "all spp: fraction of (case, size-2 ensemble, member)")
    assert decision["estimate"] == pytest.approx(22 / 24)


def test_finding_b_without_size_2_ensembles_is_inconclusive_and_says_why():
    names = ["kpcn", "nfor", "oidn", "rdfc", "ens27"]
    data = study.study_data(_from_values(lambda n: 1.0 if n == "ens27" else 2.0), "relmse", candidates=names)
    row = _finding(study.findings(data, resampling=FAST), "size-2 ensembles against each member")
    assert row["verdict"] == study.INCONCLUSIVE and "no size-2 ensemble" in row["note"]
    assert study.pair_members(data, resampling=FAST).empty
    assert "No size-2 ensemble" in study.pair_members_markdown(study.pair_members(data, resampling=FAST))


# --------------------------------------------------------------------------------------------
# recommendations: the paper-named set, both metrics
# --------------------------------------------------------------------------------------------

def _from_orders(order, *, scenes=("a", "b", "c"), spps=(4, 64, 512), metric="relmse"):
    """Error = place: ``order`` first, then REST (ensembles by descending ID, bases), then noisy."""
    rows = []
    for scene in scenes:
        for spp in spps:
            ranked = order + [n for n in REST if n not in order] + ["noisy"]
            rows += [(scene, spp, name, metric, float(i + 1)) for i, name in enumerate(ranked)]
    return _tidy(rows)


def _row(table, scope, key, which=None):
    chosen = (table["scope"] == scope) & (table["key"] == str(key))
    if which is not None:
        chosen &= table["set"] == which
    assert chosen.sum() == 1
    return table[chosen].iloc[0]


def test_pick_among_paper_named_ensembles_differs_when_a_filled_one_leads():
    # #34 (filled) first everywhere, then #27, then #33: all 31 -> #34; paper-named only -> #27
    data = study.study_data(_from_orders(["ens34", "ens27", "ens33"]), "relmse")
    table = study.recommendations(data, resampling=FAST)
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
    assert any("among only the paper's named ensembles: #27" in s for s in study.recommendation_sentences(table))
    assert "ours (paper-named only)" in study.recommendations_markdown(table)


def test_both_metrics_side_by_side_and_the_combined_rule_of_ours():
    # relMSE: #20, #27 lead; DSSIM: #18, #27 lead. With 40 entries (place p scores 41 - p) and
    # REST by descending ID: relMSE places #18 22nd (after #20, #27, #39..#28 (12), #26..#21 (6),
    # #19) -> score 19; DSSIM places #20 21st (after #18, #27, #39..#28, #26..#21) -> score 20.
    # Combined (mean of the two scores): #27 39, #39 38, #20 (40 + 20) / 2 = 30, #18 (19 + 40) / 2
    # = 29.5, #24 (24 + 24) / 2 = 24.
    relmse = study.study_data(_from_orders(["ens20", "ens27"]), "relmse")
    dssim = study.study_data(_from_orders(["ens18", "ens27"], metric="dssim"), "dssim")
    table = study.recommendations_both({"relmse": relmse, "dssim": dssim}, resampling=FAST)
    assert list(table.columns) == study.BOTH_COLUMNS
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
    text = study.recommendations_both_markdown(table)
    assert "ours, not the paper's" in text and "combined pick (ours)" in text and "nan" not in text.lower()
    # a metric missing: an empty table that says so
    empty = study.recommendations_both({"relmse": relmse}, resampling=FAST)
    assert empty.empty and list(empty.columns) == study.BOTH_COLUMNS
    assert "Needs both relmse and dssim" in study.recommendations_both_markdown(empty)
    other = study.study_data(_from_orders(["ens18"], scenes=("a", "b"), metric="dssim"), "dssim")
    with pytest.raises(BenchError, match="different scenes"):
        study.recommendations_both({"relmse": relmse, "dssim": other})


def test_writer_writes_the_pair_and_both_metrics_tables(tmp_path):
    rng = np.random.default_rng(5)
    names = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "ens15", "ens20", "ens27"]
    rows = [(f"s{s}", spp, n, m, float(rng.uniform(0.1, 1.0))) for m in ("relmse", "dssim") for s in range(3)
            for spp in (4, 64) for n in names]
    rows += [(f"s{s}", spp, "noisy", m, 5.0) for m in ("relmse", "dssim") for s in range(3) for spp in (4, 64)]
    path = tmp_path / "metrics.csv"
    _tidy(rows).to_csv(path, index=False)
    out = tmp_path / "study"
    written = study.write_study_tables(str(path), out, metrics=("relmse", "dssim"), n_resamples=200, seed=1)
    declared = {Path(p).name for p in study.study_outputs(out, ("relmse", "dssim"))}
    assert {"pair_members.csv", "pair_members.md", "recommendations_metrics.csv",
            "recommendations_metrics.md"} <= declared
    assert {p.name for p in out.iterdir() if not p.name.endswith(".crc32")} == declared
    pairs = pd.read_csv(out / "pair_members.csv")
    assert set(pairs["ensemble"]) == {"ens10", "ens15"} and set(pairs["metric"]) == {"relmse", "dssim"}
    assert len(pairs) == 2 * 2 * 3 * 3          # metrics x pairs x (member, member, both) x (4, 64, all)
    both = pd.read_csv(out / "recommendations_metrics.csv")
    assert set(both["set"]) == {"all", "paper-named"} and both["combined"].notna().any()
    assert written["recommendations_metrics"].shape[0] == both.shape[0]
    summary = (out / "summary.md").read_text()
    assert "Recommendations by relMSE and DSSIM together" in summary and "ours, not the paper's" in summary
    assert "size-2 ensemble" in summary
    for name in declared:
        assert "nan" not in (out / name).read_text().lower().replace("nano", ""), name
