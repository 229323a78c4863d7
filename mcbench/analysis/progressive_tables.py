"""Tables of progressive denoising (Firmino et al. 2022; ``methods/progressive.py``) over the
harness's test cases: its consistency against the noisy input, and per spp the errors and the
added time of each progressive entry beside its input (the rule ``progressive_tables``).

A *progressive entry* is a configured combiner of module ``progressive``; its *input* is the
one method it mixes with the noisy render (a base denoiser, or an ensemble: "stacked"). Inputs
in ``pairs`` map entry -> input, e.g. ``{"pd_oidn": "oidn", "pd_ens_all": "ens_all"}``.

**Consistency** (the property the paper's Sec. 3 proves for the mix z = x + α′(y − x) as spp
grows: the t-test shrinks α′ where y's error is significant, so z's error approaches the noisy
render's, never stays above it). Per entry and spp, over the scenes:

* ``worse``: the cases whose relMSE is above the noisy input's (the exceptions);
* ``ratio``: the geometric mean over scenes of relMSE(entry) / relMSE(noisy), 1 = no gain;
* ``gap``: the mean over scenes of |relMSE(entry) − relMSE(noisy)|, the distance to the noisy
  input's error, which must shrink as spp grows;
* the same ``worse`` and ``ratio`` of the entry's input, for contrast (a biased denoiser's ratio
  rises past 1 at high spp; its progressive version's must not).

Means are arithmetic over scenes (as the paper's tables), ratios geometric (scale-free across
scenes); every division is guarded (relMSE ≥ 0; a zero noisy error gives ratio 1 when the entry's
is also zero).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from mcbench import NOISY, BenchError

# the smallest denominator of a ratio (relMSE values of real cases are > 1e-8)
TINY = 1e-30
CONSISTENCY_COLUMNS = ["entry", "input", "spp", "cases", "noisy", "value", "input_value", "worse", "ratio",
                       "gap", "input_worse", "input_ratio"]


def _pivot(metrics: pd.DataFrame, metric: str) -> pd.DataFrame:
    """(scene, spp) x entry table of one metric (BenchError when it is missing)."""
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        raise BenchError(f"metrics table has no '{metric}' rows")
    return rows.pivot_table(index=["scene", "spp"], columns="entry", values="value", aggfunc="first")


def _need(table: pd.DataFrame, names, what: str) -> None:
    missing = [n for n in names if n not in table.columns]
    if missing:
        raise BenchError(f"metrics table lacks {what} {', '.join(missing)}: rerun gather_metrics")


def geometric_ratio(values: np.ndarray, reference: np.ndarray) -> float:
    """Geometric mean of ``values / reference`` (1-D, non-negative), guarded: pairs where both are
    0 count as 1, a zero reference is raised to :data:`TINY`."""
    values = np.maximum(np.asarray(values, np.float64), 0.0)
    reference = np.maximum(np.asarray(reference, np.float64), 0.0)
    both_zero = (values <= 0) & (reference <= 0)
    ratio = np.where(both_zero, 1.0, np.maximum(values, TINY) / np.maximum(reference, TINY))
    return float(np.exp(np.mean(np.log(ratio)))) if ratio.size else float("nan")


def consistency_table(metrics: pd.DataFrame, pairs: dict[str, str], *, metric: str = "relmse",
                      noisy: str = NOISY) -> pd.DataFrame:
    """One row per (progressive entry, spp) with the columns of :data:`CONSISTENCY_COLUMNS`
    (module docstring), from the long metrics table (scene, spp, entry, metric, value)."""
    table = _pivot(metrics, metric)
    _need(table, [noisy, *pairs, *pairs.values()], "entries")
    rows = []
    for entry, source in pairs.items():
        for spp, group in table.groupby(level="spp", sort=True):
            x, z, y = (group[c].to_numpy(np.float64) for c in (noisy, entry, source))
            rows.append({"entry": entry, "input": source, "spp": int(spp), "cases": len(group),
                         "noisy": float(np.mean(x)), "value": float(np.mean(z)), "input_value": float(np.mean(y)),
                         "worse": int(np.sum(z > x)), "ratio": geometric_ratio(z, x),
                         "gap": float(np.mean(np.abs(z - x))),
                         "input_worse": int(np.sum(y > x)), "input_ratio": geometric_ratio(y, x)})
    return pd.DataFrame(rows, columns=CONSISTENCY_COLUMNS)


def consistency_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per entry: exceptions (cases worse than noisy) out of all cases, the gap at the lowest and
    highest spp, whether the gap shrinks at every step (``gap_monotone``) and overall
    (``gap_shrinks``: highest-spp gap below the lowest's), and the input's exceptions."""
    rows = []
    for entry, group in table.groupby("entry", sort=False):
        group = group.sort_values("spp")
        gaps = group["gap"].to_numpy(np.float64)
        rows.append({"entry": entry, "input": group["input"].iloc[0], "worse": int(group["worse"].sum()),
                     "cases": int(group["cases"].sum()), "gap_first": float(gaps[0]), "gap_last": float(gaps[-1]),
                     "gap_shrinks": bool(gaps[-1] < gaps[0]),
                     "gap_monotone": bool(np.all(np.diff(gaps) <= 0)),
                     "ratio_first": float(group["ratio"].iloc[0]), "ratio_last": float(group["ratio"].iloc[-1]),
                     "input_worse": int(group["input_worse"].sum())})
    return pd.DataFrame(rows)


