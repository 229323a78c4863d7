"""mcbench.analysis.study.markdown: summary.md from the tables in memory names the metrics skipped
and the metrics table, and lists each headline finding's verdict once."""

from __future__ import annotations

import numpy as np

from mcbench.analysis.study.markdown import summary_markdown
from mcbench.analysis.study.study_tables import study_tables
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


MANIFEST = {"config_digest": "0123456789abcdef", "manifest_version": 1, "platform": "Linux",
            "git": {"commit": "a" * 40, "clean": False},
            "cpu": {"avx2": True, "avx512f": False, "family": "25", "logical_cores": 16, "model": "AMD EPYC 7763",
                    "model_number": "1", "vendor": "AuthenticAMD"},
            "versions": {"drjit": "1.5.0", "flip_evaluator": "1.7", "mcbench": "0.1.0", "mitsuba": "3.9.1",
                         "numpy": "2.4.6", "oidn": "2.5.1.0", "python": "3.11.7", "snakemake": "9.27.1",
                         "torch": "absent"}}


def test_summary_ends_with_the_provenance_block_and_keeps_the_rest(tmp_path):
    from mcbench.analysis.run_comparison import table_without_timing
    from mcbench.analysis.study.markdown import PROVENANCE_HEADING

    rng = np.random.default_rng(5)
    names = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "noisy"]
    metrics = tidy([(f"s{s}", spp, n, "relmse", float(rng.uniform(0.1, 1.0)))
                    for s in range(3) for spp in (4, 64) for n in names])
    tables = study_tables(metrics, metrics=("relmse",), resampling=FASTER)
    plain = summary_markdown(tables, source="metrics.csv")
    text = summary_markdown(tables, source="metrics.csv", provenance=MANIFEST)
    head, block = text.split(f"\n{PROVENANCE_HEADING}\n\n")
    assert head == plain                                    # the study's summary unchanged above it
    assert block.splitlines() == [
        f"- Commit: `{'a' * 40}` (uncommitted changes)",
        "- Config digest: `0123456789abcdef`",
        "- CPU: AMD EPYC 7763 (vendor AuthenticAMD, family 25, model 1); AVX2 yes, AVX-512F no; 16 logical cores",
        "- Versions: mcbench 0.1.0, Mitsuba 3.9.1, Dr.Jit 1.5.0, OIDN (pyoidn) 2.5.1.0, torch absent, NumPy 2.4.6, "
        "flip-evaluator 1.7, Snakemake 9.27.1, Python 3.11.7"]
    # two runs of one study on another commit and machine compare equal (tools/compare_runs.py)
    other = {**MANIFEST, "git": {"commit": "b" * 40, "clean": True}, "cpu": {**MANIFEST["cpu"], "model": "Xeon"}}
    (tmp_path / "a.md").write_text(text)
    (tmp_path / "b.md").write_text(summary_markdown(tables, source="metrics.csv", provenance=other))
    assert table_without_timing(tmp_path / "a.md") == table_without_timing(tmp_path / "b.md")
    # a manifest without git reads as such
    unknown = summary_markdown(tables, source="metrics.csv", provenance={**MANIFEST, "git": {"commit": "unknown",
                                                                                            "clean": "unknown"}})
    assert "- Commit: `unknown` (tree state unknown)" in unknown
