"""The paper's observations of Zheng et al. 2021 Sec. 5.3.4, each with numbers and a verdict
(:func:`findings`; the verdict rules of :mod:`mcbench.analysis.study.statistics`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench.analysis import pool
from mcbench.analysis.study.data import BAND_TEXT, Resampling, StudyData, finite_or_none, id_list
from mcbench.analysis.study.pair_members import ALMOST, ALMOST_ALWAYS, failed_cases, pair_wins, size2_pairs
from mcbench.analysis.study.statistics import (INCONCLUSIVE, NOT_REPRODUCED, REPRODUCED, bootstrap_ci,
                                               ci_verdict)

__all__ = ["LEARNED_BASES", "CLASSICAL_BASES", "FINDING_COLUMNS", "CLAIMS", "findings"]

# Finding e: learned vs classical *bases*. The DC variants are left out of both groups: a DC
# variant is a network applied on top of another base (NFOR-DC on the classical NFOR), so it
# belongs to neither family cleanly; pool.LEARNED_IDS counts them as learned for homogeneity.
LEARNED_BASES = tuple(sorted(pool.LEARNED_IDS - pool.DC_IDS))    # 1 KPCN, 3 MCGAN, 6 OIDN, 7 OptiX
CLASSICAL_BASES = tuple(sorted(pool.CLASSICAL_IDS))              # 4 NFOR, 8 RDFC
FINDING_COLUMNS = ["metric", "finding", "claim", "quantity", "estimate", "ci_low", "ci_high", "verdict", "rule", "note"]
CLAIMS = {
    "a": "Gains grow with ensemble size up to 5, then level off or drop (Sec. 5.3.4, Table 3)",
    "b": "A combination of 2 base denoisers almost always outperforms the corresponding individual base denoisers "
         "(Sec. 5.3.4): each size-2 ensemble against each of its two members",
    "c": "Homogeneous sets (only learned or only classical; e.g. #28) rank lower than heterogeneous ones (Sec. 5.3.4)",
    "d": "Sets with a DC variant rank lower than sets without (#29 below #27) (Sec. 5.3.4)",
    "e": "Learned denoisers are better at low spp, classical ones at high spp (Sec. 5.3.4)",
    "f": "Ensembles rank above their members (Sec. 5.3.4)",
}


def _combine(verdicts: list[str]) -> str:
    """All parts reproduced -> reproduced; any part not reproduced -> not reproduced; else inconclusive."""
    if not verdicts:
        return INCONCLUSIVE
    if any(v == NOT_REPRODUCED for v in verdicts):
        return NOT_REPRODUCED
    return REPRODUCED if all(v == REPRODUCED for v in verdicts) else INCONCLUSIVE


class _Rows:
    def __init__(self, data: StudyData, resampling: Resampling):
        self.data, self.resampling, self.rows = data, resampling, []

    def add(self, finding, quantity, per_scene=None, *, verdict="", rule="", note="", claim=None,
            estimate=None) -> dict:
        row = {"metric": self.data.metric, "finding": finding, "claim": claim or CLAIMS[finding],
               "quantity": quantity, "estimate": estimate, "ci_low": None, "ci_high": None, "verdict": verdict,
               "rule": rule, "note": note}
        if per_scene is not None:
            found = bootstrap_ci(per_scene, resampling=self.resampling).iloc[0]
            row.update(estimate=float(found["estimate"]), ci_low=found["ci_low"], ci_high=found["ci_high"])
            if found["ci_method"] != "BCa":
                row["note"] = "; ".join(p for p in (note, f"CI: {found['ci_method']}") if p)
        self.rows.append(row)
        return row


def _finding_size(out: _Rows, avg: np.ndarray) -> None:
    data = out.data
    groups = {}
    for name in data.bases + data.ensembles:
        groups.setdefault(pool.candidate(name).size, []).append(name)
    per = {k: avg[:, data.columns(v)].mean(axis=1) for k, v in sorted(groups.items())}
    for k, names in sorted(groups.items()):
        out.add("a", f"mean score of size-{k} candidates (n = {len(names)})", per[k])
    rule_up = "each step between consecutive sizes <= 5 has its interval above 0"
    steps = [k for k in per if k <= 5]
    parts = []
    for a, b in zip(steps, steps[1:]):
        row = out.add("a", f"gain size {a} -> {b}", per[b] - per[a], rule=rule_up)
        row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above")
        parts.append(row["verdict"])
    complete = all(k in per for k in range(1, 6))
    verdict = _combine(parts) if len(steps) >= 2 else INCONCLUSIVE
    if not complete and verdict == REPRODUCED:
        verdict = INCONCLUSIVE      # every step we have grows, but the steps up to 5 are not all there
    out.add("a", "gains grow up to size 5", verdict=verdict,
            rule="reproduced when sizes 1-5 are all present and every step is; not reproduced when one "
                 "step's interval is below 0",
            note="" if complete else "sizes " + ", ".join(str(k) for k in range(1, 6) if k not in per)
            + " missing from our data")
    larger = [k for k in per if k > 5]
    rule_off = ("not reproduced: a size k > 5 above size 5 (interval of mean(k) - mean(5) above 0); reproduced: "
                "none is, and the gain shrinks (interval of (mean5 - mean4) - (mean(k1) - mean5) above 0, k1 the "
                "smallest size > 5); inconclusive otherwise")
    if not (4 in per and 5 in per and larger):
        out.add("a", "levels off past size 5", verdict=INCONCLUSIVE, rule=rule_off,
                note="needs sizes 4, 5 and a size > 5 in our data")
        return
    above = []
    for k in larger:
        row = out.add("a", f"size {k} - size 5", per[k] - per[5], rule="part of 'levels off'")
        above.append(ci_verdict(row["ci_low"], row["ci_high"], claim="above") == REPRODUCED)
    shrink = out.add("a", f"(gain 4 -> 5) - (gain 5 -> {larger[0]})",
                     (per[5] - per[4]) - (per[larger[0]] - per[5]), rule="part of 'levels off'")
    shrinks = ci_verdict(shrink["ci_low"], shrink["ci_high"], claim="above") == REPRODUCED
    verdict = NOT_REPRODUCED if any(above) else REPRODUCED if shrinks else INCONCLUSIVE
    out.add("a", "levels off past size 5", verdict=verdict, rule=rule_off)
    # the chain of Table 3: #16 -> #24 -> #30 -> #33 grows, #35 drops
    chain = [pool.candidate_name(i) for i in (16, 24, 30, 33, 35)]
    if all(n in data.names for n in chain):
        parts = []
        for a, b in zip(chain, chain[1:]):
            claim = "below" if b == chain[-1] else "above"
            row = out.add("a", f"Table 3 chain: #{pool.candidate(b).id} - #{pool.candidate(a).id}",
                          avg[:, data.column(b)] - avg[:, data.column(a)],
                          rule=f"claimed {claim} 0 (Table 3: grows to #33, #35 drops)")
            row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim=claim)
            parts.append(row["verdict"])
        out.add("a", "Table 3 chain grows to #33 (size 5), then drops at #35", verdict=_combine(parts),
                rule="reproduced when every step is; not reproduced when one step is not")


def _listed(items: list[str], limit: int = 8) -> str:
    return ", ".join(items[:limit]) + (f" … ({len(items) - limit} more)" if len(items) > limit else "")


def _member_label(name: str) -> str:
    return pool.candidate(name).label


def _finding_members(out: _Rows) -> None:
    """Finding (b) as the paper states it: size-2 ensembles against each of their members; then
    our own pooled statistic over every size, secondary and without a verdict."""
    data = out.data
    pairs, skipped = size2_pairs(data)
    left = f"size-2 ensembles without both members in the data left out: {id_list(skipped)}" if skipped else ""
    rule = (f"claimed above {ALMOST_ALWAYS:.2f} ('almost always': worse in under {100 * ALMOST:.0f} % of cases); "
            f"verdict from the interval; a tie does not count as outperforming")
    if not pairs:
        out.add("b", "size-2 ensembles against each member", verdict=INCONCLUSIVE,
                note="; ".join(p for p in ("no size-2 ensemble of the pool with both members in our data", left) if p))
    else:
        wins = pair_wins(data, pairs)                                      # (S, P, K, 2)
        failing = []
        for k, (name, members) in enumerate(pairs):
            for j, member in enumerate(members):
                w = wins[:, :, k, j]
                lost = failed_cases(w, data)
                row = out.add("b", f"{_member_label(name)} vs member {_member_label(member)}: fraction of cases the "
                                   f"pair outperforms it", w.mean(axis=1).astype(np.float64), rule=rule,
                              note=f"not outperformed in {len(lost)} of {w.size} cases"
                                   + (f": {_listed(lost)}" if lost else ""))
                row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above", threshold=ALMOST_ALWAYS)
                if row["verdict"] != REPRODUCED:
                    failing.append(f"#{pool.candidate(name).id} vs #{pool.candidate(member).id} ({row['verdict']})")
        for i, spp in enumerate(data.spps):
            out.add("b", f"{spp} spp: fraction of (size-2 ensemble, member) comparisons the pair wins",
                    wins[:, i].mean(axis=(1, 2)).astype(np.float64))
            out.add("b", f"{spp} spp: fraction of size-2 ensembles outperforming both members",
                    wins[:, i].all(axis=-1).mean(axis=1).astype(np.float64))
        row = out.add("b", f"all spp: fraction of (case, size-2 ensemble, member) comparisons the pair wins "
                           f"({len(pairs)} pair(s))", wins.mean(axis=(1, 2, 3)).astype(np.float64),
                      rule=rule + "; this row decides (b)",
                      note="; ".join(p for p in ("pairs not reproduced against a member: " + (", ".join(failing)
                                                                                              or "none"), left) if p))
        row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above", threshold=ALMOST_ALWAYS)
        out.add("b", "all spp: fraction of (case, size-2 ensemble) outperforming both members",
                wins.all(axis=-1).mean(axis=(1, 2)).astype(np.float64))
    _members_pooled(out)


def _members_pooled(out: _Rows) -> None:
    """Ours, secondary: every pool ensemble of any size against its members, no verdict."""
    data = out.data
    lost, pair_count, best = [], 0, []
    for name in data.ensembles:
        members = [pool.candidate_name(m) for m in pool.candidate(name).members]
        if not all(m in data.names for m in members):
            continue
        own = data.values[:, :, data.column(name)]                       # (scenes, spp)
        theirs = data.values[:, :, data.columns(members)]                # (scenes, spp, m)
        lost.append((own[:, :, None] > theirs).sum(axis=2))             # members it loses to
        pair_count += len(members)
        best.append(own > theirs.min(axis=2))
    if not lost:
        return
    lead = f"ours, secondary ({len(best)} ensembles of every size pooled; not the paper's claim)"
    pairs = np.sum(np.stack(lost, axis=2), axis=2) / float(pair_count)
    out.add("b", f"{lead}: fraction of (case, ensemble, member) with the ensemble worse than that member",
            pairs.mean(axis=1), note="the paper states (b) of size-2 ensembles only; no verdict")
    out.add("b", f"{lead}: fraction of (case, ensemble) with the ensemble worse than its best member",
            np.mean(np.stack(best, axis=2), axis=2).mean(axis=1),
            note="weights minimising wᵀMw with the MSE matrix M itself are never worse than the best member "
                 "in expectation; the ensembles solve with its dual-buffer estimate ⟨M⟩ (Eq. 11-12), so they can be")


def _split_within_sizes(out: _Rows, avg: np.ndarray, finding: str, flag, what: tuple[str, str]) -> None:
    """Per size with both kinds: mean(not flagged) - mean(flagged); pooled over those sizes."""
    data = out.data
    by_size = {}
    for name in data.ensembles:
        c = pool.candidate(name)
        by_size.setdefault(c.size, ([], []))[1 if flag(c.members) else 0].append(name)
    diffs = []
    for size, (plain, flagged) in sorted(by_size.items()):
        if plain and flagged:
            diff = avg[:, data.columns(plain)].mean(axis=1) - avg[:, data.columns(flagged)].mean(axis=1)
            out.add(finding, f"size {size}: {what[0]} ({id_list(plain)}) - {what[1]} ({id_list(flagged)})", diff)
            diffs.append(diff)
    if not diffs:
        out.add(finding, f"{what[0]} - {what[1]}, within sizes", verdict=INCONCLUSIVE,
                note=f"no size with both {what[0]} and {what[1]} sets in our data")
        return
    row = out.add(finding, f"{what[0]} - {what[1]}, mean over {len(diffs)} size(s)", np.mean(diffs, axis=0),
                  rule="claimed above 0; verdict from the interval")
    row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above")


def _one_against(out: _Rows, avg: np.ndarray, finding: str, better, worse) -> None:
    data = out.data
    better = [n for n in better if n in data.names]
    if worse not in data.names or not better:
        out.add(finding, f"{id_list(better) or 'others'} - #{pool.candidate(worse).id}", verdict=INCONCLUSIVE,
                note="not in our data")
        return
    row = out.add(finding, f"mean of {id_list(better)} - #{pool.candidate(worse).id}",
                  avg[:, data.columns(better)].mean(axis=1) - avg[:, data.column(worse)],
                  rule="claimed above 0; verdict from the interval")
    row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above")


def _finding_families(out: _Rows) -> None:
    data = out.data
    learned = [pool.candidate_name(i) for i in LEARNED_BASES if pool.candidate_name(i) in data.names]
    classical = [pool.candidate_name(i) for i in CLASSICAL_BASES if pool.candidate_name(i) in data.names]
    if not learned or not classical:
        out.add("e", "learned - classical bases", verdict=INCONCLUSIVE, note="a family is missing from our data")
        return
    claims = {"low": "above", "high": "below"}
    for band in pool.SPP_BANDS:
        spps = pool.spp_band_members(data.spps, band)
        quantity = f"{band} band ({BAND_TEXT[band]}): learned ({id_list(learned)}) - classical ({id_list(classical)})"
        if not spps:
            out.add("e", quantity, verdict=INCONCLUSIVE if band in claims else "",
                    note="no spp of the band in our data")
            continue
        per_scene = data.scene_scores(spps)
        diff = per_scene[:, data.columns(learned)].mean(axis=1) - per_scene[:, data.columns(classical)].mean(axis=1)
        if band in claims:
            row = out.add("e", quantity, diff, rule=f"claimed {claims[band]} 0; verdict from the interval")
            row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim=claims[band])
        else:
            out.add("e", quantity, diff, note="no claim in the paper for this band")


def _finding_above_members(out: _Rows, avg: np.ndarray) -> None:
    data = out.data
    overall = avg.mean(axis=0)
    margins, names, below = [], [], []
    pair_wins = []
    for name in data.ensembles:
        members = [pool.candidate_name(m) for m in pool.candidate(name).members]
        if not all(m in data.names for m in members):
            continue
        top = max(members, key=lambda m: overall[data.column(m)])
        margin = avg[:, data.column(name)] - avg[:, data.column(top)]
        margins.append(margin)
        names.append(name)
        pair_wins += [overall[data.column(name)] > overall[data.column(m)] for m in members]
    if not margins:
        out.add("f", "ensemble - best member", verdict=INCONCLUSIVE, note="no ensemble with its members")
        return
    margins = np.stack(margins, axis=1)                        # (scenes, ensembles)
    per_ensemble = bootstrap_ci(margins, resampling=out.resampling)
    below = [n for n, h in zip(names, per_ensemble["ci_high"]) if finite_or_none(h) is not None and h < 0]
    above = [n for n, lo in zip(names, per_ensemble["ci_low"]) if finite_or_none(lo) is not None and lo > 0]
    out.add("f", "fraction of ensembles whose Avg. exceeds their best member's",
            estimate=float(np.mean(margins.mean(axis=0) > 0)),
            note=f"{len(above)} of {len(names)} significantly above their best member; significantly below: "
                 f"{id_list(below) or 'none'}")
    out.add("f", "fraction of (ensemble, member) pairs with the ensemble's Avg. above the member's",
            estimate=float(np.mean(pair_wins)))
    row = out.add("f", f"mean over {len(names)} ensembles of (Avg. - best member's Avg.)", margins.mean(axis=1),
                  rule="claimed above 0; verdict from the interval (best member: the member with the highest Avg.)")
    row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above")


def findings(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """The observations of Sec. 5.3.4 with numbers and verdicts (:data:`FINDING_COLUMNS`).

    Every quantity is a mean over scenes of a per-scene quantity (scores: the per-scene mean over
    spp), with its paired scene-bootstrap interval; rows with a ``verdict`` decide a claim by
    :func:`~mcbench.analysis.study.statistics.ci_verdict`, the others are the numbers behind it (empty verdict).

    a. Size: mean score per size (1 = the bases). "Grows up to 5": every step between
       consecutive sizes <= 5 above 0. "Levels off past 5": not reproduced when some size k > 5
       is above size 5 (interval of mean(k) - mean(5) above 0: the gains go on); reproduced when
       none is *and* the gain shrinks (interval of (mean5 - mean4) - (mean(k1) - mean5) above 0,
       k1 the smallest size > 5: not mere absence of evidence); inconclusive otherwise.
       Also the Table 3 chain #16 < #24 < #30 < #33 > #35 step by step (all steps must hold).
    b. As the paper states it, of size-2 ensembles (:func:`~mcbench.analysis.study.pair_members.size2_pairs`)
       against each of their two members, on the metric values per case (the pair *outperforms* a member when
       its error is strictly below): per (pair, member) the fraction of cases it does, with a verdict and the
       failing cases in the note (all of them in :func:`~mcbench.analysis.study.pair_members.pair_members`); per
       spp the fraction of (pair, member) comparisons won and of pairs outperforming both; over all spp the
       fraction of (case, pair, member) comparisons won, which decides: reproduced when its interval lies above
       :data:`~mcbench.analysis.study.pair_members.ALMOST_ALWAYS` (0.90), not reproduced when below. Then, ours
       and secondary (no verdict, labelled so): every ensemble of every size pooled against its members, not the
       paper's claim.
    c. Homogeneous (:func:`mcbench.analysis.pool.is_homogeneous`) vs heterogeneous sets: per size with
       both, mean heterogeneous - mean homogeneous score; the mean over those sizes, claimed
       above 0. And the other size-4 ensembles' mean - #28, claimed above 0.
    d. DC (:func:`mcbench.analysis.pool.has_dc`): the same with sets without minus with DC; #27 - #29.
    e. Learned (:data:`LEARNED_BASES`: #1, #3, #6, #7 -- DC variants in neither family) minus
       classical (#4, #8) bases' mean score per spp band: claimed above 0 at low, below 0 at high
       spp; medium is reported without a claim.
    f. Ensembles above their members: per ensemble its per-scene margin over its best member
       (the member with the highest Avg.); the mean margin over ensembles claimed above 0. Also
       the fraction of ensembles (and of pairs) above, and the ensembles significantly below.
    """
    out = _Rows(data, resampling)
    avg = data.scene_scores()
    _finding_size(out, avg)
    _finding_members(out)
    _split_within_sizes(out, avg, "c", pool.is_homogeneous, ("heterogeneous", "homogeneous"))
    size4 = [n for n in data.ensembles if pool.candidate(n).size == 4 and n != pool.candidate_name(28)]
    _one_against(out, avg, "c", size4, pool.candidate_name(28))
    _split_within_sizes(out, avg, "d", pool.has_dc, ("without DC", "with DC"))
    _one_against(out, avg, "d", [pool.candidate_name(27)], pool.candidate_name(29))
    _finding_families(out)
    _finding_above_members(out, avg)
    return pd.DataFrame(out.rows, columns=FINDING_COLUMNS)
