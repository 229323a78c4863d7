"""Hand-made metrics tables for the study's tests, whose scores are known exactly: the error of
each entry is its place in the case (1 = best), so the best of the 40 entries scores 40."""

from __future__ import annotations

import pandas as pd

from mcbench.analysis import pool
from mcbench.analysis.study.data import Resampling

ALL = [c.name for c in pool.POOL]
# Everything below the top lists: ensembles by descending ID, then the bases, then the noisy input.
REST = [n for n in reversed(ALL) if not pool.candidate(n).is_base] + [n for n in ALL if pool.candidate(n).is_base]
FAST = Resampling(n_resamples=400, seed=7)
FASTER = Resampling(n_resamples=300, seed=7)
SIZE2 = ["ens09", "ens10", "ens11", "ens12", "ens13", "ens14", "ens15", "ens16"]


def tidy(rows):
    return pd.DataFrame(rows, columns=["scene", "spp", "entry", "metric", "value"])


def from_orders(order, *, scenes, spps, metric="relmse", names=None):
    """A tidy table in which ``order(scene, spp)`` (best first) leads each case, then REST, then
    noisy; the error is the position (1 = best), so the scores are known exactly: best of 40 = 40."""
    names = ALL if names is None else names
    rows = []
    for scene in scenes:
        for spp in spps:
            top = order(scene, spp)
            ranked = top + [n for n in REST if n not in top and n in names] + ["noisy"]
            rows += [(scene, spp, name, metric, float(i + 1)) for i, name in enumerate(ranked)]
    return tidy(rows)


def from_fixed_order(order, *, scenes=("a", "b", "c"), spps=(4, 64, 512), metric="relmse"):
    """Error = place: ``order`` first, then REST (ensembles by descending ID, bases), then noisy."""
    rows = []
    for scene in scenes:
        for spp in spps:
            ranked = order + [n for n in REST if n not in order] + ["noisy"]
            rows += [(scene, spp, name, metric, float(i + 1)) for i, name in enumerate(ranked)]
    return tidy(rows)


def from_values(value, *, scenes=("a", "b", "c"), spps=(4, 64), metric="relmse"):
    """Every pool candidate and the noisy input with error ``value(name)`` in every case."""
    return tidy([(scene, spp, name, metric, float(value(name) if name != "noisy" else 100.0))
                 for scene in scenes for spp in spps for name in ALL + ["noisy"]])
