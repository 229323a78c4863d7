"""mcbench.analysis.study.study_tables: every table of a metrics table in memory, the metrics without
values skipped, the relMSE-only and relMSE-with-corrected tables present exactly when their
metrics are."""

from __future__ import annotations

import numpy as np

from mcbench.analysis.study.findings import FINDING_COLUMNS
from mcbench.analysis.study.paper import PAPER_COLUMNS
from mcbench.analysis.study.reference_noise import REFERENCE_NOISE_COLUMNS
from mcbench.analysis.study.study_tables import display_labels, study_tables
from tests.analysis.study.synthetic import FASTER, tidy

NAMES = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "ens27"]


def _metrics(metrics):
    rng = np.random.default_rng(8)
    return tidy([(f"s{s}", spp, n, m, float(rng.uniform(0.1, 1.0))) for m in metrics for s in range(3)
                 for spp in (4, 64) for n in NAMES + ["noisy"]])


def test_tables_of_relmse_and_dssim_skip_an_absent_metric():
    tables = study_tables(_metrics(("relmse", "dssim")), metrics=("relmse", "smape", "dssim"),
                          labels={"ens27": "mine"}, resampling=FASTER)
    assert tables.metrics == ("relmse", "smape", "dssim") and tables.skipped == ("smape",)
    assert list(tables.data) == ["relmse", "dssim"] and list(tables.scores_ci) == ["relmse", "dssim"]
    assert set(tables.recommendations["metric"]) == set(tables.findings["metric"]) == {"relmse", "dssim"}
    assert len(tables.recommendations_metrics) > 0             # both relmse and dssim: the combined pick
    assert tables.relmse_ranking is not None and list(tables.paper_table3.columns) == PAPER_COLUMNS
    assert tables.paper_table3["ours"].notna().any() and tables.paper_kendall is not None
    assert tables.reference_noise.empty and list(tables.reference_noise.columns) == REFERENCE_NOISE_COLUMNS
    assert tables.labels["ens27"] == "mine" and tables.labels["noisy"] == "noisy input"
    assert tables.labels["ens10"] == display_labels(["ens10"], None)["ens10"] != "ens10"
    assert list(tables.by_stem()) == ["scores_ci_relmse", "scores_ci_dssim", "reference_noise", "paper_table3",
                                      "recommendations", "findings", "pair_members", "recommendations_metrics"]


def test_tables_without_relmse_and_with_the_corrected_relmse():
    dssim = study_tables(_metrics(("dssim",)), metrics=("relmse", "dssim"), resampling=FASTER)
    assert dssim.skipped == ("relmse",) and dssim.relmse_ranking is None and dssim.paper_kendall is None
    assert dssim.paper_table3.empty and dssim.recommendations_metrics.empty
    none = study_tables(_metrics(("dssim",)), metrics=("relmse",), resampling=FASTER)
    assert none.data == {} and none.recommendations.empty
    assert list(none.findings.columns) == FINDING_COLUMNS and none.pair_members.empty
    both = study_tables(_metrics(("relmse", "relmse_corrected")), metrics=("relmse", "relmse_corrected"),
                        resampling=FASTER)
    assert list(both.reference_noise["spp"]) == ["4", "64", "Avg."]
