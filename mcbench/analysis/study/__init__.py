"""The 39-candidate study of Zheng et al. 2021, Sec. 5.3, checked with numbers.

Pure functions over the tidy metrics table (columns scene, spp, entry, metric, value), one
module per concern:

* :mod:`~mcbench.analysis.study.data` -- one metric's values and per-case scores on a full grid
  (:class:`~mcbench.analysis.study.data.StudyData`), the bootstrap's settings and shared constants;
* :mod:`~mcbench.analysis.study.statistics` -- the scene bootstrap: confidence intervals, real
  differences, place fractions, verdicts;
* :mod:`~mcbench.analysis.study.paper` -- our relMSE scores beside the paper's Table 3 and the
  Kendall tau of the two orderings (Sec. 5.3.3-5.3.4);
* :mod:`~mcbench.analysis.study.recommendations` -- the best ensemble by size, spp band and
  overall, beside the paper's (Sec. 5.3.5-5.3.6), per metric and relMSE with DSSIM together;
* :mod:`~mcbench.analysis.study.pair_members` -- finding (b) case by case: each size-2 ensemble
  against each member;
* :mod:`~mcbench.analysis.study.findings` -- the observations of Sec. 5.3.4 with a verdict each;
* :mod:`~mcbench.analysis.study.reference_noise` -- raw against reference-noise-corrected relMSE;
* :mod:`~mcbench.analysis.study.study_tables` -- every table of one metrics table, in memory;
* :mod:`~mcbench.analysis.study.markdown` -- the tables as Markdown and sentences, ``summary.md``;
* :mod:`~mcbench.analysis.study.writers` -- the files under ``results/tables/study/``;
* :mod:`~mcbench.analysis.study.scores_and_costs`, :mod:`~mcbench.analysis.study.equal_time` and
  :mod:`~mcbench.analysis.study.study_figures` -- the study's figures: their data and their plots.
"""