def per_spp_table(metrics: pd.DataFrame, entries: list[str], *, metric: str) -> pd.DataFrame:
    """Mean ``metric`` over scenes, one row per entry (``entries`` order), one column per spp
    and ``avg`` (the mean over spp of the per-spp means)."""
    table = _pivot(metrics, metric)
    _need(table, entries, "entries")
    means = table[entries].groupby(level="spp").mean().T
    means.columns = [str(int(c)) for c in means.columns]
    means["avg"] = means.mean(axis=1)
    means.index.name = "entry"
    return means


def added_seconds(timings: pd.DataFrame, entries: list[str]) -> pd.DataFrame:
    """Mean compute seconds per case of each entry (its own work only: a progressive entry's
    includes its divergence re-runs, not its input's), one row per entry, one column per spp and
    ``avg``; entries without a timing record (the noisy input) are left out."""
    rows = timings[timings["method"].isin(entries)]
    if rows.empty:
        return pd.DataFrame()
    means = rows.pivot_table(index="method", columns="spp", values="seconds", aggfunc="mean")
    means = means.reindex([e for e in entries if e in means.index])
    means.columns = [str(int(c)) for c in means.columns]
    means["avg"] = means.mean(axis=1)
    means.index.name = "entry"
    return means


def table_entries(pairs: dict[str, str], *, noisy: str = NOISY) -> list[str]:
    """The per-spp tables' rows: noisy, then each input followed by its progressive entries."""
    ordered = [noisy]
    for source in dict.fromkeys(pairs.values()):
        ordered.append(source)
        ordered.extend(e for e, s in pairs.items() if s == source)
    return list(dict.fromkeys(ordered))


def _label(name: str, labels: dict[str, str]) -> str:
    return labels.get(name, name)


def _markdown(frame: pd.DataFrame, labels: dict[str, str], digits: int) -> str:
    shown = frame.copy()
    shown.index = [_label(n, labels) for n in shown.index]
    return shown.to_markdown(floatfmt=f".{digits}g")


def consistency_markdown(table: pd.DataFrame, summary: pd.DataFrame, labels: dict[str, str], *,
                         metric: str) -> str:
    """The consistency table and its summary as Markdown."""
    lines = [f"# Consistency of progressive denoising ({metric})", "",
             "Per spp, over the test scenes: `worse` counts the cases whose error is above the noisy "
             "input's (exceptions), `ratio` is the geometric mean of error / noisy error (1: no gain), "
             "`gap` the mean |error - noisy error|; the `input_` columns are the same for the entry's "
             "input (mcbench.analysis.progressive_tables).", "", "## Summary", ""]
    shown = summary.copy()
    shown.insert(0, "label", [_label(n, labels) for n in shown["entry"]])
    lines += [shown.to_markdown(index=False, floatfmt=".4g"), "", "## Per spp", ""]
    for entry, group in table.groupby("entry", sort=False):
        lines += [f"### {_label(entry, labels)} (input: {_label(group['input'].iloc[0], labels)})", "",
                  group.drop(columns=["entry", "input"]).to_markdown(index=False, floatfmt=".4g"), ""]
    return "\n".join(lines) + "\n"


def per_spp_markdown(errors: dict[str, pd.DataFrame], seconds: pd.DataFrame, labels: dict[str, str]) -> str:
    """Mean errors per spp of every metric in ``errors`` and the added seconds, as Markdown."""
    lines = ["# Progressive denoising per spp", "",
             "Means over the test scenes; each input precedes its progressive versions. Seconds: each "
             "entry's own compute per case (a progressive entry's includes its divergence re-runs, not "
             "its input's).", ""]
    for metric, frame in errors.items():
        lines += [f"## {metric}", "", _markdown(frame, labels, 4), ""]
    if not seconds.empty:
        lines += ["## seconds per case (own compute)", "", _markdown(seconds, labels, 3), ""]
    return "\n".join(lines) + "\n"
