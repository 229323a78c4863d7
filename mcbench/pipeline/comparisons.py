"""The work behind ``workflow/rules/comparisons.smk``: the comparison tables of Zheng et al. 2021
Sec. 5.2 -- Tables 1-2 (the ensemble against one-hot selection), the ablation table and the
comparison methods' ranking. The tables are built and written by
:mod:`mcbench.analysis.comparison_tables` (tables in, tables out); this module is the rules' entry point.
"""

from __future__ import annotations

from mcbench.analysis.comparison_tables import write_ablation_table, write_comparison_ranking, write_onehot_tables

__all__ = ["write_onehot_tables", "write_ablation_table", "write_comparison_ranking"]
