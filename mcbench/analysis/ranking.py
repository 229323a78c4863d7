"""Score-and-rank analysis of Zheng et al. 2021, Sec. 5.3.3.

For every test case (scene, spp) all candidates together with the noisy input are sorted by
error and given linearly spaced scores: the best of K entries gets K, the worst gets 1, and
ties share the mean of the scores they span (``scipy.stats.rankdata(..., method="average")``).
Scores are averaged across scenes per spp, then across spp for the overall column ``Avg.``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

import numpy as np
import pandas as pd
from scipy.stats import rankdata

from mcbench import METRICS_COLUMNS, BenchError

__all__ = ["IncompleteMetricsError", "check_complete", "case_scores", "score_table", "ranking_table", "extras_table",
           "format_markdown",
           "format_latex", "latex_escape"]

COLUMNS = list(METRICS_COLUMNS)


class IncompleteMetricsError(BenchError):
    """A metrics table that would rank cases over different sets of entries or with lost values."""


def check_complete(metrics: pd.DataFrame, *, entries: list[str], metric_names: list[str],
                   cases: list[tuple[str, int]] | None = None, source: str = "metrics") -> None:
    """Refuse a tidy metrics table unless every case holds every entry of ``entries`` and every
    metric exactly once, with a finite value (a truncated CSV, a dropped row or a missing entry
    would otherwise move scores silently: a case with fewer entries is scored on another scale).

    ``cases`` (scene, spp) pins the expected cases too. Errors name ``source`` and the case.
    """
    missing_columns = [c for c in COLUMNS if c not in metrics.columns]
    if missing_columns:
        raise IncompleteMetricsError(f"{source}: missing column(s) {missing_columns}")
    values = pd.to_numeric(metrics["value"], errors="coerce").to_numpy(dtype=np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        row = metrics[bad].iloc[0]
        raise IncompleteMetricsError(f"{source}: {int(bad.sum())} value(s) missing or not finite, first at "
                                     f"scene {row['scene']}, spp {row['spp']}, {row['entry']}, {row['metric']}")
    expected = {(e, m) for e in entries for m in metric_names}
    found_cases = set()
    for (scene, spp), case in metrics.groupby(["scene", "spp"], sort=True):
        found_cases.add((str(scene), int(spp)))
        pairs = list(zip(case["entry"], case["metric"]))
        duplicated = sorted({p for p in pairs if pairs.count(p) > 1})
        lacking = sorted(expected - set(pairs))
        unexpected = sorted(set(pairs) - expected)
        if duplicated or lacking or unexpected:
            parts = [f"missing {lacking[:6]}" if lacking else "", f"unexpected {unexpected[:6]}" if unexpected else "",
                     f"duplicated {duplicated[:6]}" if duplicated else ""]
            raise IncompleteMetricsError(f"{source}: case scene {scene}, spp {spp} is incomplete: "
                                         + "; ".join(p for p in parts if p))
    if cases is not None:
        lost = sorted({(str(s), int(n)) for s, n in cases} - found_cases)
        if lost:
            raise IncompleteMetricsError(f"{source}: no rows for case(s) {lost[:6]}")


def case_scores(metrics: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Per-case scores from a tidy table with columns scene, spp, entry, metric, value.

    Returns columns scene, spp, entry, score. Lower error => higher score. Every case must
    have the same entries (checked: a case scored over fewer entries would be on another scale).
    """
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        raise ValueError(f"no values for metric '{metric}'")
    check_complete(rows, entries=sorted(set(rows["entry"])), metric_names=[metric])
    out = []
    for (scene, spp), case in rows.groupby(["scene", "spp"], sort=True):
        scores = rankdata(-case["value"].to_numpy(dtype=np.float64), method="average")
        out.append(pd.DataFrame({"scene": scene, "spp": spp,
                                 "entry": case["entry"].to_numpy(), "score": scores}))
    return pd.concat(out, ignore_index=True)


def score_table(scores: pd.DataFrame) -> pd.DataFrame:
    """Per-case scores (:func:`case_scores`) reduced as Table 3: rows the entries scored (their
    header ``candidate``, as the paper's Table 3, the noisy input among them), columns spp (mean
    score over scenes, as strings) and ``Avg.`` (mean over spp), in the order the entries first
    appear."""
    per_spp = scores.groupby(["entry", "spp"], sort=False)["score"].mean().unstack("spp")
    per_spp = per_spp.reindex(columns=sorted(per_spp.columns))
    per_spp.columns = [str(c) for c in per_spp.columns]
    per_spp["Avg."] = per_spp.mean(axis=1)
    per_spp.index.name = "candidate"
    return per_spp


def ranking_table(metrics: pd.DataFrame, metric: str, *, order: list[str] | None = None) -> pd.DataFrame:
    """Table 3 of the paper: rows candidates, columns spp (mean score over scenes) and ``Avg.``
    (mean over spp); sorted by overall score, best first, or in ``order`` (every candidate of the
    table once, e.g. the pool's ID order)."""
    table = score_table(case_scores(metrics, metric))
    if order is None:
        return table.sort_values("Avg.", ascending=False, kind="stable")
    if sorted(order) != sorted(table.index):
        raise ValueError(f"order names {sorted(set(order) ^ set(table.index))[:6]} not (only) in the table")
    return table.loc[list(order)]


