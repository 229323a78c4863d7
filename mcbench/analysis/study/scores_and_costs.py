"""The data of the study's score and speed figures (Zheng et al. 2021 Fig. 14 c, d): scores per
spp and overall, by ensemble size, and each candidate's total compute cost with the Pareto front.

Inputs are the workflow's tidy tables:

* ``scores``: :func:`mcbench.analysis.ranking.case_scores` output, columns ``scene, spp, entry,
  score`` (score K for the best of K entries of a case, 1 for the worst; higher is better);
* ``timings``: columns ``scene, spp, method, seconds`` (``results/timings.csv``; compute seconds
  of one method run, I/O excluded).

Every function returns tables without NaN or Inf.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench.analysis.error_speed_figures import combined_seconds, input_closure

__all__ = ["select_rows", "score_curves", "average_scores", "candidate_sizes", "score_size_points",
           "score_size_summary", "closure_seconds", "own_seconds", "pareto_front", "speed_score_points"]


def select_rows(frame: pd.DataFrame, column: str, names) -> pd.DataFrame:
    """The rows of ``frame`` whose ``column`` is one of ``names`` (all rows when ``names`` is
    ``None``); raises ``ValueError`` naming the names without a row."""
    if names is None:
        return frame
    missing = [name for name in names if name not in set(frame[column])]
    if missing:
        raise ValueError(f"no rows for {', '.join(map(str, missing))} (column '{column}')")
    return frame[frame[column].isin(list(names))]


def score_curves(scores: pd.DataFrame, *, candidates: list[str] | None = None) -> pd.DataFrame:
    """Mean score over scenes per spp (Fig. 14 c): index spp (ascending int), one column per
    candidate (``candidates`` in their order, or all in order of first appearance). Scores are
    unitless (K for the best of K entries of a case)."""
    rows = select_rows(scores, "entry", candidates)
    if rows.empty:
        raise ValueError("no scores to average")
    order = list(candidates) if candidates is not None else list(dict.fromkeys(rows["entry"]))
    table = rows.groupby(["spp", "entry"])["score"].mean().unstack("entry")
    if table.isna().to_numpy().any():
        lacking = table.columns[table.isna().any()].tolist()
        raise ValueError(f"candidate(s) {lacking} lack scores at some spp")
    table = table[order].sort_index()
    table.index = table.index.astype(int)
    table.columns.name = None
    return table


def average_scores(scores: pd.DataFrame) -> pd.Series:
    """Overall score ``Avg.`` of every candidate (Fig. 14 d, Table 3's last column): the mean
    over spp of the mean over scenes, as :func:`mcbench.analysis.ranking.ranking_table`. A Series named
    ``score`` indexed by candidate, best first (stable on ties)."""
    averages = score_curves(scores).mean(axis=0)
    averages = averages.sort_values(ascending=False, kind="stable")
    averages.index.name = "candidate"
    return averages.rename("score")


def candidate_sizes(names, *, sizes: dict[str, int] | None = None) -> dict[str, int]:
    """Ensemble size (number of base denoisers) of each name: from ``sizes`` when given there,
    else from the candidate pool (:mod:`mcbench.analysis.pool`; 1 for a base, DC variants included).
    Names in neither (the noisy input, comparison methods) are left out."""
    from mcbench.analysis.pool import PoolError, candidate

    found = {}
    for name in names:
        if sizes and name in sizes:
            found[name] = int(sizes[name])
            continue
        try:
            found[name] = candidate(name).size
        except PoolError:
            continue
    return found


def score_size_points(scores: pd.DataFrame, *, sizes: dict[str, int] | None = None) -> pd.DataFrame:
    """Each sized candidate's ``Avg.`` score against its ensemble size: index candidate (best
    first), columns ``size`` (int) and ``score``. Candidates without a size
    (:func:`candidate_sizes`: the noisy input) are left out."""
    averages = average_scores(scores)
    known = candidate_sizes(averages.index, sizes=sizes)
    if not known:
        raise ValueError("no candidate with a known ensemble size among the scores")
    names = [name for name in averages.index if name in known]
    frame = pd.DataFrame({"size": [known[n] for n in names], "score": averages[names].to_numpy(np.float64)},
                         index=pd.Index(names, name="candidate"))
    return frame


def score_size_summary(points: pd.DataFrame) -> pd.DataFrame:
    """Per ensemble size: ``n`` candidates, ``mean``, ``std`` (sample standard deviation over the
    candidates of that size, 0 for a single one), ``min``, ``max`` of their ``Avg.`` scores.
    Index ``size`` ascending."""
    grouped = points.groupby("size")["score"]
    summary = pd.DataFrame({"n": grouped.size(), "mean": grouped.mean(), "std": grouped.std(ddof=1).fillna(0.0),
                            "min": grouped.min(), "max": grouped.max()}).sort_index()
    summary.index = summary.index.astype(int)
    return summary


# --------------------------------------------------------------------------- costs


def closure_seconds(own: dict[str, float], inputs: dict[str, list[str]], *,
                    names: list[str] | None = None) -> dict[str, float]:
    """Total cost of each method (seconds per case) of ``names`` (default: all of ``own``):
    :func:`mcbench.analysis.error_speed_figures.combined_seconds`, the sum of ``own`` seconds over its input closure,
    each method counted once. Raises ``ValueError`` naming a method without a timing."""
    chosen = names if names is not None else list(own)
    needed = {m for name in chosen for m in input_closure(name, inputs)}
    missing = sorted(needed - set(own))
    if missing:
        raise ValueError(f"no timing for method(s) {', '.join(missing)}")
    totals = combined_seconds({m: own[m] for m in needed}, inputs)
    return {name: totals[name] for name in chosen}


def own_seconds(timings: pd.DataFrame) -> dict[str, float]:
    """Each method's own mean compute seconds per case: the mean over its (scene, spp) cases of
    the mean over repeated runs of a case (so a case timed twice weighs as one)."""
    per_case = timings.groupby(["method", "scene", "spp"])["seconds"].mean()
    return {str(k): float(v) for k, v in per_case.groupby(level="method").mean().items()}


def pareto_front(cost, score) -> np.ndarray:
    """Boolean mask of the points not dominated for (min ``cost``, max ``score``): a point is
    dominated when another has cost <= and score >= with one of them strict. Identical points
    are both on the front."""
    cost = np.asarray(cost, dtype=np.float64)
    score = np.asarray(score, dtype=np.float64)
    order = np.lexsort((-score, cost))  # by cost ascending, then score descending
    front = np.zeros(cost.shape, dtype=bool)
    best_score, best_cost = -np.inf, np.nan
    for index in order:
        if score[index] > best_score:
            front[index] = True
            best_score, best_cost = score[index], cost[index]
        elif score[index] == best_score and cost[index] == best_cost:
            front[index] = True
    return front


def speed_score_points(scores: pd.DataFrame, timings: pd.DataFrame, *, inputs: dict[str, list[str]],
                       noisy: str = "noisy", sizes: dict[str, int] | None = None) -> pd.DataFrame:
    """Each candidate's total cost against its ``Avg.`` score.

    Index candidate (every scored candidate but ``noisy``, best first); columns ``seconds`` (own
    mean compute seconds per case, :func:`own_seconds`), ``total_seconds`` (its whole input
    closure, :func:`closure_seconds`), ``score`` (``Avg.``), ``size`` (0 when unknown) and
    ``pareto`` (on the front of min total seconds, max score). Raises ``ValueError`` naming a
    candidate or input without timings."""
    averages = average_scores(scores).drop(noisy, errors="ignore")
    own = own_seconds(timings)
    names = list(averages.index)
    totals = closure_seconds(own, inputs, names=names)
    known = candidate_sizes(names, sizes=sizes)
    frame = pd.DataFrame({
        "seconds": [own[n] for n in names],
        "total_seconds": [totals[n] for n in names],
        "score": averages.to_numpy(np.float64),
        "size": [known.get(n, 0) for n in names],
    }, index=pd.Index(names, name="candidate"))
    frame["pareto"] = pareto_front(frame["total_seconds"], frame["score"])
    return frame

