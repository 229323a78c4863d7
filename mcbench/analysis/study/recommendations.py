"""The best ensemble per scope, derived from the data, beside the paper's (Zheng et al. 2021
Sec. 5.3.5-5.3.6): :func:`recommendations` per metric, among all 31 pool ensembles and among
only the 12 the paper names; :func:`recommendations_both` relMSE's and DSSIM's picks side by
side and one combined pick by mcbench's own rule (:data:`COMBINED_RULE`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench import BenchError
from mcbench.analysis import pool
from mcbench.analysis.study.data import Resampling, StudyData, id_list
from mcbench.analysis.study.statistics import bootstrap_ci, is_real, place_fractions, resample_indices

__all__ = ["REC_COLUMNS", "COMBINED_RULE", "BOTH_METRICS", "BOTH_COLUMNS", "recommendations", "recommendations_both"]

REC_COLUMNS = ["metric", "scope", "key", "spp", "candidates", "ours", "ours_id", "ours_score", "ours_ci_low",
               "ours_ci_high", "ours_fraction", "named_candidates", "named", "named_id", "named_score",
               "named_ci_low", "named_ci_high", "named_fraction", "paper", "paper_id", "paper_score", "paper_ci_low",
               "paper_ci_high", "paper_fraction", "difference", "difference_ci_low", "difference_ci_high",
               "real_difference", "agrees", "named_agrees", "note"]
# mcbench's own rule that weighs relMSE and DSSIM together (Sec. 5.3.6 does so for #27 without a formula).
COMBINED_RULE = ("ours, not the paper's: the highest mean of the relMSE and DSSIM ranking scores (each the paper's "
                 "per-case score over the same entries, averaged over the scope's spp and the scenes)")
BOTH_METRICS = ("relmse", "dssim")
BOTH_COLUMNS = ["scope", "key", "spp", "set", "candidates", "relmse", "relmse_id", "relmse_score", "dssim", "dssim_id",
                "dssim_score", "combined", "combined_id", "combined_score", "combined_ci_low", "combined_ci_high",
                "combined_fraction", "paper", "paper_id", "paper_combined_score", "agrees", "note"]


def _paper_named(names) -> list[str]:
    """The ensembles of ``names`` that the paper names (:data:`mcbench.analysis.pool.PAPER_NAMED_IDS`)."""
    return [n for n in names if pool.candidate(n).id in pool.PAPER_NAMED_IDS]


def _scopes(data: StudyData) -> list[tuple[str, object, list[str], list[int], int, int | None]]:
    """(scope, key, eligible ensembles, spps, place, the paper's ID) per recommendation."""
    ensembles = data.ensembles
    out = []
    for size in sorted({pool.candidate(n).size for n in ensembles}):
        chosen = [n for n in ensembles if pool.candidate(n).size == size]
        out.append(("size", size, chosen, list(data.spps), 1, pool.PAPER_RECOMMENDATIONS["size"].get(size)))
    for band in pool.SPP_BANDS:
        out.append(("band", band, ensembles, pool.spp_band_members(data.spps, band), 1,
                    pool.PAPER_RECOMMENDATIONS["band"].get(band)))
    for place, key in ((1, "best"), (2, "second")):
        out.append(("overall", key, ensembles, list(data.spps), place, pool.PAPER_RECOMMENDATIONS["overall"].get(key)))
    fewer = [n for n in ensembles if pool.candidate(n).size < pool.FEWER_THAN]
    out.append(("overall", "fewer", fewer, list(data.spps), 1, pool.PAPER_RECOMMENDATIONS["overall"].get("fewer")))
    return out


def _with_int_ids(table: pd.DataFrame, columns) -> pd.DataFrame:
    """``table`` with ``columns`` (counts and pool IDs) as nullable integers: empty cells stay
    empty, the others are written without a decimal point."""
    for column in columns:
        table[column] = table[column].astype("Int64")
    return table


def _pick(per_scene: np.ndarray, eligible: list[str], place: int, indices: np.ndarray,
          resampling: Resampling) -> dict | None:
    """The entry of ``eligible`` (columns of ``per_scene``, (scenes, k)) holding ``place`` by mean
    (ties: the lower ID), its interval, the fraction of resamples in which it holds the place,
    and the entries tied with it. ``None`` with fewer than ``place`` entries."""
    if len(eligible) < place:
        return None
    means = per_scene.mean(axis=0)
    order = sorted(range(len(eligible)), key=lambda i: (-round(means[i], 9), pool.candidate(eligible[i]).id))
    mine = order[place - 1]
    found = bootstrap_ci(per_scene, resampling=resampling)
    fractions = place_fractions(per_scene, indices, place=place)
    return {"index": mine, "name": eligible[mine], "id": pool.candidate(eligible[mine]).id,
            "score": float(means[mine]), "ci_low": found["ci_low"][mine], "ci_high": found["ci_high"][mine],
            "fraction": float(fractions[mine]), "means": means, "fractions": fractions, "found": found,
            "tied": [eligible[i] for i in order if i != mine and round(means[i], 9) == round(means[mine], 9)]}


def _scope_row(data: StudyData, scope: str, key, eligible: list[str], spps, place: int, paper_id, indices,
               resampling: Resampling) -> dict:
    """One row of :func:`recommendations`: the scope's two picks, beside the paper's choice."""
    row = dict.fromkeys(REC_COLUMNS)
    named = _paper_named(eligible)
    row.update(metric=data.metric, scope=scope, key=str(key), spp=" ".join(str(s) for s in spps),
               candidates=len(eligible), named_candidates=len(named), note="")
    paper = pool.candidate_name(paper_id) if paper_id is not None else None
    row["paper_id"] = paper_id
    row["paper"] = paper
    if not spps or len(eligible) < place:
        row["note"] = "no spp of the band in our data" if not spps else f"fewer than {place} ensembles"
        return row
    per_scene = data.scene_scores(spps)[:, data.columns(eligible)]
    best = _pick(per_scene, eligible, place, indices, resampling)
    row.update(ours=best["name"], ours_id=best["id"], ours_score=best["score"], ours_ci_low=best["ci_low"],
               ours_ci_high=best["ci_high"], ours_fraction=best["fraction"])
    notes = [f"tied with {', '.join('#%d' % pool.candidate(t).id for t in best['tied'])}"] if best["tied"] else []
    chosen = _pick(data.scene_scores(spps)[:, data.columns(named)], named, place, indices, resampling) \
        if named else None
    if chosen is not None:
        row.update(named=chosen["name"], named_id=chosen["id"], named_score=chosen["score"],
                   named_ci_low=chosen["ci_low"], named_ci_high=chosen["ci_high"],
                   named_fraction=chosen["fraction"])
        if chosen["tied"]:
            notes.append(f"paper-named pick tied with {id_list(chosen['tied'])}")
    else:
        notes.append(f"fewer than {place} paper-named ensembles in this scope")
    if paper is not None:
        notes += _against_paper(row, paper, paper_id, eligible, best, chosen, per_scene, resampling)
    row["note"] = "; ".join(notes)
    return row


def _against_paper(row: dict, paper: str, paper_id: int, eligible: list[str], best: dict, chosen: dict | None,
                   per_scene, resampling: Resampling) -> list[str]:
    """The paper's choice beside the picks, into ``row`` (agreement, its score and fraction,
    the paired difference with ours); the notes it adds."""
    ours, mine = best["name"], best["index"]
    row["agrees"] = "yes" if paper == ours else "no"
    if chosen is not None:
        row["named_agrees"] = "yes" if paper == chosen["name"] else "no"
    if paper not in eligible:
        return [f"the paper's #{paper_id} is not in our data"]
    theirs = eligible.index(paper)
    row.update(paper_score=float(best["means"][theirs]), paper_ci_low=best["found"]["ci_low"][theirs],
               paper_ci_high=best["found"]["ci_high"][theirs], paper_fraction=float(best["fractions"][theirs]))
    if paper != ours:
        diff = bootstrap_ci(per_scene[:, mine] - per_scene[:, theirs], resampling=resampling).iloc[0]
        real = is_real(diff["ci_low"], diff["ci_high"])
        row.update(difference=float(diff["estimate"]), difference_ci_low=diff["ci_low"],
                   difference_ci_high=diff["ci_high"],
                   real_difference="" if real is None else ("yes" if real else "no"))
    return []


def recommendations(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """The best ensemble per scope, derived from ``data``, beside the paper's choice.

    Scopes: each ensemble size present (2, 3, 4, 5, 6, 8), each spp band of
    :data:`mcbench.analysis.pool.SPP_BANDS` (mean score over the band's spp in our data; 32 spp is in low
    and medium), overall best and second (by ``Avg.``), and overall ``fewer``: the best ensemble
    with fewer members than the paper's #27 (size < :data:`mcbench.analysis.pool.FEWER_THAN`; the
    paper's "fewer base denoisers: #20", Sec. 5.3.6). Only pool ensembles present in the data
    compete (bases never).

    Two picks per scope: ``ours`` among every pool ensemble present, ``named`` among only the ensembles the
    paper names (:data:`mcbench.analysis.pool.PAPER_NAMED_IDS`, 12 of the 31; the pick the paper could have
    made). Each is the highest mean score (ties: the lower ID, noted). Columns :data:`REC_COLUMNS`:
    ``*_fraction`` is the fraction of the scene resamples
    (:func:`~mcbench.analysis.study.statistics.resample_indices`) in which the candidate holds the scope's place
    within its set (ties share it); ``difference`` ours - the paper's, with its paired interval;
    ``real_difference`` yes/no (:func:`~mcbench.analysis.study.statistics.is_real`), empty when ours is the
    paper's or either is missing; ``agrees`` / ``named_agrees`` yes/no, empty when the paper has no choice for
    the scope (sizes 5, 6, 8). """
    indices = resample_indices(len(data.scenes), resampling=resampling)
    rows = [_scope_row(data, scope, key, eligible, spps, place, paper_id, indices, resampling)
            for scope, key, eligible, spps, place, paper_id in _scopes(data)]
    return _with_int_ids(pd.DataFrame(rows, columns=REC_COLUMNS),
                         ("candidates", "ours_id", "named_candidates", "named_id", "paper_id"))


def recommendations_both(by_metric: dict[str, StudyData], *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """relMSE's and DSSIM's picks side by side and one combined pick of ours, per scope and set.

    ``by_metric``: :class:`~mcbench.analysis.study.data.StudyData` of ``relmse`` and ``dssim`` over the same
    scenes, spp and entries (an empty table, :data:`BOTH_COLUMNS`, when either is missing). Scopes as
    :func:`recommendations` (sizes, spp bands, overall best, second, fewer); sets ``all`` (every pool ensemble
    present) and ``paper-named`` (:data:`mcbench.analysis.pool.PAPER_NAMED_IDS`). Per row: each metric's pick
    (highest mean score, ties the lower ID) and its score; the ``combined`` pick by :data:`COMBINED_RULE` -- per
    scene the mean of the two metrics' scores (each the scene's mean over the scope's spp), then the mean over
    scenes -- with its scene- bootstrap interval and the fraction of resamples in which it holds the place; the
    paper's choice, its combined score and whether the combined pick agrees with it. """
    if any(m not in by_metric for m in BOTH_METRICS):
        return pd.DataFrame(columns=BOTH_COLUMNS)
    first, second = (by_metric[m] for m in BOTH_METRICS)
    if (first.scenes, first.spps, first.names) != (second.scenes, second.spps, second.names):
        raise BenchError("recommendations: relMSE and DSSIM cover different scenes, spp or entries")
    indices = resample_indices(len(first.scenes), resampling=resampling)
    rows = []
    for scope, key, eligible, spps, place, paper_id in _scopes(first):
        paper = pool.candidate_name(paper_id) if paper_id is not None else None
        for which, chosen in (("all", list(eligible)), ("paper-named", _paper_named(eligible))):
            row = dict.fromkeys(BOTH_COLUMNS)
            row.update(scope=scope, key=str(key), spp=" ".join(str(s) for s in spps), set=which,
                       candidates=len(chosen), paper=paper, paper_id=paper_id, note="")
            if not spps or len(chosen) < place:
                row["note"] = "no spp of the band in our data" if not spps else f"fewer than {place} ensembles"
                rows.append(row)
                continue
            scores = {m: d.scene_scores(spps)[:, d.columns(chosen)] for m, d in zip(BOTH_METRICS, (first, second))}
            notes = []
            for metric, per_scene in scores.items():
                means = per_scene.mean(axis=0)
                order = sorted(range(len(chosen)), key=lambda i: (-round(means[i], 9), pool.candidate(chosen[i]).id))
                pick = order[place - 1]
                row.update({metric: chosen[pick], f"{metric}_id": pool.candidate(chosen[pick]).id,
                            f"{metric}_score": float(means[pick])})
            combined = (scores["relmse"] + scores["dssim"]) / 2.0
            best = _pick(combined, chosen, place, indices, resampling)
            row.update(combined=best["name"], combined_id=best["id"], combined_score=best["score"],
                       combined_ci_low=best["ci_low"], combined_ci_high=best["ci_high"],
                       combined_fraction=best["fraction"])
            if best["tied"]:
                notes.append(f"combined pick tied with {id_list(best['tied'])}")
            if paper is not None:
                row["agrees"] = "yes" if paper == best["name"] else "no"
                if paper in chosen:
                    row["paper_combined_score"] = float(best["means"][chosen.index(paper)])
                else:
                    notes.append(f"the paper's #{paper_id} is not in this set in our data")
            row["note"] = "; ".join(notes)
            rows.append(row)
    return _with_int_ids(pd.DataFrame(rows, columns=BOTH_COLUMNS),
                         ("candidates", "relmse_id", "dssim_id", "combined_id", "paper_id"))

