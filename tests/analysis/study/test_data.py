"""mcbench.analysis.study.data: the study's scores on a full grid, checked against the ranking table."""

from __future__ import annotations


import numpy as np
import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.analysis.ranking import ranking_table
from mcbench.analysis.study.data import ranking_from, study_data
from tests.analysis.study.synthetic import ALL, tidy


def test_avg_is_the_ranking_tables_avg_and_a_missing_candidate_is_named():
    rng = np.random.default_rng(1)
    rows = [(f"s{s}", spp, n, "relmse", float(rng.uniform(0.1, 1.0)))
            for s in range(3) for spp in (4, 8, 16) for n in ALL + ["noisy"]]
    metrics = tidy(rows)
    data = study_data(metrics, "relmse")
    assert data.entries == 40 and data.names[-1] == "noisy"
    ours = ranking_from(data)
    theirs = ranking_table(metrics, "relmse")
    pd.testing.assert_series_equal(ours["Avg."].sort_index(), theirs["Avg."].sort_index(), check_exact=False)
    dropped = metrics[~((metrics["scene"] == "s1") & (metrics["spp"] == 8) & (metrics["entry"] == "ens27"))]
    with pytest.raises(BenchError, match="ens27"):
        study_data(dropped, "relmse", source="metrics.csv")
    no_spp = metrics[~((metrics["scene"] == "s2") & (metrics["spp"] == 16))]
    with pytest.raises(BenchError, match="s2"):
        study_data(no_spp, "relmse")
