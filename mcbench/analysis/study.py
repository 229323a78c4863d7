"""The 39-candidate study of Zheng et al. 2021, Sec. 5.3, checked with numbers.

Pure functions over the tidy metrics table (columns scene, spp, candidate, metric, value; the
pool's harness names of :mod:`mcbench.analysis.pool` plus ``noisy``), writers at the end. Core module:
imports only from ``mcbench``.

* :func:`paper_comparison` / :func:`paper_kendall` -- our relMSE scores of the candidates of the
  paper's Table 3 beside the paper's, per spp and ``Avg.``, and the Kendall tau of the two
  orderings (Sec. 5.3.3-5.3.4).
* :func:`bootstrap_ci`, :func:`score_cis`, :func:`difference_ci` -- confidence intervals over
  scenes (the uncertainty of every score and difference).
* :func:`recommendations` -- the best ensemble by size, spp band and overall, derived from the
  data, among all 31 pool ensembles and among only the 12 the paper names, beside the paper's
  (Sec. 5.3.5-5.3.6); :func:`recommendations_both` -- relMSE's and DSSIM's picks side by side and
  one combined pick by a rule of ours (:data:`COMBINED_RULE`).
* :func:`findings` -- the paper's observations of Sec. 5.3.4 with a verdict each;
  :func:`pair_members` -- finding (b) case by case: each size-2 ensemble against each member.

Scores and the scene bootstrap
------------------------------
Scores are the paper's (:func:`mcbench.analysis.ranking.case_scores`: in each case (scene, spp) the best
of K entries gets K, the worst 1) over the pool candidates present in the data plus the noisy
input -- 40 entries when the pool is complete, as in the paper. A candidate's per-scene score is
the mean over spp of its scores in that scene; its ``Avg.`` is the mean over scenes of those.
:func:`study_data` insists on a full grid (every scene has every spp, every case every entry:
:func:`mcbench.analysis.ranking.check_complete`), under which this equals the ranking table's mean over
spp of the mean over scenes (:func:`avg_scores` checks it).

Every statistic here is a mean over scenes of a per-scene quantity (a score, a difference of
scores, a fraction of cases), so the uncertainty is that of the scenes: whole scenes are
resampled with replacement, paired (one resample moves every candidate's scores together;
differences are formed per scene before resampling). Confidence intervals come from
:func:`scipy.stats.bootstrap` with a fixed seed (:class:`Resampling`; numpy ``Generator``),
confidence 0.95, method **BCa** (bias-corrected and accelerated: second-order accurate, it
corrects for the skew a bounded rank score has near the top or bottom of the scale). BCa is
undefined for degenerate data (all resampled statistics equal, e.g. a candidate that wins every
case) and unstable with very few scenes; a column whose BCa interval is not finite falls back to
the **percentile** interval and says so in its ``ci_method``. With fewer than two scenes no
interval is given (empty cells). Which candidate is top, per scope, is counted on one matrix of
resampled scene indices (:func:`resample_indices`) shared by every candidate and scope.

A difference is **real** when the 95 % paired bootstrap interval of the per-scene difference
excludes 0 (strictly: low > 0 or high < 0).

Verdicts (:func:`ci_verdict`)
-----------------------------
A claim "quantity above t" is **reproduced** when the quantity's interval lies entirely above
t, **not reproduced** when it lies entirely below t, **inconclusive** otherwise (it contains t,
or no interval could be formed). "Below t" mirrors it. Claims made of several parts combine as
documented in :func:`findings`. Never by eye: only the intervals decide.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from mcbench import NOISY, BenchError

from mcbench.analysis import pool
from mcbench.io.tables import read_table, write_csv, write_text
from mcbench.analysis.metrics import METRIC_LABELS
from mcbench.analysis.ranking import case_scores, check_complete

__all__ = ["NOISY", "PAPER_ENTRIES", "SEED", "N_RESAMPLES", "CONFIDENCE", "ALMOST", "LEARNED_BASES",
           "CLASSICAL_BASES", "REPRODUCED", "NOT_REPRODUCED", "INCONCLUSIVE", "STUDY_FILES", "Resampling",
           "StudyData", "study_data", "avg_scores", "ranking_from", "resample_indices", "bootstrap_ci",
           "score_cis", "difference_ci", "is_real", "place_fractions", "paper_comparison", "paper_kendall",
           "PAPER_TABLE3_BASES",
           "paper_comparison_markdown", "recommendations", "recommendation_sentences", "recommendations_markdown",
           "ci_verdict", "findings", "findings_markdown", "ALMOST_ALWAYS", "size2_pairs", "pair_wins", "PAIR_COLUMNS",
           "pair_members", "pair_members_markdown", "REC_COLUMNS", "BOTH_COLUMNS", "BOTH_METRICS", "COMBINED_RULE",
           "recommendations_both", "recommendations_both_markdown", "recommendations_both_sentences",
           "REFERENCE_NOISE_COLUMNS", "reference_noise_effect",
           "reference_noise_markdown", "study_outputs", "write_study_tables"]

PAPER_ENTRIES = 40              # the paper's scale: 39 candidates + the noisy input
SEED = 20210815
N_RESAMPLES = 2000
CONFIDENCE = 0.95
# "almost always"/"almost never" (Sec. 5.3.4), as a fraction of cases: worse in below 10 %,
# i.e. better in above 90 % (ALMOST_ALWAYS).
ALMOST = 0.10
ALMOST_ALWAYS = 1.0 - ALMOST
# Finding e: learned vs classical *bases*. The DC variants are left out of both groups: a DC
# variant is a network applied on top of another base (NFOR-DC on the classical NFOR), so it
# belongs to neither family cleanly; pool.LEARNED_IDS counts them as learned for homogeneity.
LEARNED_BASES = tuple(sorted(pool.LEARNED_IDS - pool.DC_IDS))    # 1 KPCN, 3 MCGAN, 6 OIDN, 7 OptiX
CLASSICAL_BASES = tuple(sorted(pool.CLASSICAL_IDS))              # 4 NFOR, 8 RDFC
REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE = "reproduced", "not reproduced", "inconclusive"
BAND_TEXT = {"low": "4–32 spp", "medium": "32–256 spp", "high": ">256 spp"}
STUDY_FILES = ("paper_table3.csv", "paper_table3.md", "recommendations.csv", "recommendations.md",
               "recommendations_metrics.csv", "recommendations_metrics.md", "findings.csv", "findings.md",
               "pair_members.csv", "pair_members.md", "reference_noise.csv", "reference_noise.md", "summary.md")


# --------------------------------------------------------------------------------------------
# data
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Resampling:
    """The scene bootstrap's settings: ``n_resamples`` resamples of the scenes, numpy
    ``Generator`` seed ``seed``, two-sided ``confidence`` level."""

    n_resamples: int = N_RESAMPLES
    seed: int = SEED
    confidence: float = CONFIDENCE

    def __post_init__(self):
        if int(self.n_resamples) < 1:
            raise BenchError(f"study: n_resamples must be >= 1, got {self.n_resamples}")
        if not 0.0 < float(self.confidence) < 1.0:
            raise BenchError(f"study: confidence must lie in (0, 1), got {self.confidence}")


@dataclass(frozen=True)
class StudyData:
    """One metric's values and scores on a full grid.

    ``values`` and ``scores`` are float64 arrays of shape (scenes, spp, names), ``names`` the
    pool candidates present in ID order, then the noisy input (when scored).
    """

    metric: str
    scenes: tuple[str, ...]
    spps: tuple[int, ...]
    names: tuple[str, ...]
    values: np.ndarray
    scores: np.ndarray

    def column(self, name: str) -> int:
        return self.names.index(name)

    def columns(self, names) -> list[int]:
        return [self.names.index(n) for n in names]

    def scene_scores(self, spps=None) -> np.ndarray:
        """(scenes, names): each scene's mean score over ``spps`` (default all)."""
        chosen = range(len(self.spps)) if spps is None else [self.spps.index(int(s)) for s in spps]
        chosen = list(chosen)
        if not chosen:
            raise ValueError("no spp chosen")
        return self.scores[:, chosen, :].mean(axis=1)

    @property
    def entries(self) -> int:
        return len(self.names)

    @property
    def ensembles(self) -> list[str]:
        """Pool ensembles present, ID order (bases never count as ensembles)."""
        return [n for n in self.names if n != NOISY and _is_pool(n) and not pool.candidate(n).is_base]

    @property
    def bases(self) -> list[str]:
        return [n for n in self.names if n != NOISY and _is_pool(n) and pool.candidate(n).is_base]


