"""Every table of the 39-candidate study, computed in memory from the tidy metrics table
(:func:`study_tables`); :mod:`mcbench.analysis.study.writers` writes them to files."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from mcbench import NOISY
from mcbench.analysis import pool
from mcbench.analysis.study.data import Resampling, StudyData, is_pool_name, ranking_from, study_data
from mcbench.analysis.study.findings import FINDING_COLUMNS, findings
from mcbench.analysis.study.pair_members import PAIR_COLUMNS, pair_members
from mcbench.analysis.study.paper import PAPER_COLUMNS, paper_comparison, paper_kendall
from mcbench.analysis.study.recommendations import REC_COLUMNS, recommendations, recommendations_both
from mcbench.analysis.study.reference_noise import REFERENCE_NOISE_COLUMNS, reference_noise_effect
from mcbench.analysis.study.statistics import score_cis

__all__ = ["StudyTables", "display_labels", "study_tables"]


@dataclass(frozen=True)
class StudyTables:
    """The study's tables of one metrics table.

    ``metrics``: the metrics asked for, in order; ``skipped``: those without values in the
    table; ``data``: :class:`~mcbench.analysis.study.data.StudyData` by metric with values;
    ``labels``: the display label of every scored entry (:func:`display_labels`). The tables:
    ``scores_ci`` (:func:`~mcbench.analysis.study.statistics.score_cis` by metric with values),
    ``recommendations`` and ``findings`` and ``pair_members`` (one block per metric),
    ``recommendations_metrics`` (:func:`~mcbench.analysis.study.recommendations.recommendations_both`),
    ``relmse_ranking`` (:func:`~mcbench.analysis.study.data.ranking_from` of relMSE; ``None``
    without relMSE) with ``paper_table3`` and ``paper_kendall`` (``None`` without relMSE) beside
    the paper's Table 3, and ``reference_noise``
    (:func:`~mcbench.analysis.study.reference_noise.reference_noise_effect`; empty without both
    relmse and relmse_corrected); ``metric_labels``: how the text names each metric of
    ``metrics`` (its declared label, else its name).
    """

    metrics: tuple[str, ...]
    skipped: tuple[str, ...]
    resampling: Resampling
    data: dict[str, StudyData]
    labels: dict[str, str]
    scores_ci: dict[str, pd.DataFrame]
    recommendations: pd.DataFrame
    recommendations_metrics: pd.DataFrame
    findings: pd.DataFrame
    pair_members: pd.DataFrame
    relmse_ranking: pd.DataFrame | None
    paper_table3: pd.DataFrame
    paper_kendall: pd.DataFrame | None
    reference_noise: pd.DataFrame
    metric_labels: dict[str, str]

    def by_stem(self) -> dict[str, pd.DataFrame]:
        """The tables by the stem of the file each is written to (``scores_ci_<metric>`` only
        for the metrics with values)."""
        return {**{f"scores_ci_{m}": t for m, t in self.scores_ci.items()}, "reference_noise": self.reference_noise,
                "paper_table3": self.paper_table3, "recommendations": self.recommendations,
                "findings": self.findings, "pair_members": self.pair_members,
                "recommendations_metrics": self.recommendations_metrics}


def display_labels(names, labels: dict[str, str] | None) -> dict[str, str]:
    """The label shown for each of ``names``: ``labels``' when given there, else the pool's,
    ``"noisy input"`` for the noisy input, the name itself otherwise."""
    labels = dict(labels or {})
    return {n: labels.get(n) or (pool.candidate(n).label if is_pool_name(n) else ("noisy input" if n == NOISY else n))
            for n in names}


def study_tables(table: pd.DataFrame, *, metrics=("relmse", "dssim"), labels: dict[str, str] | None = None,
                 candidates=None, noisy: str | None = NOISY, resampling: Resampling = Resampling(),
                 source: str = "metrics", metric_labels: dict[str, str] | None = None) -> StudyTables:
    """The study's tables of the tidy metrics ``table`` (columns scene, spp, entry, metric,
    value) for each of ``metrics``; a metric without values in ``table`` is skipped.
    ``candidates`` (default: the pool candidates present) and ``noisy`` are the scored entries;
    a pool candidate missing in a case stops with a :class:`mcbench.BenchError` naming it and
    ``source``. ``metric_labels`` {metric: label}: how the Markdown names the metrics."""
    available = set(table["metric"])
    data, cis, recs, finds, pairs, skipped = {}, {}, [], [], [], []
    for metric in metrics:
        if metric not in available:
            skipped.append(metric)
            continue
        found = study_data(table, metric, candidates=candidates, noisy=noisy, source=source)
        data[metric] = found
        cis[metric] = score_cis(found, resampling=resampling)
        recs.append(recommendations(found, resampling=resampling))
        finds.append(findings(found, resampling=resampling))
        pairs.append(pair_members(found, resampling=resampling))
    names = sorted({n for d in data.values() for n in d.names})
    ranking = ranking_from(data["relmse"]) if "relmse" in data else None
    if "relmse" in data and "relmse_corrected" in data:
        noise = reference_noise_effect(data["relmse"], data["relmse_corrected"], resampling=resampling)
    else:
        noise = pd.DataFrame(columns=REFERENCE_NOISE_COLUMNS)
    return StudyTables(
        metrics=tuple(metrics), skipped=tuple(skipped), resampling=resampling, data=data,
        labels=display_labels(names, labels), scores_ci=cis,
        recommendations=pd.concat(recs, ignore_index=True) if recs else pd.DataFrame(columns=REC_COLUMNS),
        recommendations_metrics=recommendations_both(data, resampling=resampling),
        findings=pd.concat(finds, ignore_index=True) if finds else pd.DataFrame(columns=FINDING_COLUMNS),
        pair_members=pd.concat([t for t in pairs if len(t)], ignore_index=True) if any(len(t) for t in pairs)
        else pd.DataFrame(columns=PAIR_COLUMNS),
        relmse_ranking=ranking,
        paper_table3=paper_comparison(ranking) if ranking is not None else pd.DataFrame(columns=PAPER_COLUMNS),
        paper_kendall=paper_kendall(ranking) if ranking is not None else None,
        reference_noise=noise, metric_labels={m: (metric_labels or {}).get(m, m) for m in metrics})
