"""The scene bootstrap of the 39-candidate study: confidence intervals, real differences,
place fractions and verdicts.

Every statistic of the study is a mean over scenes of a per-scene quantity (a score, a
difference of scores, a fraction of cases), so the uncertainty is that of the scenes: whole
scenes are resampled with replacement, paired (one resample moves every candidate's scores
together; differences are formed per scene before resampling). Confidence intervals come from
:func:`scipy.stats.bootstrap` with a fixed seed (:class:`~mcbench.analysis.study.data.Resampling`;
numpy ``Generator``), confidence 0.95, method **BCa** (bias-corrected and accelerated:
second-order accurate, it corrects for the skew a bounded rank score has near the top or bottom
of the scale). BCa is undefined for degenerate data (all resampled statistics equal, e.g. a
candidate that wins every case) and unstable with very few scenes; a column whose BCa interval
is not finite falls back to the **percentile** interval and says so in its ``ci_method``. With
fewer than two scenes no interval is given (empty cells). Which candidate is top, per scope, is
counted on one matrix of resampled scene indices (:func:`resample_indices`) shared by every
candidate and scope.

A difference is **real** when the 95 % paired bootstrap interval of the per-scene difference
excludes 0 (strictly: low > 0 or high < 0).

Verdicts (:func:`ci_verdict`): a claim "quantity above t" is **reproduced** when the quantity's
interval lies entirely above t, **not reproduced** when it lies entirely below t,
**inconclusive** otherwise (it contains t, or no interval could be formed). "Below t" mirrors
it. Claims made of several parts combine as documented in
:func:`mcbench.analysis.study.findings.findings`. Never by eye: only the intervals decide.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy import stats

from mcbench.analysis import pool
from mcbench.analysis.study.data import Resampling, StudyData, avg_scores, finite_or_none, pool_id

__all__ = ["REPRODUCED", "NOT_REPRODUCED", "INCONCLUSIVE", "SCORE_CI_COLUMNS", "resample_indices", "bootstrap_ci",
           "is_real", "difference_ci", "score_cis", "place_fractions", "ci_verdict"]

REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE = "reproduced", "not reproduced", "inconclusive"
# the columns of score_cis (and of scores_ci_<metric>.csv)
SCORE_CI_COLUMNS = ["candidate", "id", "avg", "avg_ci_low", "avg_ci_high", "ci_method"] + \
    [f"{b}{s}" for b in pool.SPP_BANDS for s in ("", "_ci_low", "_ci_high")]


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
    table = pd.DataFrame({"candidate": list(data.names), "id": [pool_id(n) for n in data.names],
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



def ci_verdict(ci_low, ci_high, *, claim: str = "above", threshold: float = 0.0) -> str:
    """Verdict of the claim "quantity ``claim`` (above/below) ``threshold``" from its interval:
    reproduced when the interval lies entirely on the claimed side (strictly), not reproduced
    when entirely on the other side, inconclusive otherwise or without an interval."""
    low, high = finite_or_none(ci_low), finite_or_none(ci_high)
    if low is None or high is None:
        return INCONCLUSIVE
    if claim not in ("above", "below"):
        raise ValueError(f"claim must be 'above' or 'below', got {claim!r}")
    if low > threshold:
        return REPRODUCED if claim == "above" else NOT_REPRODUCED
    if high < threshold:
        return REPRODUCED if claim == "below" else NOT_REPRODUCED
    return INCONCLUSIVE
