"""mcbench.analysis.study.markdown: summary.md from the tables in memory names the metrics skipped
and the metrics table, and lists each headline finding's verdict once."""

from __future__ import annotations

import numpy as np

from mcbench.analysis.study.markdown import summary_markdown
from mcbench.analysis.study.tables import study_tables
from tests.analysis.study.synthetic import FASTER, tidy


def test_summary_names_the_skipped_metric_and_every_headline_verdict():
    rng = np.random.default_rng(4)
    names = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "ens27", "noisy"]
    metrics = tidy([(f"s{s}", spp, n, "relmse", float(rng.uniform(0.1, 1.0)))
                    for s in range(3) for spp in (4, 64) for n in names])
    tables = study_tables(metrics, metrics=("relmse", "dssim"), resampling=FASTER)
    text = summary_markdown(tables, source="metrics_of_a_run.csv")
    assert "- dssim: no values in metrics_of_a_run.csv; skipped" in text
    assert "## Beside the paper's Table 3" in text and "- needs both relmse and dssim" in text
    findings = tables.findings
    headline = (findings["verdict"] != "") & ~((findings["finding"] == "b") & findings["quantity"].str.startswith("#"))
    listed = [line for line in text.split("## Findings")[1].splitlines() if line.startswith("- ")]
    assert len(listed) == headline.sum() > 0
    assert all(f"**{v}**" in line for v, line in zip(findings.loc[headline, "verdict"], listed))