def extras_table(metrics: pd.DataFrame, metric: str, *, pool: list[str], extras: list[str]) -> pd.DataFrame:
    """Scores of methods outside the ranking pool, each scored in a pool that adds it alone.

    For every extra method e and case, the entries ``pool + [e]`` (K = len(pool) + 1) are scored as
    in :func:`case_scores` (K for the lowest error, 1 for the highest, ties averaged) and e's score is
    kept: e's row says where it would stand among the pool, and the pool's own table never depends
    on which extras a config runs. Returns rows ``extras`` (in that order), columns spp and ``Avg.``
    as :func:`ranking_table`. Every case must hold every pool member and extra (checked).
    """
    rows = metrics[metrics["metric"] == metric]
    check_complete(rows[rows["entry"].isin(pool + extras)], entries=list(pool) + list(extras),
                   metric_names=[metric])
    out = []
    for (scene, spp), case in rows.groupby(["scene", "spp"], sort=True):
        values = dict(zip(case["entry"], case["value"].to_numpy(dtype=np.float64)))
        pool_values = np.array([values[name] for name in pool], dtype=np.float64)
        for name in extras:
            scores = rankdata(-np.append(pool_values, values[name]), method="average")
            out.append({"scene": scene, "spp": spp, "entry": name, "score": float(scores[-1])})
    if not out:
        return pd.DataFrame(columns=["Avg."])
    return score_table(pd.DataFrame(out)).loc[list(extras)]


def _best_per_column(table: pd.DataFrame) -> pd.DataFrame:
    """Boolean frame: True where a score equals its column's maximum (``np.isclose``: ties all)."""
    values = table.to_numpy(dtype=np.float64)
    if not np.all(np.isfinite(values)):
        raise ValueError("ranking table holds NaN or Inf scores")
    return pd.DataFrame(np.isclose(values, values.max(axis=0, initial=-np.inf)),
                        index=table.index, columns=table.columns)


def _marked(column, marked) -> str:
    """A column's header, followed by `` ‡`` when its spp is in ``marked``."""
    return f"{column} ‡" if str(column).isdigit() and int(column) in marked else str(column)


def format_markdown(table: pd.DataFrame, labels: dict[str, str] | None = None, digits: int = 1, *,
                    marked: Iterable[int] = ()) -> str:
    """Markdown rendering of a ranking table; the best score of each column is bold; the spp
    columns in ``marked`` (those the references cannot rank,
    :func:`mcbench.analysis.scene_summary.unrankable_columns`) carry ``‡`` in their header."""
    labels = labels or {}
    marked = {int(m) for m in marked}
    shown = table.copy()
    best = _best_per_column(table)
    for column in table.columns:
        shown[column] = [f"**{v:.{digits}f}**" if is_best else f"{v:.{digits}f}"
                         for v, is_best in zip(table[column], best[column])]
    shown.columns = [_marked(c, marked) for c in table.columns]
    shown.index = [labels.get(c, c) for c in table.index]
    shown.index.name = "candidate"
    return shown.to_markdown()


# Characters with a meaning in LaTeX text mode, and the dagger of our stand-in labels.
_LATEX_ESCAPES = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
                  "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "†": r"\dag{}",
                  "‡": r"\ddag{}"}
_LATEX_LABEL = re.compile(r"[A-Za-z0-9:._-]+")


def latex_escape(text: str) -> str:
    """``text`` as LaTeX text-mode source: ``\\ & % $ # _ { } ~ ^`` escaped, ``†`` as ``\\dag{}``."""
    return "".join(_LATEX_ESCAPES.get(char, char) for char in str(text))


def format_latex(table: pd.DataFrame, labels: dict[str, str] | None = None, *, caption: str, label: str,
                 digits: int = 1, marked: Iterable[int] = ()) -> str:
    """A ranking table as a LaTeX ``table`` with booktabs rules (``\\usepackage{booktabs}``).

    One row per candidate (``labels`` maps names to shown labels, escaped with
    :func:`latex_escape`), one column per spp (header ``<N> spp``) and ``Avg.``; scores with
    ``digits`` decimals, the best of each column in ``\\textbf{}`` (ties all bold, as in
    :func:`format_markdown`); the spp columns in ``marked`` carry ``\\ddag{}`` in their header.
    ``caption`` is plain text (escaped); ``label`` is the ``\\label`` key (letters, digits, ``:._-``).
    """
    if not _LATEX_LABEL.fullmatch(label):
        raise ValueError(f"LaTeX label {label!r} may hold only letters, digits and ':._-'")
    labels = labels or {}
    best = _best_per_column(table)
    marked = {int(m) for m in marked}
    header = ["Candidate"] + [(f"{c} spp" + (" ‡" if int(c) in marked else "")) if str(c).isdigit() else str(c)
                              for c in table.columns]
    rows = []
    for candidate in table.index:
        cells = [latex_escape(labels.get(candidate, candidate))]
        for column in table.columns:
            number = f"{table.loc[candidate, column]:.{digits}f}"
            cells.append(rf"\textbf{{{number}}}" if best.loc[candidate, column] else number)
        rows.append("    " + " & ".join(cells) + r" \\")
    lines = [
        r"% Requires \usepackage{booktabs}. Written by mcbench (mcbench.analysis.ranking.format_latex).",
        r"\begin{table}",
        r"  \centering",
        rf"  \caption{{{latex_escape(caption)}}}",
        rf"  \label{{{label}}}",
        r"  \begin{tabular}{l" + "r" * len(table.columns) + "}",
        r"    \toprule",
        "    " + " & ".join(latex_escape(h) for h in header) + r" \\",
        r"    \midrule",
        *rows,
        r"    \bottomrule",
        r"  \end{tabular}",
        r"\end{table}",
    ]
    return "\n".join(lines) + "\n"
