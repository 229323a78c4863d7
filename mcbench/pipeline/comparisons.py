"""The work behind ``workflow/rules/comparisons.smk``: the comparison tables of Zheng et al. 2021
Sec. 5.2 -- Tables 1-2 (the ensemble against one-hot selection), the ablation table and the
comparison methods' ranking. The tables are built and written by
:mod:`mcbench.analysis.comparison_tables` (tables in, tables out); this module is the rules' entry point.
"""

from __future__ import annotations

from mcbench.analysis import comparison_tables
from mcbench.analysis.comparison_tables import write_ablation_table
from mcbench.pipeline.registry import load_metric

__all__ = ["write_onehot_tables", "write_ablation_table", "write_comparison_ranking"]


def write_onehot_tables(metrics_csv: str, metric: str, **kwargs):
    """Tables 1 and 2 for ``metric`` (:func:`mcbench.analysis.comparison_tables.write_onehot_tables`), the
    metric named by its declared label (``metrics/<metric>.py``)."""
    return comparison_tables.write_onehot_tables(metrics_csv, metric, metric_label=load_metric(metric).label, **kwargs)


def write_comparison_ranking(metrics_csv: str, metric: str, **kwargs):
    """The comparison methods' ranking for ``metric`` (:func:`mcbench.analysis.comparison_tables.write_comparison_ranking`),
    the metric named by its declared label (``metrics/<metric>.py``)."""
    return comparison_tables.write_comparison_ranking(metrics_csv, metric, metric_label=load_metric(metric).label, **kwargs)
