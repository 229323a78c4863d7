"""References you can trust: how the study's ranking moves when relMSE is corrected for the
reference's own noise (:func:`reference_noise_effect`)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from mcbench import BenchError
from mcbench.analysis.study.data import Resampling, StudyData
from mcbench.analysis.study.statistics import bootstrap_ci, is_real

__all__ = ["REFERENCE_NOISE_COLUMNS", "reference_noise_effect"]

REFERENCE_NOISE_COLUMNS = ["spp", "kendall_tau", "max_abs_change", "real_changes", "changed", "top_raw",
                           "top_corrected", "agree"]


def reference_noise_effect(raw: StudyData, corrected: StudyData, *, resampling: Resampling = Resampling(),
                           top: int = 3) -> pd.DataFrame:
    """How the ranking moves when relMSE is corrected for the reference's own noise
    (:func:`mcbench.analysis.metrics.relmse_corrected`), per spp and over all spp (``Avg.``).

    ``raw`` and ``corrected``: the two metrics' :class:`~mcbench.analysis.study.data.StudyData` over the same
    scenes, spp and entries. Per column: the Kendall tau of the two mean-score orderings, the largest change of
    a mean score, and the entries whose score changes *really* (the paired scene-bootstrap interval of corrected
    - raw per-scene score excludes 0, :func:`~mcbench.analysis.study.statistics.is_real`), with the ``top``
    entries of each ordering. ``agree`` is "yes" when no entry's score changes really: the raw ranking is then
    trustworthy within the intervals, i.e. the references are quiet enough for this study; "no" names the spp at
    which the reference noise reorders candidates. """
    if (raw.scenes, raw.spps, raw.names) != (corrected.scenes, corrected.spps, corrected.names):
        raise BenchError("reference noise: the raw and corrected relMSE cover different scenes, spp or entries")
    rows = []
    columns = [(str(s), [s]) for s in raw.spps] + [("Avg.", list(raw.spps))]
    for label, spps in columns:
        a, b = raw.scene_scores(spps), corrected.scene_scores(spps)          # (scenes, names)
        mean_a, mean_b = a.mean(axis=0), b.mean(axis=0)
        tau = stats.kendalltau(mean_a, mean_b).statistic if len(raw.names) > 1 else None
        cis = bootstrap_ci(b - a, resampling=resampling)
        changed = [n for n, low, high in zip(raw.names, cis["ci_low"], cis["ci_high"]) if is_real(low, high)]
        order_a = [raw.names[i] for i in np.argsort(-mean_a, kind="stable")[:top]]
        order_b = [raw.names[i] for i in np.argsort(-mean_b, kind="stable")[:top]]
        rows.append({"spp": label, "kendall_tau": None if tau is None or not np.isfinite(tau) else float(tau),
                     "max_abs_change": float(np.max(np.abs(mean_b - mean_a))), "real_changes": len(changed),
                     "changed": " ".join(changed), "top_raw": " ".join(order_a), "top_corrected": " ".join(order_b),
                     "agree": "yes" if not changed else "no"})
    return pd.DataFrame(rows, columns=REFERENCE_NOISE_COLUMNS)
