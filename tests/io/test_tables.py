"""mcbench.io.tables.read_table: a table lacking a column it is asked for is refused naming the
file; a metrics table whose entries are headed ``candidate`` (an earlier mcbench's header) says so."""

from __future__ import annotations

import pandas as pd
import pytest

from mcbench import METRICS_COLUMNS, BenchError
from mcbench.io.tables import read_table, write_csv


def test_a_metrics_table_with_the_column_candidate_is_refused_naming_it(tmp_path):
    rows = {"scene": ["s"], "spp": [4], "candidate": ["noisy"], "metric": ["relmse"], "value": [0.5]}
    path = tmp_path / "spp4.csv"
    write_csv(path, pd.DataFrame(rows))
    with pytest.raises(BenchError, match=r"spp4.csv: missing column\(s\) entry; it has 'candidate' \(now 'entry'\)"
                                         r".*snakemake -f .*spp4.csv"):
        read_table(path, columns=METRICS_COLUMNS)


def test_a_metrics_table_reads_with_its_columns(tmp_path):
    path = tmp_path / "spp4.csv"
    write_csv(path, pd.DataFrame({"scene": ["s"], "spp": [4], "entry": ["noisy"], "metric": ["relmse"],
                                  "value": [0.5]}))
    assert list(read_table(path, columns=METRICS_COLUMNS).columns) == list(METRICS_COLUMNS)
    with pytest.raises(BenchError, match=r"spp4.csv: missing column\(s\) seconds$"):
        read_table(path, columns=("seconds",))
