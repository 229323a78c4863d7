"""Layer ``analysis``: tables in, tables and figures out.

Metrics (:mod:`~mcbench.analysis.metrics`), the score-and-rank analysis
(:mod:`~mcbench.analysis.ranking`), the 39-candidate pool (:mod:`~mcbench.analysis.pool`) and
study (:mod:`~mcbench.analysis.study`: its tables and figures), the Sec. 5.2
comparisons (:mod:`~mcbench.analysis.comparison_tables`), figures, the image viewer, scene reports and
progressive denoising's tables.
"""