def _is_pool(name: str) -> bool:
    try:
        pool.candidate(name)
    except BenchError:
        return False
    return True


def _cid(name: str) -> int | None:
    return pool.candidate(name).id if _is_pool(name) else None


def study_data(metrics: pd.DataFrame, metric: str, *, candidates=None, noisy: str | None = NOISY,
               source: str = "metrics") -> StudyData:
    """Values and scores of ``metric`` for ``candidates`` (default: every pool candidate with a
    row of this metric, ID order) plus ``noisy`` (``None``: not scored).

    Refuses (:class:`mcbench.BenchError`, naming ``source``, the case and the candidate) a table
    in which a case lacks one of them, a scene lacks an spp another scene has, or a value is
    missing or not finite.
    """
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        raise BenchError(f"{source}: no values for metric '{metric}'")
    present = set(rows["candidate"])
    if candidates is None:
        names = [c.name for c in pool.POOL if c.name in present]
    else:
        names = list(dict.fromkeys(candidates))
    if not names:
        raise BenchError(f"{source}: no candidate of the pool has a '{metric}' value")
    if noisy is not None:
        names.append(noisy)
    rows = rows[rows["candidate"].isin(names)].copy()
    rows["scene"] = rows["scene"].astype(str)
    rows["spp"] = rows["spp"].astype(int)
    scenes = sorted(set(rows["scene"]))
    spps = sorted(set(rows["spp"]))
    check_complete(rows, candidates=names, metric_names=[metric], cases=[(s, n) for s in scenes for n in spps],
                   source=source)
    index = pd.MultiIndex.from_product([scenes, spps, names], names=["scene", "spp", "candidate"])
    values = rows.set_index(["scene", "spp", "candidate"])["value"].astype(np.float64).reindex(index)
    scored = case_scores(rows, metric)
    scored["scene"] = scored["scene"].astype(str)
    scored["spp"] = scored["spp"].astype(int)
    scores = scored.set_index(["scene", "spp", "candidate"])["score"].astype(np.float64).reindex(index)
    shape = (len(scenes), len(spps), len(names))
    return StudyData(metric, tuple(scenes), tuple(int(s) for s in spps), tuple(names),
                     values.to_numpy(dtype=np.float64).reshape(shape), scores.to_numpy(dtype=np.float64).reshape(shape))


def avg_scores(data: StudyData) -> np.ndarray:
    """(names,) ``Avg.``: mean over scenes of the per-scene scores; checked equal to the mean
    over spp of the mean over scenes (the ranking table's order of averaging)."""
    by_scene = data.scene_scores().mean(axis=0)
    by_spp = data.scores.mean(axis=0).mean(axis=0)
    if not np.allclose(by_scene, by_spp, rtol=0.0, atol=1e-9):
        raise RuntimeError("study: Avg. over scenes and over spp disagree on a full grid")
    return by_scene


def ranking_from(data: StudyData) -> pd.DataFrame:
    """A ranking table like :func:`mcbench.analysis.ranking.ranking_table`'s (index candidate, columns
    spp as strings and ``Avg.``), in ID order (noisy last)."""
    table = pd.DataFrame(data.scores.mean(axis=0).T, index=list(data.names), columns=[str(s) for s in data.spps])
    table["Avg."] = avg_scores(data)
    table.index.name = "candidate"
    return table


# --------------------------------------------------------------------------------------------
# the scene bootstrap
# --------------------------------------------------------------------------------------------

def resample_indices(n_scenes: int, *, resampling: Resampling = Resampling()) -> np.ndarray:
    """(n_resamples, n_scenes) int: scene indices drawn with replacement, one row per resample,
    from a numpy Generator seeded with ``(seed, 1)`` (a stream apart from the CIs')."""
    rng = np.random.default_rng([int(resampling.seed), 1])
    return rng.integers(0, n_scenes, size=(int(resampling.n_resamples), n_scenes))


