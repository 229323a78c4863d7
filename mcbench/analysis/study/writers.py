"""The study's files: :func:`write_study_tables` computes every table of a metrics CSV
(:func:`mcbench.analysis.study.study_tables.study_tables`) and :func:`write_study_files` writes them,
CSV and Markdown, atomically (:mod:`mcbench.io.tables`), with ``summary.md``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from mcbench import METRICS_COLUMNS, NOISY
from mcbench.analysis.study.data import CONFIDENCE, N_RESAMPLES, SEED, Resampling
from mcbench.analysis.study.markdown import (NO_RELMSE_MARKDOWN, findings_markdown, pair_members_markdown,
                                             paper_comparison_markdown, recommendations_both_markdown,
                                             recommendations_markdown, reference_noise_markdown, summary_markdown)
from mcbench.analysis.study.statistics import SCORE_CI_COLUMNS
from mcbench.analysis.study.study_tables import StudyTables, study_tables
from mcbench.io.tables import read_table, write_csv, write_text

__all__ = ["STUDY_FILES", "study_outputs", "write_study_files", "write_study_tables"]

STUDY_FILES = ("paper_table3.csv", "paper_table3.md", "recommendations.csv", "recommendations.md",
               "recommendations_metrics.csv", "recommendations_metrics.md", "findings.csv", "findings.md",
               "pair_members.csv", "pair_members.md", "reference_noise.csv", "reference_noise.md", "summary.md")


def study_outputs(out_dir, metrics) -> list[str]:
    """Every file :func:`write_study_tables` writes under ``out_dir``: :data:`STUDY_FILES` and
    ``scores_ci_<metric>.csv`` per metric of ``metrics`` (written, header only, for a metric
    absent from the data, so a rule can declare the list)."""
    return [str(Path(out_dir) / f) for f in STUDY_FILES] + [str(Path(out_dir) / f"scores_ci_{m}.csv") for m in metrics]


def write_study_files(tables: StudyTables, out_dir, *, source: str, provenance: dict | None = None) -> None:
    """Write ``tables`` under ``out_dir`` (:func:`study_outputs`; CSV numbers with four decimals,
    an absent table as its header only); ``source``: the metrics table's file name, named in
    ``summary.md``; ``provenance``: the run's manifest, whose short block ends ``summary.md``."""
    out_dir = Path(out_dir)
    shown, resampling = tables.labels, tables.resampling
    for metric in tables.metrics:
        path = out_dir / f"scores_ci_{metric}.csv"
        if metric in tables.scores_ci:
            write_csv(path, tables.scores_ci[metric][SCORE_CI_COLUMNS], float_format="%.4f")
        else:
            write_csv(path, pd.DataFrame(columns=SCORE_CI_COLUMNS))
    write_csv(out_dir / "recommendations.csv", tables.recommendations, float_format="%.4f")
    metric_labels = tables.metric_labels
    write_text(out_dir / "recommendations.md", recommendations_markdown(tables.recommendations, labels=shown,
                                                                        resampling=resampling,
                                                                        metric_labels=metric_labels))
    write_csv(out_dir / "findings.csv", tables.findings, float_format="%.4f")
    write_text(out_dir / "findings.md", findings_markdown(tables.findings, resampling=resampling,
                                                                  metric_labels=metric_labels))
    write_csv(out_dir / "pair_members.csv", tables.pair_members, float_format="%.4f")
    skipped = {m: "no values; skipped" for m in tables.skipped}
    write_text(out_dir / "pair_members.md", pair_members_markdown(tables.pair_members, labels=shown,
                                                                  resampling=resampling, skipped=skipped,
                                                                  metric_labels=metric_labels))
    write_csv(out_dir / "recommendations_metrics.csv", tables.recommendations_metrics, float_format="%.4f")
    write_text(out_dir / "recommendations_metrics.md", recommendations_both_markdown(
        tables.recommendations_metrics, labels=shown, resampling=resampling))
    if tables.relmse_ranking is not None:
        write_csv(out_dir / "paper_table3.csv", tables.paper_table3, float_format="%.4f")
        write_text(out_dir / "paper_table3.md", paper_comparison_markdown(tables.relmse_ranking, labels=shown,
                                                                          entries=tables.data["relmse"].entries))
    else:
        write_csv(out_dir / "paper_table3.csv", tables.paper_table3)
        write_text(out_dir / "paper_table3.md", NO_RELMSE_MARKDOWN)
    write_csv(out_dir / "reference_noise.csv", tables.reference_noise, float_format="%.4f")
    write_text(out_dir / "reference_noise.md", reference_noise_markdown(tables.reference_noise, labels=shown,
                                                                        resampling=resampling))
    write_text(out_dir / "summary.md", summary_markdown(tables, source=source, provenance=provenance))


def write_study_tables(metrics_csv, out_dir, *, metrics=("relmse", "dssim"), labels: dict[str, str] | None = None,
                       candidates=None, noisy: str | None = NOISY, n_resamples: int = N_RESAMPLES, seed: int = SEED,
                       confidence: float = CONFIDENCE, provenance: dict | None = None,
                       metric_labels: dict[str, str] | None = None) -> dict[str, pd.DataFrame]:
    """The study's tables from ``metrics.csv``, written atomically under ``out_dir``
    (``results/tables/study/``). Files (:func:`study_outputs`):

    * ``paper_table3.csv`` (:func:`mcbench.analysis.study.paper.paper_comparison`: id, candidate, spp, ours, paper,
      difference, note; relMSE) and ``paper_table3.md`` (with the Kendall taus, the scale note);
    * ``recommendations.csv`` (:data:`mcbench.analysis.study.recommendations.REC_COLUMNS`, one block per metric) and
      ``recommendations.md`` (table and sentences);
    * ``recommendations_metrics.csv`` (:func:`mcbench.analysis.study.recommendations.recommendations_both`) and
      ``.md``: relMSE's and DSSIM's picks side by side and our combined pick;
    * ``findings.csv`` (:data:`mcbench.analysis.study.findings.FINDING_COLUMNS`) and ``findings.md``;
    * ``pair_members.csv`` (:func:`mcbench.analysis.study.pair_members.pair_members`, one block per metric)
      and ``.md``: finding (b), each size-2 ensemble against each member, per spp and overall;
    * ``scores_ci_<metric>.csv`` per metric of ``metrics`` (:func:`mcbench.analysis.study.statistics.score_cis`:
      :data:`~mcbench.analysis.study.statistics.SCORE_CI_COLUMNS`);
    * ``summary.md``: the sentences, the Kendall tau, the verdicts, the metrics skipped, and
      the short block of ``provenance`` (the run's ``results/manifest.json``) when given.

    ``metrics`` absent from the data are skipped (their CSV holds the header only, summary.md
    says so); a pool candidate missing in a case stops with a :class:`mcbench.BenchError`
    naming it. ``candidates`` (default: the pool candidates present) and ``noisy`` are the
    scored entries; ``metric_labels`` {metric: label} name the metrics in the Markdown (default:
    their names). Returns the tables by file stem.
    """
    table = read_table(metrics_csv, columns=METRICS_COLUMNS)
    resampling = Resampling(n_resamples=n_resamples, seed=seed, confidence=confidence)
    tables = study_tables(table, metrics=metrics, labels=labels, candidates=candidates, noisy=noisy,
                          resampling=resampling, source=str(metrics_csv), metric_labels=metric_labels)
    write_study_files(tables, out_dir, source=Path(metrics_csv).name, provenance=provenance)
    return tables.by_stem()
