"""mcbench.analysis.study.paper: our ranking beside the paper's Table 3, typed from the paper, and
Kendall's tau against brute-force pair counts."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
import pytest

from mcbench.analysis import pool
from mcbench.analysis.study.paper import PAPER_TABLE3_BASES, paper_comparison, paper_kendall
from mcbench.analysis.study.markdown import paper_comparison_markdown


def _paper_like_ranking(spps=pool.PAPER_TABLE3_SPP, drop=()):
    """Ours = the paper's value + 1 (typed independently below), for every Table 3 candidate."""
    table = pd.DataFrame({str(s): [pool.PAPER_TABLE3[c][s] + 1.0 for c in pool.PAPER_TABLE3] for s in spps},
                         index=[pool.candidate_name(c) for c in pool.PAPER_TABLE3])
    table["Avg."] = table.mean(axis=1)
    return table.drop(index=list(drop))


def test_paper_side_reads_the_papers_table3():
    table = paper_comparison(_paper_like_ranking()).set_index(["id", "spp"])
    assert table.loc[(33, "Avg."), "paper"] == 29.0
    assert table.loc[(24, "4"), "paper"] == 28.6
    assert table.loc[(8, "1024"), "paper"] == 18.1
    assert table.loc[(3, "64"), "paper"] == 7.8
    assert table.loc[(24, "4"), "ours"] == pytest.approx(29.6)
    assert table.loc[(24, "4"), "difference"] == pytest.approx(1.0)
    assert sorted({i for i, _ in table.index}) == [1, 3, 4, 6, 7, 8, 16, 24, 30, 33, 35]


def test_paper_side_handles_missing_spp_and_candidates_honestly():
    ranking = _paper_like_ranking(spps=(4, 8), drop=["ens33"])
    table = paper_comparison(ranking).set_index(["id", "spp"])
    assert pd.isna(table.loc[(1, "16"), "ours"]) and pd.isna(table.loc[(1, "16"), "difference"])
    assert table.loc[(1, "16"), "note"] == "spp not in our data"
    assert table.loc[(1, "Avg. (common spp)"), "paper"] == pytest.approx((16.5 + 15.0) / 2)
    assert table.loc[(1, "Avg. (common spp)"), "ours"] == pytest.approx((17.5 + 16.0) / 2)
    assert "over 4–1024" in table.loc[(1, "Avg."), "note"]
    assert pd.isna(table.loc[(33, "4"), "ours"]) and "not in our ranking" in table.loc[(33, "4"), "note"]
    text = paper_comparison_markdown(ranking)
    assert "not on the same scale" in text and "nan" not in text.lower()
    assert "same scale" in paper_comparison_markdown(ranking, entries=40)
    assert "not on the same scale" not in paper_comparison_markdown(ranking, entries=40)


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
    found = paper_kendall(ranking).set_index("basis")
    assert found.loc["Avg.", "n"] == 11
    assert found.loc["Avg.", "tau"] == pytest.approx(_brute_tau(ours, paper))
    assert 0.0 < found.loc["Avg.", "p_value"] <= 1.0
    common = [pool.PAPER_TABLE3[c][4] for c in pool.PAPER_TABLE3]
    assert found.loc["Avg. (common spp)", "tau"] == pytest.approx(_brute_tau(ours, common))
    # the bases alone: the six rows of IDs <= 8, nothing else
    bases = [i for i, c in enumerate(pool.PAPER_TABLE3) if c <= 8]
    assert PAPER_TABLE3_BASES == (1, 3, 4, 6, 7, 8)
    found = paper_kendall(ranking, ids=PAPER_TABLE3_BASES).set_index("basis")
    assert found.loc["Avg.", "n"] == 6
    assert found.loc["Avg.", "tau"] == pytest.approx(_brute_tau([ours[i] for i in bases], [paper[i] for i in bases]))
    assert "among its bases alone (IDs 1, 3, 4, 6, 7, 8), by Avg.: tau = " \
        f"{found.loc['Avg.', 'tau']:.3f}" in paper_comparison_markdown(ranking)
