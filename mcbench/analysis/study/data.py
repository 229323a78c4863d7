"""One metric of the 39-candidate study on a full grid, and the constants the study shares.

:func:`study_data` turns the tidy metrics table (columns scene, spp, entry, metric, value;
the pool's harness names of :mod:`mcbench.analysis.pool` plus ``noisy``) into
:class:`StudyData`: values and the paper's per-case scores as (scenes, spp, names) arrays.

Scores are the paper's (:func:`mcbench.analysis.ranking.case_scores`: in each case (scene, spp)
the best of K entries gets K, the worst 1) over the pool candidates present in the data plus the
noisy input -- 40 entries when the pool is complete, as in the paper. A candidate's per-scene
score is the mean over spp of its scores in that scene; its ``Avg.`` is the mean over scenes of
those. :func:`study_data` insists on a full grid (every scene has every spp, every case every
entry: :func:`mcbench.analysis.ranking.check_complete`), under which this equals the ranking
table's mean over spp of the mean over scenes (:func:`avg_scores` checks it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from mcbench import NOISY, BenchError
from mcbench.analysis import pool
from mcbench.analysis.ranking import case_scores, check_complete

__all__ = ["PAPER_ENTRIES", "SEED", "N_RESAMPLES", "CONFIDENCE", "BAND_TEXT", "Resampling", "StudyData",
           "is_pool_name", "pool_id", "id_list", "finite_or_none", "study_data", "avg_scores", "ranking_from"]

PAPER_ENTRIES = 40              # the paper's scale: 39 candidates + the noisy input
SEED = 20210815
N_RESAMPLES = 2000
CONFIDENCE = 0.95
BAND_TEXT = {"low": "4–32 spp", "medium": "32–256 spp", "high": ">256 spp"}


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
        return [n for n in self.names if n != NOISY and is_pool_name(n) and not pool.candidate(n).is_base]

    @property
    def bases(self) -> list[str]:
        return [n for n in self.names if n != NOISY and is_pool_name(n) and pool.candidate(n).is_base]


def is_pool_name(name: str) -> bool:
    """Whether ``name`` is a candidate of the pool (:func:`mcbench.analysis.pool.candidate`)."""
    try:
        pool.candidate(name)
    except BenchError:
        return False
    return True


def pool_id(name: str) -> int | None:
    """The pool ID of ``name``; ``None`` for a name outside the pool (the noisy input)."""
    return pool.candidate(name).id if is_pool_name(name) else None


def id_list(names) -> str:
    """``"#20, #27"``: the pool IDs of ``names``, in their order."""
    return ", ".join(f"#{pool.candidate(n).id}" for n in names)


def finite_or_none(value) -> float | None:
    """``value`` as a float, or ``None`` when it is missing, not a number or not finite."""
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if np.isfinite(number) else None


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
    present = set(rows["entry"])
    if candidates is None:
        names = [c.name for c in pool.POOL if c.name in present]
    else:
        names = list(dict.fromkeys(candidates))
    if not names:
        raise BenchError(f"{source}: no candidate of the pool has a '{metric}' value")
    if noisy is not None:
        names.append(noisy)
    rows = rows[rows["entry"].isin(names)].copy()
    rows["scene"] = rows["scene"].astype(str)
    rows["spp"] = rows["spp"].astype(int)
    scenes = sorted(set(rows["scene"]))
    spps = sorted(set(rows["spp"]))
    check_complete(rows, entries=names, metric_names=[metric], cases=[(s, n) for s in scenes for n in spps],
                   source=source)
    index = pd.MultiIndex.from_product([scenes, spps, names], names=["scene", "spp", "entry"])
    values = rows.set_index(["scene", "spp", "entry"])["value"].astype(np.float64).reindex(index)
    scored = case_scores(rows, metric)
    scored["scene"] = scored["scene"].astype(str)
    scored["spp"] = scored["spp"].astype(int)
    scores = scored.set_index(["scene", "spp", "entry"])["score"].astype(np.float64).reindex(index)
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

