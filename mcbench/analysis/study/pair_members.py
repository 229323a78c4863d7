"""Finding (b) of Zheng et al. 2021 Sec. 5.3.4 case by case: "a combination of 2 base denoisers
almost always outperforms the corresponding individual base denoisers" -- each size-2 pool
ensemble against each of its two members, on the metric values (:func:`pair_members`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench.analysis import pool
from mcbench.analysis.study.data import Resampling, StudyData
from mcbench.analysis.study.statistics import bootstrap_ci, ci_verdict

__all__ = ["ALMOST", "ALMOST_ALWAYS", "PAIR_COLUMNS", "size2_pairs", "pair_wins", "failed_cases", "pair_members"]

# "almost always"/"almost never" (Sec. 5.3.4), as a fraction of cases: worse in below 10 %,
# i.e. better in above 90 % (ALMOST_ALWAYS).
ALMOST = 0.10
ALMOST_ALWAYS = 1.0 - ALMOST
# the columns of pair_members (and of pair_members.csv)
PAIR_COLUMNS = ["metric", "ensemble", "id", "member", "member_id", "spp", "cases", "wins", "fraction", "ci_low",
                "ci_high", "ci_method", "verdict", "failures"]


def size2_pairs(data: StudyData) -> tuple[list[tuple[str, list[str]]], list[str]]:
    """The size-2 pool ensembles of ``data`` whose two members are in it, as ``(ensemble,
    [member, member])`` in ID order, and the size-2 ensembles left out for a missing member."""
    pairs, skipped = [], []
    for name in data.ensembles:
        c = pool.candidate(name)
        if c.size != 2:
            continue
        members = [pool.candidate_name(m) for m in c.members]
        if all(m in data.names for m in members):
            pairs.append((name, members))
        else:
            skipped.append(name)
    return pairs, skipped


def pair_wins(data: StudyData, pairs: list[tuple[str, list[str]]]) -> np.ndarray:
    """(scenes, spp, pairs, 2) bool: in each case the pair's error is strictly below that member's
    (the pair *outperforms* it; a tie does not count)."""
    own = data.values[:, :, data.columns([name for name, _ in pairs])]                    # (S, P, K)
    theirs = np.stack([data.values[:, :, data.columns([m[j] for _, m in pairs])] for j in (0, 1)], axis=3)
    return own[..., None] < theirs


def failed_cases(wins: np.ndarray, data: StudyData) -> list[str]:
    """``scene@spp`` of the cases (scenes, spp) where ``wins`` is False."""
    return [f"{data.scenes[i]}@{data.spps[j]}" for i, j in zip(*np.nonzero(~wins))]



def pair_members(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """Finding (b) case by case: every size-2 pool ensemble against each of its two members
    (Sec. 5.3.4: "a combination of 2 base denoisers almost always outperforms the corresponding
    individual base denoisers"), on the metric values.

    One row (:data:`PAIR_COLUMNS`) per size-2 ensemble of :func:`size2_pairs`, ``member`` (each of the two, then
    ``both``: the pair outperforms both members in the case) and ``spp`` (each spp of the data, then ``all``):
    ``cases`` compared, ``wins`` (the pair's error strictly below), ``fraction`` = wins / cases with the
    scene-bootstrap interval of the per-scene fraction, ``verdict`` of "fraction above :data:`ALMOST_ALWAYS`"
    (:func:`~mcbench.analysis.study.statistics.ci_verdict`) and the ``failures``: the cases (``scene@spp``) the
    pair does not outperform it. """
    pairs, _ = size2_pairs(data)
    if not pairs:
        return pd.DataFrame(columns=PAIR_COLUMNS)
    wins = pair_wins(data, pairs)                                          # (S, P, K, 2)
    columns = []                                                           # (ensemble, member, (S, P) bool)
    for k, (name, members) in enumerate(pairs):
        columns += [(name, m, wins[:, :, k, j]) for j, m in enumerate(members)]
        columns.append((name, "both", wins[:, :, k, :].all(axis=-1)))
    labels = [str(s) for s in data.spps] + ["all"]
    blocks = {}
    for i, label in enumerate(labels):
        per_scene = np.stack([w[:, i] if label != "all" else w.mean(axis=1) for _, _, w in columns], axis=1)
        blocks[label] = bootstrap_ci(per_scene.astype(np.float64), resampling=resampling)
    rows = []
    for c, (name, member, w) in enumerate(columns):
        for i, label in enumerate(labels):
            chosen = w[:, [i]] if label != "all" else w
            found = blocks[label].iloc[c]
            rows.append({"metric": data.metric, "ensemble": name, "id": pool.candidate(name).id, "member": member,
                         "member_id": None if member == "both" else pool.candidate(member).id, "spp": label,
                         "cases": int(chosen.size), "wins": int(chosen.sum()), "fraction": float(chosen.mean()),
                         "ci_low": found["ci_low"], "ci_high": found["ci_high"], "ci_method": found["ci_method"],
                         "verdict": ci_verdict(found["ci_low"], found["ci_high"], claim="above",
                                               threshold=ALMOST_ALWAYS),
                         "failures": " ".join(failed_cases(chosen, data) if label == "all" else
                                              [f"{data.scenes[s]}@{label}" for s in np.nonzero(~chosen[:, 0])[0]])})
    table = pd.DataFrame(rows, columns=PAIR_COLUMNS)
    table["member_id"] = table["member_id"].astype("Int64")
    return table
