"""mcbench.analysis.study.writers: the declared files, written without NaN, absent metrics skipped."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mcbench import BenchError
from mcbench.analysis import pool
from mcbench.analysis.study.statistics import SCORE_CI_COLUMNS
from mcbench.analysis.study.writers import study_outputs, write_study_tables
from tests.analysis.study.synthetic import ALL, tidy


def test_writer_writes_the_declared_files_without_nan_and_skips_absent_metrics(tmp_path):
    rng = np.random.default_rng(4)
    quality = {n: rng.normal() for n in ALL}
    rows = [(f"s{s}", spp, n, "relmse", float(np.exp(-quality[n] + rng.normal(0, 0.3))))
            for s in range(4) for spp in (4, 64, 512) for n in ALL]
    rows += [(f"s{s}", spp, "noisy", "relmse", 100.0) for s in range(4) for spp in (4, 64, 512)]
    path = tmp_path / "metrics.csv"
    tidy(rows).to_csv(path, index=False)
    out = tmp_path / "study"
    write_study_tables(str(path), out, metrics=("relmse", "dssim"), n_resamples=300, seed=1)
    declared = {Path(p).name for p in study_outputs(out, ("relmse", "dssim"))}
    # every declared file, and besides them only their hidden checksum side files (mcbench.io.checksums)
    assert {p.name for p in out.iterdir() if not p.name.endswith(".crc32")} == declared
    assert {p.name for p in out.iterdir() if p.name.endswith(".crc32")} == {f".{name}.crc32" for name in declared}
    for name in declared:
        text = (out / name).read_text()
        assert "nan" not in text.lower().replace("nano", "") and "inf " not in text.lower(), name
    assert list(pd.read_csv(out / "scores_ci_dssim.csv").columns) == SCORE_CI_COLUMNS
    assert len(pd.read_csv(out / "scores_ci_dssim.csv")) == 0
    assert "dssim: no values" in (out / "summary.md").read_text()
    cis = pd.read_csv(out / "scores_ci_relmse.csv")
    assert len(cis) == 40 and (cis["avg_ci_low"] <= cis["avg"]).all() and (cis["avg"] <= cis["avg_ci_high"]).all()
    paper = pd.read_csv(out / "paper_table3.csv")
    assert set(paper["id"]) == set(pool.PAPER_TABLE3)
    broken = tidy(rows)
    broken = broken[~((broken["entry"] == "ens31") & (broken["scene"] == "s0") & (broken["spp"] == 64))]
    broken.to_csv(path, index=False)
    with pytest.raises(BenchError, match="ens31"):
        write_study_tables(str(path), out, metrics=("relmse",), n_resamples=100)


def test_writer_writes_the_pair_and_both_metrics_tables(tmp_path):
    rng = np.random.default_rng(5)
    names = ["kpcn", "nfor", "oidn", "rdfc", "ens10", "ens15", "ens20", "ens27"]
    rows = [(f"s{s}", spp, n, m, float(rng.uniform(0.1, 1.0))) for m in ("relmse", "dssim") for s in range(3)
            for spp in (4, 64) for n in names]
    rows += [(f"s{s}", spp, "noisy", m, 5.0) for m in ("relmse", "dssim") for s in range(3) for spp in (4, 64)]
    path = tmp_path / "metrics.csv"
    tidy(rows).to_csv(path, index=False)
    out = tmp_path / "study"
    written = write_study_tables(str(path), out, metrics=("relmse", "dssim"), n_resamples=200, seed=1)
    declared = {Path(p).name for p in study_outputs(out, ("relmse", "dssim"))}
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
