"""Score-and-rank analysis of Zheng et al. 2021, Sec. 5.3.3.

For every test case (scene, spp) all candidates together with the noisy input are sorted by
error and given linearly spaced scores: the best of K entries gets K, the worst gets 1, and
ties share the mean of the scores they span (``scipy.stats.rankdata(..., method="average")``).
Scores are averaged across scenes per spp, then across spp for the overall column ``Avg.``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import rankdata

__all__ = ["case_scores", "ranking_table", "format_markdown"]


def case_scores(metrics: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per-case scores from a tidy table with columns scene, spp, candidate, metric, value.

    Returns columns scene, spp, candidate, score. Lower error => higher score.
    A case missing some candidate is scored over the entries it has.
    """
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        raise ValueError(f"no values for metric '{metric}'")
    out = []
    for (scene, spp), case in rows.groupby(["scene", "spp"], sort=True):
        scores = rankdata(-case["value"].to_numpy(dtype=np.float64), method="average")
        out.append(pd.DataFrame({"scene": scene, "spp": spp,
                                 "candidate": case["candidate"].to_numpy(), "score": scores}))
    return pd.concat(out, ignore_index=True)


def ranking_table(metrics: pd.DataFrame, metric: str, order: list[str] | None = None) -> pd.DataFrame:
    """Table 3 of the paper: rows candidates, columns spp (mean score over scenes) and ``Avg.``
    (mean over spp). ``order`` fixes the row order (default: by overall score, best first)."""
    scores = case_scores(metrics, metric)
    per_spp = scores.groupby(["candidate", "spp"])["score"].mean().unstack("spp")
    per_spp = per_spp.reindex(columns=sorted(per_spp.columns))
    per_spp.columns = [str(c) for c in per_spp.columns]
    per_spp["Avg."] = per_spp.mean(axis=1)
    if order is None:
        per_spp = per_spp.sort_values("Avg.", ascending=False)
    else:
        per_spp = per_spp.reindex([c for c in order if c in per_spp.index])
    per_spp.index.name = "candidate"
    return per_spp


def format_markdown(table: pd.DataFrame, labels: dict[str, str] | None = None, digits: int = 1) -> str:
    """Markdown rendering of a ranking table; the best score of each column is bold."""
    labels = labels or {}
    shown = table.copy()
    best = table.max(axis=0)
    for column in table.columns:
        shown[column] = [f"**{v:.{digits}f}**" if np.isclose(v, best[column]) else f"{v:.{digits}f}"
                         for v in table[column]]
    shown.index = [labels.get(c, c) for c in table.index]
    shown.index.name = "candidate"
    return shown.to_markdown()