def _scipy_interval(x: np.ndarray, method: str, resampling: Resampling) -> tuple[np.ndarray, np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = stats.bootstrap((x.T,), np.mean, n_resamples=int(resampling.n_resamples), vectorized=True, axis=-1,
                                 confidence_level=float(resampling.confidence), method=method,
                                 rng=np.random.default_rng(int(resampling.seed)))
    low = np.atleast_1d(np.asarray(result.confidence_interval.low, dtype=np.float64))
    high = np.atleast_1d(np.asarray(result.confidence_interval.high, dtype=np.float64))
    return low, high


def bootstrap_ci(per_scene, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """Mean over scenes and its bootstrap interval, per column.

    ``per_scene``: (scenes,) or (scenes, k) float64, one row per scene. Returns k rows with
    columns estimate, ci_low, ci_high (None where no interval: fewer than 2 scenes) and
    ci_method (``"BCa"``, ``"percentile (BCa degenerate)"`` or ``"none (fewer than 2 scenes)"``).
    """
    x = np.asarray(per_scene, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] == 0:
        raise ValueError(f"per_scene must be (scenes, k) with at least one scene, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("per_scene holds NaN or Inf")
    n, k = x.shape
    estimate = x.mean(axis=0)
    low = np.full(k, np.nan)
    high = np.full(k, np.nan)
    method = np.array(["none (fewer than 2 scenes)"] * k, dtype=object)
    if n >= 2 and k:
        try:
            low, high = _scipy_interval(x, "BCa", resampling)
        except (ValueError, FloatingPointError):
            low, high = np.full(k, np.nan), np.full(k, np.nan)
        good = np.isfinite(low) & np.isfinite(high)
        method[good] = "BCa"
        if not good.all():
            p_low, p_high = _scipy_interval(x[:, ~good], "percentile", resampling)
            low[~good], high[~good] = p_low, p_high
            method[~good] = "percentile (BCa degenerate)"
    finite = np.isfinite(low) & np.isfinite(high)
    return pd.DataFrame({"estimate": estimate,
                         "ci_low": [float(v) if f else None for v, f in zip(low, finite)],
                         "ci_high": [float(v) if f else None for v, f in zip(high, finite)],
                         "ci_method": list(method)})


def is_real(ci_low, ci_high) -> bool | None:
    """A difference is real when its interval excludes 0 (low > 0 or high < 0); ``None``
    without an interval."""
    if ci_low is None or ci_high is None or not (np.isfinite(ci_low) and np.isfinite(ci_high)):
        return None
    return bool(ci_low > 0.0 or ci_high < 0.0)


def difference_ci(data: StudyData, a: str, b: str, *, spps=None, resampling: Resampling = Resampling()) -> dict:
    """Paired bootstrap of the score difference ``a - b`` (per scene, mean over ``spps``):
    ``{"estimate", "ci_low", "ci_high", "ci_method", "real"}`` (``real``: :func:`is_real`)."""
    per_scene = data.scene_scores(spps)
    diff = per_scene[:, data.column(a)] - per_scene[:, data.column(b)]
    row = bootstrap_ci(diff, resampling=resampling).iloc[0].to_dict()
    row["real"] = is_real(row["ci_low"], row["ci_high"])
    return row


def score_cis(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """Every entry's ``Avg.`` with its interval, and per spp band (:data:`mcbench.analysis.pool.SPP_BANDS`)
    the band's mean score with its interval.

    Columns: candidate, id (empty for non-pool names), avg, avg_ci_low, avg_ci_high, ci_method,
    then ``<band>``, ``<band>_ci_low``, ``<band>_ci_high`` for low, medium, high (empty when no
    spp of the data is in the band), ID order with the noisy input last.
    """
    overall = bootstrap_ci(data.scene_scores(), resampling=resampling)
    table = pd.DataFrame({"candidate": list(data.names), "id": [_cid(n) for n in data.names],
                          "avg": avg_scores(data), "avg_ci_low": overall["ci_low"],
                          "avg_ci_high": overall["ci_high"], "ci_method": overall["ci_method"]})
    table["id"] = table["id"].astype("Int64")
    for band in pool.SPP_BANDS:
        spps = pool.spp_band_members(data.spps, band)
        if spps:
            found = bootstrap_ci(data.scene_scores(spps), resampling=resampling)
            table[band], table[f"{band}_ci_low"], table[f"{band}_ci_high"] = (found["estimate"], found["ci_low"],
                                                                           found["ci_high"])
        else:
            table[band] = table[f"{band}_ci_low"] = table[f"{band}_ci_high"] = None
    return table


def place_fractions(per_scene, indices: np.ndarray, *, place: int = 1) -> np.ndarray:
    """(k,) fraction of the resamples (rows of ``indices``, scene indices) in which each column
    of ``per_scene`` (scenes, k) holds ``place`` (1 = highest mean). Tied columns share the places
    they span equally, so the fractions of one place sum to 1."""
    x = np.asarray(per_scene, dtype=np.float64)
    means = np.round(x[indices].mean(axis=1), 9)                  # (B, k)
    above = (means[:, None, :] > means[:, :, None]).sum(axis=2)   # (B, k): columns strictly higher
    equal = (means[:, None, :] == means[:, :, None]).sum(axis=2)  # includes itself
    holds = (above < place) & (place <= above + equal)
    return (holds / equal).mean(axis=0)


# --------------------------------------------------------------------------------------------
# beside the paper (Table 3)
# --------------------------------------------------------------------------------------------

# The base denoisers among the paper's Table 3 rows (KPCN, MCGAN, NFOR, OIDN, OptiX, RDFC).
PAPER_TABLE3_BASES = tuple(cid for cid in pool.PAPER_TABLE3 if pool.candidate(cid).is_base)


def _paper_names(names) -> dict[int, str]:
    names = dict(names or {})
    return {cid: names.get(cid, pool.candidate_name(cid)) for cid in pool.PAPER_TABLE3}


def _number(value) -> float | None:
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if np.isfinite(number) else None


def paper_comparison(ranking: pd.DataFrame, *, names: dict[int, str] | None = None) -> pd.DataFrame:
    """Our scores beside the paper's Table 3 (relMSE; Sec. 5.3.4).

    ``ranking``: index candidate names, columns spp as strings and ``Avg.`` (as
    :func:`mcbench.analysis.ranking.ranking_table`). ``names`` maps the paper's IDs to our candidate names
    (default: the pool's harness names). Long table, one row per candidate of
    :data:`mcbench.analysis.pool.PAPER_TABLE3` (ID order) and column: columns id, candidate, spp (``"4"``
    ... ``"1024"``, our extra spp, ``"Avg."`` and ``"Avg. (common spp)"`` -- both averaged over
    the spp that both tables have), ours, paper, difference (ours - paper), note. A cell one side
    lacks is empty (None) and the note says which.
    """
    mapping = _paper_names(names)
    our_spp = [c for c in ranking.columns if str(c) != "Avg."]
    paper_spp = [str(s) for s in pool.PAPER_TABLE3_SPP]
    common = [s for s in paper_spp if s in [str(c) for c in our_spp]]
    columns = paper_spp + sorted((str(c) for c in our_spp if str(c) not in paper_spp), key=int)
    rows = []
    for cid, name in mapping.items():
        paper_row = pool.PAPER_TABLE3[cid]
        have = name in ranking.index
        for spp in columns + ["Avg.", "Avg. (common spp)"]:
            paper = _number(paper_row.get(int(spp))) if spp.isdigit() else None
            ours = _number(ranking.loc[name, spp]) if have and spp in [str(c) for c in ranking.columns] else None
            note = ""
            if spp == "Avg.":
                paper = paper_row["Avg."]
                if have and common != paper_spp:
                    note = "our Avg. is over our spp, the paper's over 4–1024"
            if spp == "Avg. (common spp)":
                paper = float(np.mean([paper_row[int(s)] for s in common])) if common else None
                ours = float(np.mean([float(ranking.loc[name, s]) for s in common])) if common and have else None
                if not common:
                    note = "no spp in common"
            if not have:
                note = f"{name} not in our ranking"
            elif ours is None and spp.isdigit():
                note = "spp not in our data"
            elif paper is None and spp.isdigit():
                note = "spp not in the paper"
            diff = ours - paper if ours is not None and paper is not None else None
            rows.append({"id": cid, "candidate": name, "spp": spp, "ours": ours, "paper": paper, "difference": diff,
                         "note": note})
    return pd.DataFrame(rows, columns=["id", "candidate", "spp", "ours", "paper", "difference", "note"])


def _kendall(ours, paper) -> dict:
    ours, paper = np.asarray(ours, dtype=np.float64), np.asarray(paper, dtype=np.float64)
    if len(ours) < 2 or np.all(ours == ours[0]) or np.all(paper == paper[0]):
        return {"n": int(len(ours)), "tau": None, "p_value": None}
    result = stats.kendalltau(ours, paper)
    tau, p = _number(result.statistic), _number(result.pvalue)
    return {"n": int(len(ours)), "tau": tau, "p_value": p}


def paper_kendall(ranking: pd.DataFrame, *, names: dict[int, str] | None = None,
                  ids=None) -> pd.DataFrame:
    """Kendall tau-b (:func:`scipy.stats.kendalltau`, two-sided p-value) between our ordering of
    the Table 3 candidates in our ranking and the paper's: once by ``Avg.`` as each table has
    it, once by the mean over the spp both have. ``ids``: only these of the paper's IDs (e.g.
    :data:`PAPER_TABLE3_BASES`, the six bases of its Table 3); default all 11. Columns basis, n,
    tau, p_value (None when fewer than two candidates or one side constant)."""
    table = paper_comparison(ranking, names=names)
    if ids is not None:
        table = table[table["id"].isin(list(ids))]
    rows = []
    for basis in ("Avg.", "Avg. (common spp)"):
        chosen = table[(table["spp"] == basis)].dropna(subset=["ours", "paper"])
        rows.append({"basis": basis, **_kendall(chosen["ours"], chosen["paper"])})
    return pd.DataFrame(rows, columns=["basis", "n", "tau", "p_value"])


def _clean(record: dict) -> dict:
    """A table row with missing cells (None, NaN, pandas NA: what a concat or a CSV makes of an
    empty cell) as None."""
    return {k: (None if v is None or (not isinstance(v, str) and pd.isna(v)) else v) for k, v in record.items()}


def _cell(value, digits: int = 1, unit: str = "") -> str:
    number = _number(value)
    return "–" if number is None else f"{number:.{digits}f}{unit}"


def _ci_text(low, high, digits: int = 1) -> str:
    if _number(low) is None or _number(high) is None:
        return "no CI"
    return f"[{low:.{digits}f}, {high:.{digits}f}]"


def paper_comparison_markdown(ranking: pd.DataFrame, *, names: dict[int, str] | None = None,
                              labels: dict[str, str] | None = None, entries: int | None = None) -> str:
    """Markdown: per Table 3 candidate and spp ``ours (paper)``, the Avg. differences and the
    Kendall taus; a note when our ranking does not have the paper's 40 entries (``entries``,
    default ``len(ranking)``)."""
    labels = labels or {}
    table = paper_comparison(ranking, names=names)
    kendall = paper_kendall(ranking, names=names)
    entries = len(ranking) if entries is None else int(entries)
    spps = list(dict.fromkeys(table["spp"]))
    lines = ["# Beside the paper's Table 3 (relMSE scores)", "",
             "Our relMSE ranking scores (mean over our scenes) of the candidates of Zheng et al. 2021 Table 3 "
             "and, in parentheses, the paper's (mean over its 30 scenes); – where one side has no value. "
             "`Avg. (common spp)` averages both over the spp both tables have.", ""]
    if entries != PAPER_ENTRIES:
        lines += [f"**Scale:** our ranking has {entries} entries, the paper's {PAPER_ENTRIES}: the scores are not on "
                  f"the same scale (the best of K entries scores K), so compare orders, not numbers.", ""]
    else:
        lines += [f"Both rankings have {PAPER_ENTRIES} entries (same scale).", ""]
    lines += ["| candidate | " + " | ".join(spps) + " | Avg. diff |", "|---" * (len(spps) + 2) + "|"]
    for cid, group in table.groupby("id", sort=False):
        name = group["candidate"].iloc[0]
        cells = [f"{_cell(r.ours)} ({_cell(r.paper)})" for r in group.itertuples()]
        diff = group.loc[group["spp"] == "Avg.", "difference"].iloc[0]
        label = labels.get(name, pool.candidate(cid).label if name == pool.candidate_name(cid) else name)
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {_cell(diff)} |")
    missing = sorted({r.note for r in table.itertuples() if r.note.endswith("not in our ranking")})
    lines += [""] + [f"- {m}" for m in missing]
    lines += ["", "Kendall tau-b of our ordering of these candidates against the paper's:", ""]
    bases = paper_kendall(ranking, names=names, ids=PAPER_TABLE3_BASES)
    bases_prefix = f"among its bases alone (IDs {', '.join(map(str, PAPER_TABLE3_BASES))}), "
    for prefix, rows in (("", kendall), (bases_prefix, bases)):
        for r in rows.itertuples():
            text = "undefined (fewer than two candidates, or a constant side)" if r.tau is None else \
                f"tau = {r.tau:.3f} (p = {r.p_value:.3g}, n = {r.n})"
            lines.append(f"- {prefix}by {r.basis}: {text}")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# recommendations (Sec. 5.3.5-5.3.6)
# --------------------------------------------------------------------------------------------

REC_COLUMNS = ["metric", "scope", "key", "spp", "candidates", "ours", "ours_id", "ours_score", "ours_ci_low",
               "ours_ci_high", "ours_fraction", "named_candidates", "named", "named_id", "named_score",
               "named_ci_low", "named_ci_high", "named_fraction", "paper", "paper_id", "paper_score", "paper_ci_low",
               "paper_ci_high", "paper_fraction", "difference", "difference_ci_low", "difference_ci_high",
               "real_difference", "agrees", "named_agrees", "note"]
# The rule of ours that weighs relMSE and DSSIM together (Sec. 5.3.6 does so for #27 without a formula).
COMBINED_RULE = ("ours, not the paper's: the highest mean of the relMSE and DSSIM ranking scores (each the paper's "
                 "per-case score over the same entries, averaged over the scope's spp and the scenes)")
BOTH_METRICS = ("relmse", "dssim")
BOTH_COLUMNS = ["scope", "key", "spp", "set", "candidates", "relmse", "relmse_id", "relmse_score", "dssim", "dssim_id",
                "dssim_score", "combined", "combined_id", "combined_score", "combined_ci_low", "combined_ci_high",
                "combined_fraction", "paper", "paper_id", "paper_combined_score", "agrees", "note"]
SETS = {"all": "every pool ensemble in our data", "paper-named": "only the ensembles the paper names"}


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


def recommendations(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """The best ensemble per scope, derived from ``data``, beside the paper's choice.

    Scopes: each ensemble size present (2, 3, 4, 5, 6, 8), each spp band of
    :data:`mcbench.analysis.pool.SPP_BANDS` (mean score over the band's spp in our data; 32 spp is in low
    and medium), overall best and second (by ``Avg.``), and overall ``fewer``: the best ensemble
    with fewer members than the paper's #27 (size < :data:`mcbench.analysis.pool.FEWER_THAN`; the
    paper's "fewer base denoisers: #20", Sec. 5.3.6). Only pool ensembles present in the data
    compete (bases never).

    Two picks per scope: ``ours`` among every pool ensemble present, ``named`` among only the
    ensembles the paper names (:data:`mcbench.analysis.pool.PAPER_NAMED_IDS`, 12 of the 31; the
    pick the paper could have made). Each is the highest mean score (ties: the lower ID, noted).
    Columns :data:`REC_COLUMNS`: ``*_fraction`` is the fraction of the scene resamples
    (:func:`resample_indices`) in which the candidate holds the scope's place within its set (ties
    share it); ``difference`` ours - the paper's, with its paired interval; ``real_difference``
    yes/no (:func:`is_real`), empty when ours is the paper's or either is missing; ``agrees`` /
    ``named_agrees`` yes/no, empty when the paper has no choice for the scope (sizes 5, 6, 8).
    """
    indices = resample_indices(len(data.scenes), resampling=resampling)
    rows = []
    for scope, key, eligible, spps, place, paper_id in _scopes(data):
        row = dict.fromkeys(REC_COLUMNS)
        named = _paper_named(eligible)
        row.update(metric=data.metric, scope=scope, key=str(key), spp=" ".join(str(s) for s in spps),
                   candidates=len(eligible), named_candidates=len(named), note="")
        paper = pool.candidate_name(paper_id) if paper_id is not None else None
        row["paper_id"] = paper_id
        row["paper"] = paper
        if not spps or len(eligible) < place:
            row["note"] = "no spp of the band in our data" if not spps else f"fewer than {place} ensembles"
            rows.append(row)
            continue
        per_scene = data.scene_scores(spps)[:, data.columns(eligible)]
        best = _pick(per_scene, eligible, place, indices, resampling)
        mine, means, fractions, found = best["index"], best["means"], best["fractions"], best["found"]
        ours = best["name"]
        row.update(ours=ours, ours_id=best["id"], ours_score=best["score"], ours_ci_low=best["ci_low"],
                   ours_ci_high=best["ci_high"], ours_fraction=best["fraction"])
        notes = [f"tied with {', '.join('#%d' % pool.candidate(t).id for t in best['tied'])}"] if best["tied"] else []
        chosen = _pick(data.scene_scores(spps)[:, data.columns(named)], named, place, indices, resampling) \
            if named else None
        if chosen is not None:
            row.update(named=chosen["name"], named_id=chosen["id"], named_score=chosen["score"],
                       named_ci_low=chosen["ci_low"], named_ci_high=chosen["ci_high"],
                       named_fraction=chosen["fraction"])
            if chosen["tied"]:
                notes.append(f"paper-named pick tied with {_ids(chosen['tied'])}")
        else:
            notes.append(f"fewer than {place} paper-named ensembles in this scope")
        if paper is not None:
            row["agrees"] = "yes" if paper == ours else "no"
            if chosen is not None:
                row["named_agrees"] = "yes" if paper == chosen["name"] else "no"
            if paper in eligible:
                theirs = eligible.index(paper)
                row.update(paper_score=float(means[theirs]), paper_ci_low=found["ci_low"][theirs],
                           paper_ci_high=found["ci_high"][theirs], paper_fraction=float(fractions[theirs]))
                if paper != ours:
                    diff = bootstrap_ci(per_scene[:, mine] - per_scene[:, theirs], resampling=resampling).iloc[0]
                    real = is_real(diff["ci_low"], diff["ci_high"])
                    row.update(difference=float(diff["estimate"]), difference_ci_low=diff["ci_low"],
                               difference_ci_high=diff["ci_high"],
                               real_difference="" if real is None else ("yes" if real else "no"))
            else:
                notes.append(f"the paper's #{paper_id} is not in our data")
        row["note"] = "; ".join(notes)
        rows.append(row)
    table = pd.DataFrame(rows, columns=REC_COLUMNS)
    for column in ("candidates", "ours_id", "named_candidates", "named_id", "paper_id"):
        table[column] = table[column].astype("Int64")
    return table


def recommendations_both(by_metric: dict[str, StudyData], *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """relMSE's and DSSIM's picks side by side and one combined pick of ours, per scope and set.

    ``by_metric``: :class:`StudyData` of ``relmse`` and ``dssim`` over the same scenes, spp and
    entries (an empty table, :data:`BOTH_COLUMNS`, when either is missing). Scopes as
    :func:`recommendations` (sizes, spp bands, overall best, second, fewer); sets ``all`` (every
    pool ensemble present) and ``paper-named`` (:data:`mcbench.analysis.pool.PAPER_NAMED_IDS`).
    Per row: each metric's pick (highest mean score, ties the lower ID) and its score; the
    ``combined`` pick by :data:`COMBINED_RULE` -- per scene the mean of the two metrics' scores
    (each the scene's mean over the scope's spp), then the mean over scenes -- with its scene-
    bootstrap interval and the fraction of resamples in which it holds the place; the paper's
    choice, its combined score and whether the combined pick agrees with it.
    """
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
                notes.append(f"combined pick tied with {_ids(best['tied'])}")
            if paper is not None:
                row["agrees"] = "yes" if paper == best["name"] else "no"
                if paper in chosen:
                    row["paper_combined_score"] = float(best["means"][chosen.index(paper)])
                else:
                    notes.append(f"the paper's #{paper_id} is not in this set in our data")
            row["note"] = "; ".join(notes)
            rows.append(row)
    table = pd.DataFrame(rows, columns=BOTH_COLUMNS)
    for column in ("candidates", "relmse_id", "dssim_id", "combined_id", "paper_id"):
        table[column] = table[column].astype("Int64")
    return table


def _label(name, labels: dict[str, str]) -> str:
    if name is None:
        return "–"
    return labels.get(name) or (pool.candidate(name).label if _is_pool(name) else str(name))


def _percent(fraction) -> str:
    number = _number(fraction)
    return "–" if number is None else f"{100.0 * number:.0f} %"


def _score_ci(score, low, high) -> str:
    """A score with its interval; "–" alone when there is no score."""
    return "–" if _number(score) is None else f"{_cell(score)} {_ci_text(low, high)}"


def _of(name, count, labels: dict[str, str]) -> str:
    """A pick's label with the number of candidates it was picked from."""
    return "–" if name is None else f"{_label(name, labels)} (of {count})"


def _scope_text(scope: str, key: str) -> str:
    if scope == "size":
        return f"size {key}"
    if scope == "band":
        return f"{key} ({BAND_TEXT.get(key, '')})"
    return f"overall {key}" + (f" (size < {pool.FEWER_THAN})" if key == "fewer" else "")


def recommendation_sentences(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                             n_resamples: int | None = None) -> list[str]:
    """One sentence a user can act on per row of :func:`recommendations`."""
    labels = labels or {}
    out = []
    for r in map(_clean, table.to_dict("records")):
        r["paper_id"] = None if r["paper_id"] is None else int(r["paper_id"])
        metric = METRIC_LABELS.get(r["metric"], r["metric"])
        if r["scope"] == "size":
            lead = f"With {r['key']} base denoisers ({metric})"
        elif r["scope"] == "band":
            lead = f"For {BAND_TEXT.get(r['key'], r['key'])} ({metric}; our spp {r['spp'] or 'none'})"
        elif r["key"] == "fewer":
            lead = f"Overall with fewer than {pool.FEWER_THAN} base denoisers ({metric})"
        else:
            lead = f"Overall ({metric}), {'first' if r['key'] == 'best' else 'second'} choice"
        if r["ours"] is None:
            out.append(f"{lead}: no recommendation ({r['note']}).")
            continue
        resamples = f" of {n_resamples}" if n_resamples else ""
        what = "top" if r["key"] != "second" else "second"
        sentence = (f"{lead}: use {_label(r['ours'], labels)} (score {_cell(r['ours_score'])} "
                    f"{_ci_text(r['ours_ci_low'], r['ours_ci_high'])}, {what} in {_percent(r['ours_fraction'])}"
                    f"{resamples} scene resamples)")
        if r.get("named") is not None and r["named"] != r["ours"]:
            sentence += (f"; among only the paper's named ensembles: {_label(r['named'], labels)} "
                         f"(score {_cell(r['named_score'])})")
        elif r.get("named") is not None:
            sentence += "; also the best of the paper's named ensembles"
        if r["paper"] is None:
            sentence += "; the paper recommends none for this case."
        elif r["paper"] == r["ours"]:
            sentence += f"; the paper recommends the same, #{r['paper_id']}."
        elif r["paper_score"] is None:
            sentence += f"; the paper recommends #{r['paper_id']}, which is not in our data."
        else:
            verdict = {"yes": "really different from ours", "no": "not really different from ours",
                       "": "difference undetermined"}[r["real_difference"] or ""]
            sentence += (f"; the paper recommends #{r['paper_id']} ({what} in {_percent(r['paper_fraction'])}), "
                         f"{verdict} (ours - paper's {_cell(r['difference'])}, "
                         f"{_ci_text(r['difference_ci_low'], r['difference_ci_high'])}).")
        notes = [n for n in (r["note"] or "").split("; ") if n and not n.startswith("the paper's")]
        if notes:
            sentence = sentence[:-1] + f" ({'; '.join(notes)})."
        out.append(sentence)
    return out


def recommendations_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                             resampling: Resampling = Resampling()) -> str:
    """The recommendations as a short Markdown table and the sentences."""
    labels = labels or {}
    level = f"{100 * resampling.confidence:.0f} %"
    lines = ["# Recommendations derived from the data (Zheng et al. 2021 Sec. 5.3.5-5.3.6)", "",
             f"Best pool ensemble per scope by mean ranking score (bases never compete), its {level} scene-bootstrap "
             f"interval and the fraction of {resampling.n_resamples} paired scene resamples in which it holds the "
             f"place (seed {resampling.seed}); beside it the best among only the ensembles the paper names "
             f"({', '.join(f'#{i}' for i in pool.PAPER_NAMED_IDS)}; the other pool rows are ours), then the "
             f"paper's choice. A difference is real when the paired interval of ours - paper's excludes 0. "
             f"'overall fewer': the best with fewer than {pool.FEWER_THAN} members (Sec. 5.3.6: #20 for users "
             f"who want fewer base denoisers than #27). Both metrics together: recommendations_metrics.md.", "",
             "| metric | scope | ours (all pool ensembles) | score | resamples | ours (paper-named only) | score | paper | "
             "score | resamples | ours - paper | real? |",
             "|---" * 12 + "|"]
    for r in map(_clean, table.to_dict("records")):
        lines.append(f"| {METRIC_LABELS.get(r['metric'], r['metric'])} | {_scope_text(r['scope'], r['key'])} | "
                     f"{_of(r['ours'], r['candidates'], labels)} | "
                     f"{_score_ci(r['ours_score'], r['ours_ci_low'], r['ours_ci_high'])} | "
                     f"{_percent(r['ours_fraction'])} | {_of(r.get('named'), r.get('named_candidates'), labels)} | "
                     f"{_cell(r.get('named_score'))} | {_label(r['paper'], labels)} | {_cell(r['paper_score'])} | "
                     f"{_percent(r['paper_fraction'])} | {_cell(r['difference'])} "
                     f"{'' if r['difference'] is None else _ci_text(r['difference_ci_low'], r['difference_ci_high'])}"
                     f" | {r['real_difference'] or '–'} |")
    lines += ["", *[f"- {s}" for s in recommendation_sentences(table, labels=labels,
                                                                n_resamples=resampling.n_resamples)]]
    return "\n".join(lines) + "\n"


def recommendations_both_sentences(table: pd.DataFrame, *, labels: dict[str, str] | None = None) -> list[str]:
    """One line per scope of :func:`recommendations_both` (both sets)."""
    labels = labels or {}
    out = []
    for (scope, key), group in table.groupby(["scope", "key"], sort=False):
        parts = []
        for r in map(_clean, group.to_dict("records")):
            if r["combined"] is None:
                parts.append(f"{r['set']}: none ({r['note']})")
                continue
            parts.append(f"{r['set']}: relMSE {_label(r['relmse'], labels)}, DSSIM {_label(r['dssim'], labels)}, "
                         f"combined (ours) {_label(r['combined'], labels)} ({_cell(r['combined_score'])} "
                         f"{_ci_text(r['combined_ci_low'], r['combined_ci_high'])}, "
                         f"{_percent(r['combined_fraction'])} of resamples)")
        paper = group["paper_id"].iloc[0]
        tail = "" if pd.isna(paper) else f"; the paper: #{int(paper)}"
        out.append(f"{_scope_text(scope, key)}: " + "; ".join(parts) + tail + ".")
    return out


def recommendations_both_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                                  resampling: Resampling = Resampling()) -> str:
    """:func:`recommendations_both` as Markdown: both metrics' picks side by side and our combined pick."""
    labels = labels or {}
    level = f"{100 * resampling.confidence:.0f} %"
    lines = ["# Recommendations by relMSE and DSSIM together (Zheng et al. 2021 Sec. 5.3.5-5.3.6)", "",
             "Sec. 5.3.6 recommends #27 as working well 'under both the relMSE and DSSIM metrics' without a "
             "formula for weighing the two. Here each metric's pick, side by side, and one combined rule, "
             f"**{COMBINED_RULE}**; its {level} scene-bootstrap interval and the fraction of "
             f"{resampling.n_resamples} paired scene resamples in which the pick holds the place. Sets: "
             f"'all' = every pool ensemble in our data; 'paper-named' = only the ensembles the paper names "
             f"({', '.join(f'#{i}' for i in pool.PAPER_NAMED_IDS)}).", ""]
    if table.empty:
        return "\n".join(lines + ["Needs both relmse and dssim among the study's metrics, with values in "
                                  "metrics.csv; one is missing."]) + "\n"
    lines += ["| scope | set (candidates) | relMSE pick | score | DSSIM pick | score | combined pick (ours) | score | resamples "
              "| paper | paper's combined score | agrees |", "|---" * 12 + "|"]
    for r in map(_clean, table.to_dict("records")):
        lines.append(f"| {_scope_text(r['scope'], r['key'])} | {r['set']} ({r['candidates']}) | "
                     f"{_label(r['relmse'], labels)} | "
                     f"{_cell(r['relmse_score'])} | {_label(r['dssim'], labels)} | {_cell(r['dssim_score'])} | "
                     f"{_label(r['combined'], labels)} | "
                     f"{_score_ci(r['combined_score'], r['combined_ci_low'], r['combined_ci_high'])} | "
                     f"{_percent(r['combined_fraction'])} | "
                     f"{_label(r['paper'], labels)} | {_cell(r['paper_combined_score'])} | {r['agrees'] or '–'} |")
    lines += ["", *[f"- {s}" for s in recommendations_both_sentences(table, labels=labels)]]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# the paper's findings (Sec. 5.3.4)
# --------------------------------------------------------------------------------------------

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


def ci_verdict(ci_low, ci_high, *, claim: str = "above", threshold: float = 0.0) -> str:
    """Verdict of the claim "quantity ``claim`` (above/below) ``threshold``" from its interval:
    reproduced when the interval lies entirely on the claimed side (strictly), not reproduced
    when entirely on the other side, inconclusive otherwise or without an interval."""
    low, high = _number(ci_low), _number(ci_high)
    if low is None or high is None:
        return INCONCLUSIVE
    if claim not in ("above", "below"):
        raise ValueError(f"claim must be 'above' or 'below', got {claim!r}")
    if low > threshold:
        return REPRODUCED if claim == "above" else NOT_REPRODUCED
    if high < threshold:
        return REPRODUCED if claim == "below" else NOT_REPRODUCED
    return INCONCLUSIVE


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


def _ids(names) -> str:
    return ", ".join(f"#{pool.candidate(n).id}" for n in names)


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


def _failures(wins: np.ndarray, data: StudyData) -> list[str]:
    """``scene@spp`` of the cases (scenes, spp) where ``wins`` is False."""
    return [f"{data.scenes[i]}@{data.spps[j]}" for i, j in zip(*np.nonzero(~wins))]


def _listed(items: list[str], limit: int = 8) -> str:
    return ", ".join(items[:limit]) + (f" … ({len(items) - limit} more)" if len(items) > limit else "")


def _member_label(name: str) -> str:
    return pool.candidate(name).label


PAIR_COLUMNS = ["metric", "ensemble", "id", "member", "member_id", "spp", "cases", "wins", "fraction", "ci_low",
                "ci_high", "ci_method", "verdict", "failures"]


def pair_members(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """Finding (b) case by case: every size-2 pool ensemble against each of its two members
    (Sec. 5.3.4: "a combination of 2 base denoisers almost always outperforms the corresponding
    individual base denoisers"), on the metric values.

    One row (:data:`PAIR_COLUMNS`) per size-2 ensemble of :func:`size2_pairs`, ``member`` (each
    of the two, then ``both``: the pair outperforms both members in the case) and ``spp`` (each
    spp of the data, then ``all``): ``cases`` compared, ``wins`` (the pair's error strictly
    below), ``fraction`` = wins / cases with the scene-bootstrap interval of the per-scene
    fraction, ``verdict`` of "fraction above :data:`ALMOST_ALWAYS`" (:func:`ci_verdict`) and the
    ``failures``: the cases (``scene@spp``) the pair does not outperform it.
    """
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
                         "failures": " ".join(_failures(chosen, data) if label == "all" else
                                              [f"{data.scenes[s]}@{label}" for s in np.nonzero(~chosen[:, 0])[0]])})
    table = pd.DataFrame(rows, columns=PAIR_COLUMNS)
    table["member_id"] = table["member_id"].astype("Int64")
    return table


def pair_members_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                          resampling: Resampling = Resampling(), skipped: dict[str, str] | None = None) -> str:
    """:func:`pair_members` as Markdown: per metric, wins/cases per spp and overall with the
    interval and verdict, then the cases each pair fails."""
    labels = labels or {}
    lines = ["# Finding (b): size-2 ensembles against each of their members (Zheng et al. 2021 Sec. 5.3.4)", "",
             "The paper: \"a combination of 2 base denoisers almost always outperforms the corresponding individual "
             "base denoisers\". Per metric, every size-2 ensemble of the pool in our data against each of its two "
             "members and against both at once: cases in which its error is strictly below the member's "
             "(wins/cases) per spp and over all spp. 'Almost always' is read as a fraction above "
             f"{ALMOST_ALWAYS:.2f} (worse in under {100 * ALMOST:.0f} % of cases): reproduced when the "
             f"{100 * resampling.confidence:.0f} % scene-bootstrap interval of the fraction lies above it, not "
             "reproduced when below, inconclusive otherwise.", ""]
    for metric, reason in (skipped or {}).items():
        lines += [f"- {METRIC_LABELS.get(metric, metric)}: {reason}"]
    if table.empty:
        return "\n".join(lines + ["", "No size-2 ensemble of the pool with both members in our data."]) + "\n"
    for metric, by_metric in table.groupby("metric", sort=False):
        spps = [s for s in dict.fromkeys(by_metric["spp"]) if s != "all"]
        lines += ["", f"## {METRIC_LABELS.get(metric, metric)}", "",
                  "| size-2 ensemble | outperforms | " + " | ".join(f"{s} spp" for s in spps)
                  + " | all spp | fraction | interval | verdict |", "|---" * (len(spps) + 6) + "|"]
        failed = []
        for (name, member), group in by_metric.groupby(["ensemble", "member"], sort=False):
            cells = {r["spp"]: r for r in map(_clean, group.to_dict("records"))}
            every = cells["all"]
            against = "both members" if member == "both" else _label(member, labels)
            lines.append(f"| {_label(name, labels)} | {against} | "
                         + " | ".join(f"{cells[s]['wins']}/{cells[s]['cases']}" for s in spps)
                         + f" | {every['wins']}/{every['cases']} | {_cell(every['fraction'], 3)} | "
                         f"{_ci_text(every['ci_low'], every['ci_high'], 3)} | **{every['verdict']}** |")
            if every["failures"]:
                failed.append(f"- {_label(name, labels)} does not outperform {against} in: "
                              + ", ".join(str(every["failures"]).split()))
        lines += ["", "Cases the pair does not outperform (`scene@spp`):", ""] + (failed or ["- none"])
    return "\n".join(lines) + "\n"


def _finding_members(out: _Rows) -> None:
    """Finding (b) as the paper states it: size-2 ensembles against each of their members; then
    our own pooled statistic over every size, secondary and without a verdict."""
    data = out.data
    pairs, skipped = size2_pairs(data)
    left = f"size-2 ensembles without both members in the data left out: {_ids(skipped)}" if skipped else ""
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
                lost = _failures(w, data)
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
            out.add(finding, f"size {size}: {what[0]} ({_ids(plain)}) - {what[1]} ({_ids(flagged)})", diff)
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
        out.add(finding, f"{_ids(better) or 'others'} - #{pool.candidate(worse).id}", verdict=INCONCLUSIVE,
                note="not in our data")
        return
    row = out.add(finding, f"mean of {_ids(better)} - #{pool.candidate(worse).id}",
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
        quantity = f"{band} band ({BAND_TEXT[band]}): learned ({_ids(learned)}) - classical ({_ids(classical)})"
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
    below = [n for n, h in zip(names, per_ensemble["ci_high"]) if _number(h) is not None and h < 0]
    above = [n for n, lo in zip(names, per_ensemble["ci_low"]) if _number(lo) is not None and lo > 0]
    out.add("f", "fraction of ensembles whose Avg. exceeds their best member's",
            estimate=float(np.mean(margins.mean(axis=0) > 0)),
            note=f"{len(above)} of {len(names)} significantly above their best member; significantly below: "
                 f"{_ids(below) or 'none'}")
    out.add("f", "fraction of (ensemble, member) pairs with the ensemble's Avg. above the member's",
            estimate=float(np.mean(pair_wins)))
    row = out.add("f", f"mean over {len(names)} ensembles of (Avg. - best member's Avg.)", margins.mean(axis=1),
                  rule="claimed above 0; verdict from the interval (best member: the member with the highest Avg.)")
    row["verdict"] = ci_verdict(row["ci_low"], row["ci_high"], claim="above")


def findings(data: StudyData, *, resampling: Resampling = Resampling()) -> pd.DataFrame:
    """The observations of Sec. 5.3.4 with numbers and verdicts (:data:`FINDING_COLUMNS`).

    Every quantity is a mean over scenes of a per-scene quantity (scores: the per-scene mean over
    spp), with its paired scene-bootstrap interval; rows with a ``verdict`` decide a claim by
    :func:`ci_verdict`, the others are the numbers behind it (empty verdict).

    a. Size: mean score per size (1 = the bases). "Grows up to 5": every step between
       consecutive sizes <= 5 above 0. "Levels off past 5": not reproduced when some size k > 5
       is above size 5 (interval of mean(k) - mean(5) above 0: the gains go on); reproduced when
       none is *and* the gain shrinks (interval of (mean5 - mean4) - (mean(k1) - mean5) above 0,
       k1 the smallest size > 5: not mere absence of evidence); inconclusive otherwise.
       Also the Table 3 chain #16 < #24 < #30 < #33 > #35 step by step (all steps must hold).
    b. As the paper states it, of size-2 ensembles (:func:`size2_pairs`) against each of their
       two members, on the metric values per case (the pair *outperforms* a member when its error
       is strictly below): per (pair, member) the fraction of cases it does, with a verdict and
       the failing cases in the note (all of them in :func:`pair_members`); per spp the fraction
       of (pair, member) comparisons won and of pairs outperforming both; over all spp the
       fraction of (case, pair, member) comparisons won, which decides: reproduced when its
       interval lies above :data:`ALMOST_ALWAYS` (0.90), not reproduced when below. Then, ours
       and secondary (no verdict, labelled so): every ensemble of every size pooled against its
       members -- what this finding tested before, not the paper's claim.
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


def findings_markdown(table: pd.DataFrame, *, resampling: Resampling = Resampling()) -> str:
    """The findings as Markdown, one section per metric and finding."""
    level = f"{100 * resampling.confidence:.0f} %"
    lines = ["# The paper's findings (Zheng et al. 2021 Sec. 5.3.4), checked with numbers", "",
             f"Means over scenes with {level} paired scene-bootstrap intervals ({resampling.n_resamples} resamples, "
             f"seed {resampling.seed}; BCa, percentile where BCa is degenerate). A claim 'above t' is reproduced "
             f"when its interval lies above t, not reproduced when below, inconclusive when it contains t.", ""]
    for metric, by_metric in table.groupby("metric", sort=False):
        lines += [f"## {METRIC_LABELS.get(metric, metric)}", ""]
        for finding, group in by_metric.groupby("finding", sort=True):
            lines += [f"### {finding}. {CLAIMS[finding]}", "", "| quantity | estimate | interval | verdict | note |",
                      "|---|---|---|---|---|"]
            digits = 3 if finding == "b" or "fraction" in " ".join(group["quantity"]) else 2
            for r in map(_clean, group.to_dict("records")):
                verdict = f"**{r['verdict']}**" if r["verdict"] else ""
                interval = "" if r["ci_low"] is None and r["ci_high"] is None else _ci_text(r["ci_low"], r["ci_high"],
                                                                                            digits)
                lines.append(f"| {r['quantity']} | {_cell(r['estimate'], digits)} | {interval} | {verdict} | "
                             f"{r['note']} |")
            rules = list(dict.fromkeys(r for r in group["rule"] if r))
            lines += [""] + [f"Rule: {r}." for r in rules] + [""]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# references you can trust: raw against reference-noise-corrected relMSE
# --------------------------------------------------------------------------------------------

REFERENCE_NOISE_COLUMNS = ["spp", "kendall_tau", "max_abs_change", "real_changes", "changed", "top_raw",
                           "top_corrected", "agree"]


def reference_noise_effect(raw: StudyData, corrected: StudyData, *, resampling: Resampling = Resampling(),
                           top: int = 3) -> pd.DataFrame:
    """How the ranking moves when relMSE is corrected for the reference's own noise
    (:func:`mcbench.analysis.metrics.relmse_corrected`), per spp and over all spp (``Avg.``).

    ``raw`` and ``corrected``: the two metrics' :class:`StudyData` over the same scenes, spp and
    entries. Per column: the Kendall tau of the two mean-score orderings, the largest change of a
    mean score, and the entries whose score changes *really* (the paired scene-bootstrap interval
    of corrected - raw per-scene score excludes 0, :func:`is_real`), with the ``top`` entries of
    each ordering. ``agree`` is "yes" when no entry's score changes really: the raw ranking is then
    trustworthy within the intervals, i.e. the references are quiet enough for this study; "no"
    names the spp at which the reference noise reorders candidates.
    """
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


def reference_noise_markdown(table: pd.DataFrame, *, labels: dict[str, str] | None = None,
                             resampling: Resampling = Resampling()) -> str:
    """The reference-noise table as Markdown with a verdict sentence."""
    labels = labels or {}
    lines = ["# References you can trust: raw against corrected relMSE", "",
             "Scores by relMSE against the reference (raw) and by relMSE corrected for the reference's own "
             "noise with its stored variance (corrected; `mcbench.analysis.metrics.relmse_corrected`). An entry's score "
             "changes *really* when the paired scene-bootstrap interval of its score change excludes 0 "
             f"({100 * resampling.confidence:.0f} %, {resampling.n_resamples} resamples).", ""]
    if table.empty:
        return "\n".join(lines + ["No relmse and relmse_corrected values to compare (both must be configured)."]) + "\n"
    lines += ["| spp | Kendall τ | largest change | real changes | top 3 raw | top 3 corrected |", "|---|---|---|---|---|---|"]
    for r in map(_clean, table.to_dict("records")):
        tops = [", ".join(labels.get(n, n) for n in str(r[k] or "").split()) for k in ("top_raw", "top_corrected")]
        changed = ", ".join(labels.get(n, n) for n in str(r["changed"] or "").split()) or "none"
        lines.append(f"| {r['spp']} | {_cell(r['kendall_tau'], 3)} | {_cell(r['max_abs_change'], 2)} | "
                     f"{r['real_changes']} ({changed}) | {tops[0]} | {tops[1]} |")
    disagree = [str(s) for s, a in zip(table["spp"], table["agree"]) if a != "yes"]
    lines += ["", "Verdict: " + ("the raw and corrected rankings agree within the intervals at every spp; the "
                                 "references are quiet enough for this study." if not disagree else
                                 "the reference noise really changes scores at spp " + ", ".join(disagree)
                                 + "; there, read the corrected ranking (or render longer references).")]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# writers
# --------------------------------------------------------------------------------------------

def study_outputs(out_dir, metrics) -> list[str]:
    """Every file :func:`write_study_tables` writes under ``out_dir``: :data:`STUDY_FILES` and
    ``scores_ci_<metric>.csv`` per metric of ``metrics`` (written, header only, for a metric
    absent from the data, so a rule can declare the list)."""
    return [str(Path(out_dir) / f) for f in STUDY_FILES] + [str(Path(out_dir) / f"scores_ci_{m}.csv") for m in metrics]


def _labels_for(names, labels: dict[str, str] | None) -> dict[str, str]:
    labels = dict(labels or {})
    return {n: labels.get(n) or (pool.candidate(n).label if _is_pool(n) else ("noisy input" if n == NOISY else n))
            for n in names}


SCORE_CI_COLUMNS = ["candidate", "id", "avg", "avg_ci_low", "avg_ci_high", "ci_method"] + \
    [f"{b}{s}" for b in pool.SPP_BANDS for s in ("", "_ci_low", "_ci_high")]


def write_study_tables(metrics_csv, out_dir, *, metrics=("relmse", "dssim"), labels: dict[str, str] | None = None,
                       candidates=None, noisy: str | None = NOISY, n_resamples: int = N_RESAMPLES, seed: int = SEED,
                       confidence: float = CONFIDENCE) -> dict[str, pd.DataFrame]:
    """The study's tables from ``metrics.csv``, written atomically under ``out_dir``
    (``results/tables/study/``). Files (:func:`study_outputs`):

    * ``paper_table3.csv`` (:func:`paper_comparison`: id, candidate, spp, ours, paper,
      difference, note; relMSE) and ``paper_table3.md`` (with the Kendall taus, the scale note);
    * ``recommendations.csv`` (:data:`REC_COLUMNS`, one block per metric) and
      ``recommendations.md`` (table and sentences);
    * ``recommendations_metrics.csv`` (:func:`recommendations_both`: :data:`BOTH_COLUMNS`) and
      ``.md``: relMSE's and DSSIM's picks side by side and our combined pick;
    * ``findings.csv`` (:data:`FINDING_COLUMNS`) and ``findings.md``;
    * ``pair_members.csv`` (:func:`pair_members`: :data:`PAIR_COLUMNS`, one block per metric)
      and ``.md``: finding (b), each size-2 ensemble against each member, per spp and overall;
    * ``scores_ci_<metric>.csv`` per metric of ``metrics`` (:func:`score_cis`:
      :data:`SCORE_CI_COLUMNS`);
    * ``summary.md``: the sentences, the Kendall tau, the verdicts, the metrics skipped.

    ``metrics`` absent from the data are skipped (their CSV holds the header only, summary.md
    says so); a pool candidate missing in a case stops with a :class:`mcbench.BenchError`
    naming it. ``candidates`` (default: the pool candidates present) and ``noisy`` are the
    scored entries. Returns the tables by file stem.
    """
    table = read_table(metrics_csv, columns=("scene", "spp", "candidate", "metric", "value"))
    resampling = Resampling(n_resamples=n_resamples, seed=seed, confidence=confidence)
    out_dir = Path(out_dir)
    available = set(table["metric"])
    recs, finds, pair_tables, written, skipped = [], [], [], {}, []
    data_by_metric = {}
    for metric in metrics:
        path = out_dir / f"scores_ci_{metric}.csv"
        if metric not in available:
            skipped.append(metric)
            write_csv(path, pd.DataFrame(columns=SCORE_CI_COLUMNS))
            continue
        data = study_data(table, metric, candidates=candidates, noisy=noisy, source=str(metrics_csv))
        data_by_metric[metric] = data
        cis = score_cis(data, resampling=resampling)
        write_csv(path, cis[SCORE_CI_COLUMNS], float_format="%.4f")
        written[f"scores_ci_{metric}"] = cis
        recs.append(recommendations(data, resampling=resampling))
        finds.append(findings(data, resampling=resampling))
        pair_tables.append(pair_members(data, resampling=resampling))
    names = sorted({n for d in data_by_metric.values() for n in d.names})
    shown = _labels_for(names, labels)

    rec_table = pd.concat(recs, ignore_index=True) if recs else pd.DataFrame(columns=REC_COLUMNS)
    find_table = pd.concat(finds, ignore_index=True) if finds else pd.DataFrame(columns=FINDING_COLUMNS)
    write_csv(out_dir / "recommendations.csv", rec_table, float_format="%.4f")
    write_text(out_dir / "recommendations.md", recommendations_markdown(rec_table, labels=shown, resampling=resampling))
    write_csv(out_dir / "findings.csv", find_table, float_format="%.4f")
    write_text(out_dir / "findings.md", findings_markdown(find_table, resampling=resampling))
    pair_table = pd.concat([t for t in pair_tables if len(t)], ignore_index=True) if any(len(t) for t in pair_tables) \
        else pd.DataFrame(columns=PAIR_COLUMNS)
    write_csv(out_dir / "pair_members.csv", pair_table, float_format="%.4f")
    write_text(out_dir / "pair_members.md", pair_members_markdown(pair_table, labels=shown, resampling=resampling,
                                                                  skipped={m: "no values; skipped" for m in skipped}))
    both = recommendations_both(data_by_metric, resampling=resampling)
    write_csv(out_dir / "recommendations_metrics.csv", both, float_format="%.4f")
    write_text(out_dir / "recommendations_metrics.md", recommendations_both_markdown(both, labels=shown,
                                                                                    resampling=resampling))

    kendall = None
    if "relmse" in data_by_metric:
        data = data_by_metric["relmse"]
        ranking = ranking_from(data)
        paper = paper_comparison(ranking)
        kendall = paper_kendall(ranking)
        write_csv(out_dir / "paper_table3.csv", paper, float_format="%.4f")
        write_text(out_dir / "paper_table3.md", paper_comparison_markdown(ranking, labels=shown, entries=data.entries))
    else:
        paper = pd.DataFrame(columns=["id", "candidate", "spp", "ours", "paper", "difference", "note"])
        write_csv(out_dir / "paper_table3.csv", paper)
        write_text(out_dir / "paper_table3.md", "# Beside the paper's Table 3 (relMSE scores)\n\nNo relMSE values in "
                                                "the metrics table (or relmse not among the study's metrics).\n")

    lines = ["# The 39-candidate study: summary", "",
             f"Scene bootstrap: {resampling.n_resamples} paired resamples, seed {resampling.seed}, "
             f"{100 * resampling.confidence:.0f} % intervals. Rows of the pool marked 'filled' are our choice, "
             f"not the paper's (see mcbench/analysis/pool.py).", ""]
    for metric, data in data_by_metric.items():
        lines.append(f"- {METRIC_LABELS.get(metric, metric)}: {len(data.scenes)} scene(s), spp "
                     f"{', '.join(map(str, data.spps))}, {data.entries} entries"
                     + ("" if data.entries == PAPER_ENTRIES else f" (the paper: {PAPER_ENTRIES})"))
    lines += [f"- {m}: no values in {Path(metrics_csv).name}; skipped" for m in skipped]
    lines += ["", "## Recommendations", ""]
    lines += [f"- {s}" for s in recommendation_sentences(rec_table, labels=shown, n_resamples=resampling.n_resamples)]
    lines += ["", "## Recommendations by relMSE and DSSIM together", "", f"Combined rule: {COMBINED_RULE}.", ""]
    lines += [f"- {s}" for s in recommendations_both_sentences(both, labels=shown)] if len(both) else \
        ["- needs both relmse and dssim in the study's metrics"]
    if kendall is not None:
        lines += ["", "## Beside the paper's Table 3", ""]
        for r in kendall.itertuples():
            lines.append(f"- Kendall tau by {r.basis}: " + ("undefined" if r.tau is None else
                                                            f"{r.tau:.3f} (p = {r.p_value:.3g}, n = {r.n})"))
    if "relmse" in data_by_metric and "relmse_corrected" in data_by_metric:
        noise = reference_noise_effect(data_by_metric["relmse"], data_by_metric["relmse_corrected"],
                                       resampling=resampling)
    else:
        noise = pd.DataFrame(columns=REFERENCE_NOISE_COLUMNS)
    write_csv(out_dir / "reference_noise.csv", noise, float_format="%.4f")
    noise_text = reference_noise_markdown(noise, labels=shown, resampling=resampling)
    write_text(out_dir / "reference_noise.md", noise_text)
    written["reference_noise"] = noise
    lines += ["", "## References", "", noise_text.strip().splitlines()[-1]]
    lines += ["", "## Findings", ""]
    # finding (b)'s per-(pair, member) verdicts are its parts: pair_members.md and findings.md hold them
    headline = (find_table["verdict"] != "") & ~((find_table["finding"] == "b") & find_table["quantity"].str.startswith("#"))
    for r in map(_clean, find_table[headline].to_dict("records")):
        numbers = "" if r["estimate"] is None else \
            f" ({_cell(r['estimate'], 3)}, {_ci_text(r['ci_low'], r['ci_high'], 3)})"
        lines.append(f"- {METRIC_LABELS.get(r['metric'], r['metric'])}, {r['finding']}: {r['quantity']}: "
                     f"**{r['verdict']}**{numbers}")
    write_text(out_dir / "summary.md", "\n".join(lines) + "\n")
    written.update(paper_table3=paper, recommendations=rec_table, findings=find_table, pair_members=pair_table,
                   recommendations_metrics=both)
    return written
