"""The work behind ``workflow/rules/study.smk``: the 39-candidate study's tables and figures
(Zheng et al. 2021 Sec. 5.3).
"""

from __future__ import annotations



from mcbench import NOISY
from mcbench.io.tables import read_json, read_table


def write_study(metrics_csv: str, out_dir: str, *, metrics: list[str], labels: dict[str, str],
                entries: list[str], n_resamples: int, seed: int, manifest_json: str | None = None) -> dict:
    """The 39-candidate study's tables (:func:`mcbench.analysis.study.writers.write_study_tables`) under ``out_dir``
    over ``entries`` (the candidates ranked and the noisy input):
    beside the paper's Table 3, recommendations, findings, bootstrap intervals, summary;
    ``summary.md`` ends with the provenance block of ``manifest_json`` (the run's
    ``results/manifest.json``, :mod:`mcbench.pipeline.provenance`) when given; each metric named by
    its declared label (``metrics/<name>.py``)."""
    from mcbench.analysis.study.writers import write_study_tables
    from mcbench.pipeline.registry import load_metrics

    provenance = None if manifest_json is None else read_json(manifest_json)
    metric_labels = {name: spec.label for name, spec in load_metrics(metrics).items()}
    return write_study_tables(metrics_csv, out_dir, metrics=list(metrics), labels=labels,
                              candidates=[e for e in entries if e != NOISY], noisy=NOISY,
                              n_resamples=n_resamples, seed=seed, provenance=provenance, metric_labels=metric_labels)


def recommended_names(recommendations_csv: str, metric: str) -> list[str]:
    """The ensembles the study recommends under ``metric`` (any scope), in the table's order; the
    relMSE ones when the table has none for ``metric`` (e.g. a metric the study did not rank)."""
    table = read_table(recommendations_csv)
    for chosen in (metric, "relmse"):
        rows = table[(table["metric"] == chosen) & table["ours"].notna()]
        if len(rows):
            return list(dict.fromkeys(str(n) for n in rows["ours"]))
    return []


def write_study_figures_of(metrics_csv: str, timings_csv: str, recommendations_csv: str, scores_ci_csv: str,
                           render_paths: list[str], paths: dict[str, str], *, metric: str, entries: list[str],
                           labels: dict[str, str], inputs: dict[str, list[str]]) -> None:
    """The study's figures for one metric (:func:`mcbench.analysis.study.study_figures.write_study_figures`) over
    ``entries`` (the candidates ranked and the noisy input): the
    bases and the ensembles the study recommends (``recommendations_csv``) as curves, the bootstrap
    intervals of ``scores_ci_csv`` on the size figure, render times from the renders' EXRs."""
    from mcbench.analysis.study.study_figures import curve_candidates, write_study_figures

    recommended = [n for n in recommended_names(recommendations_csv, metric) if n in entries]
    intervals = read_table(scores_ci_csv)
    ci = (intervals.rename(columns={"avg_ci_low": "ci_low", "avg_ci_high": "ci_high"})[["candidate", "ci_low", "ci_high"]]
          .dropna() if len(intervals) else None)
    write_study_figures(metrics_csv, timings_csv, render_paths, paths, metric=metric,
                        candidates=[e for e in entries if e != NOISY],
                        curves=[c for c in curve_candidates(recommended) if c in entries], recommended=recommended,
                        labels=labels, inputs=inputs, noisy=NOISY, ci=ci)
