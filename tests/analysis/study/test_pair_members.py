"""mcbench.analysis.study.pair_members: finding (b) case by case (Zheng et al. 2021 Sec. 5.3.4), on
hand-made tables whose answers are counted by hand."""

from __future__ import annotations


import pandas as pd
import pytest

from mcbench.analysis import pool
from mcbench.analysis.study.data import study_data
from mcbench.analysis.study.statistics import INCONCLUSIVE, NOT_REPRODUCED, REPRODUCED
from mcbench.analysis.study.pair_members import PAIR_COLUMNS, pair_members
from mcbench.analysis.study.findings import findings
from mcbench.analysis.study.markdown import pair_members_markdown
from tests.analysis.study.synthetic import FASTER, SIZE2, tidy


def _finding(table, prefix):
    rows = table[(table["finding"] == "b") & table["quantity"].str.startswith(prefix)]
    assert len(rows) == 1, (prefix, list(table.loc[table["finding"] == "b", "quantity"]))
    return rows.iloc[0]


def test_the_pool_holds_eight_size_2_ensembles_and_115_member_comparisons():
    # hand count of pool.py: #9-#16 pairs, #17-#24 triples, #25-#31 quads, #32-#34 fives, #35-#38 sixes, #39 all 8
    assert [c.name for c in pool.POOL if not c.is_base and c.size == 2] == SIZE2
    assert sum(c.size for c in pool.POOL if not c.is_base) == 8 * 2 + 8 * 3 + 7 * 4 + 3 * 5 + 4 * 6 + 8 == 115


def test_pair_members_counts_wins_per_spp_and_names_the_failing_cases():
    # bases kpcn (#1), nfor (#4), rdfc (#8); pairs ens10 {1,4}, ens11 {1,8}; scenes a, b, c; spp 4, 64
    names = ["kpcn", "nfor", "rdfc", "ens10", "ens11"]
    errors = {("a", 4): {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 2.0, "ens11": 0.5},
              ("b", 4): {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 0.9, "ens11": 1.0},   # ens11 ties kpcn
              ("c", 4): {"kpcn": 1.0, "nfor": 3.0, "rdfc": 2.0, "ens10": 0.9, "ens11": 0.5}}
    errors.update({(s, 64): {"kpcn": 2.0, "nfor": 1.0, "rdfc": 3.0, "ens10": 0.5, "ens11": 0.5} for s in "abc"})
    rows = [(s, spp, n, "dssim", v) for (s, spp), case in errors.items() for n, v in case.items()]
    rows += [(s, spp, "noisy", "dssim", 9.0) for s, spp in errors]
    data = study_data(tidy(rows), "dssim", candidates=names)
    table = pair_members(data, resampling=FASTER).set_index(["ensemble", "member", "spp"])
    assert list(table.columns) == [c for c in PAIR_COLUMNS if c not in ("ensemble", "member", "spp")]
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
    assert table.loc[("ens10", "nfor", "all"), "verdict"] == REPRODUCED
    assert table.loc[("ens10", "nfor", "all"), "ci_low"] == 1.0
    assert set(table["verdict"]) <= {REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE}
    text = pair_members_markdown(table.reset_index())
    assert "| #10 KPCN+NFOR | #1 KPCN† | 2/3 | 3/3 | 5/6 | 0.833 |" in text
    assert "does not outperform #1 KPCN† in: a@4" in text and "nan" not in text.lower()
    # the findings agree with the table: (b)'s deciding row is the mean over scenes of the per-scene
    # fraction of comparisons won. 4 spp: a 3/4 (ens10 loses to kpcn), b 3/4 (ens11's tie with kpcn),
    # c 4/4; 64 spp 4/4 everywhere -> per scene 7/8, 7/8, 1 -> mean 22/24
    decision = _finding(findings(data, resampling=FASTER), "all spp: fraction of (case, size-2 ensemble, member)")
    assert decision["estimate"] == pytest.approx(22 / 24)
