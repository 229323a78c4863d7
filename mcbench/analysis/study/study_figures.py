"""Figures of the 39-candidate study (Zheng et al. 2021, Sec. 5.3), PNGs written with
matplotlib's Agg backend through :func:`mcbench.analysis.error_speed_figures.save_figure`; their data come
from :mod:`mcbench.analysis.study.scores_and_costs` and :mod:`mcbench.analysis.study.equal_time`.

Figures (:func:`write_study_figures`, files named by :func:`study_figure_paths`):

1. ``error_curves_<metric>.png``: error against spp per scene and the mean over scenes for the
   bases and the recommended ensembles (Fig. 13), drawn by :mod:`mcbench.analysis.error_speed_figures`;
2. ``score_curves_<metric>.png``: mean score over scenes against spp for those candidates, and
   every candidate's overall score ``Avg.`` (Fig. 14 c, d);
3. ``score_size_<metric>.png``: each candidate's ``Avg.`` against its ensemble size (bases at 1),
   with the mean per size and its spread;
4. ``speed_score_<metric>.png``: each candidate's total cost per case (its whole input closure,
   each method once) against its ``Avg.``, with the Pareto front (max score, min cost);
5. ``equal_time_<metric>.png``: each candidate's error divided by the error of a noisy render
   given the same total time (render + method), geometric mean over scenes against spp.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from mcbench import METRICS_COLUMNS
from mcbench.analysis.error_speed_figures import (entry_styles, error_curves, error_curves_figure, pyplot_agg,
                                                  save_figure)
from mcbench.analysis.study.equal_time import equal_time_curves, equal_time_table, read_render_seconds
from mcbench.analysis.study.scores_and_costs import (average_scores, score_curves, score_size_points,
                                                     score_size_summary, speed_score_points)

__all__ = ["STUDY_FIGURES", "study_figure_paths", "paper_recommended", "curve_candidates", "study_error_curves_figure",
           "score_curves_figure", "score_size_figure", "speed_score_figure", "equal_time_figure", "write_study_figures"]

# the fixed figure set, in order; file names: <key>_<metric>.png
STUDY_FIGURES: tuple[str, ...] = ("error_curves", "score_curves", "score_size", "speed_score", "equal_time")


def study_figure_paths(figures_dir: str | Path, metric: str) -> dict[str, str]:
    """The fixed output files of :func:`write_study_figures` for one metric:
    ``{key: <figures_dir>/<key>_<metric>.png}`` for every key of :data:`STUDY_FIGURES`
    (the workflow's ``figures_dir`` is ``results/figures/study``)."""
    return {key: str(Path(figures_dir) / f"{key}_{metric}.png") for key in STUDY_FIGURES}


def paper_recommended() -> list[str]:
    """Harness names of the paper's recommended ensembles (Sec. 5.3.5-5.3.6; #27, #20, #10,
    #18), a default for ``recommended`` until the study's own recommendations are computed."""
    from mcbench.analysis.pool import PAPER_RECOMMENDATIONS, candidate_name

    ids = [PAPER_RECOMMENDATIONS["overall"]["best"], PAPER_RECOMMENDATIONS["overall"]["second"],
           *PAPER_RECOMMENDATIONS["size"].values(), *PAPER_RECOMMENDATIONS["band"].values()]
    return [candidate_name(i) for i in dict.fromkeys(ids)]


def curve_candidates(recommended: list[str]) -> list[str]:
    """The candidates drawn as lines: the eight bases in the paper's order, then ``recommended``
    (in its order, bases and repeats left out)."""
    from mcbench.analysis.pool import BASES

    bases = list(BASES.values())
    return bases + [name for name in dict.fromkeys(recommended) if name not in bases]


# --------------------------------------------------------------------------- plots


def _label(name: str, labels: dict[str, str] | None) -> str:
    if labels and name in labels:
        return labels[name]
    from mcbench.analysis.pool import PoolError, candidate

    try:
        return candidate(name).label
    except PoolError:
        return name


def _spp_axis(axis, spps) -> None:
    axis.set_xscale("log", base=2)
    axis.set_xticks(list(spps), [str(s) for s in spps])
    axis.minorticks_off()
    axis.set_xlabel("spp", fontsize=8)
    axis.tick_params(labelsize=7)
    axis.grid(True, which="major", alpha=0.3)


def study_error_curves_figure(metrics: pd.DataFrame, path: str | Path, *, metric: str, candidates: list[str],
                              labels: dict[str, str] | None = None, noisy: str = "noisy") -> None:
    """Fig. 13: error against spp per scene and the mean over scenes for ``candidates`` (the
    bases and the recommended ensembles) and the noisy input, by
    :func:`mcbench.analysis.error_speed_figures.error_curves_figure`."""
    wanted = [noisy] + [c for c in candidates if c != noisy]
    rows = metrics[metrics["entry"].isin(wanted)]
    labels = {name: _label(name, labels) for name in wanted}
    error_curves_figure(error_curves(rows, metric=metric), path, metric=metric, labels=labels, noisy=noisy)


def score_curves_figure(curves: pd.DataFrame, averages: pd.Series, path: str | Path, *, metric: str,
                        labels: dict[str, str] | None = None, noisy: str = "noisy") -> None:
    """Fig. 14 c, d: left, the mean score over scenes against spp of the candidates in ``curves``
    (:func:`~mcbench.analysis.study.scores_and_costs.score_curves`), one line each; right, every candidate's
    ``Avg.`` (:func:`~mcbench.analysis.study.scores_and_costs.average_scores`) as horizontal bars, best on top,
    those of the left panel in their colours and the others grey."""
    plt = pyplot_agg()
    names = list(curves.columns)
    styles = entry_styles([noisy] + [n for n in names if n != noisy], noisy)
    height = max(4.2, 0.16 * len(averages) + 1.0)
    figure, (left, right) = plt.subplots(1, 2, figsize=(11.5, height), gridspec_kw={"width_ratios": [1.5, 1]})
    for name in names:
        left.plot(curves.index.to_numpy(), curves[name].to_numpy(np.float64), marker="o", markersize=3,
                  linewidth=1.3, label=_label(name, labels), **styles[name])
    _spp_axis(left, curves.index)
    left.set_ylabel(f"mean score over scenes ({metric}; higher is better)", fontsize=8)
    left.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=7, frameon=False)
    positions = np.arange(len(averages))[::-1]
    colours = [styles[name]["color"] if name in styles else "0.75" for name in averages.index]
    right.barh(positions, averages.to_numpy(np.float64), color=colours, height=0.75)
    right.set_yticks(positions, [_label(name, labels) for name in averages.index], fontsize=6)
    for position, value in zip(positions, averages.to_numpy(np.float64)):
        right.text(value, position, f" {value:.1f}", va="center", fontsize=5.5)
    right.set_xlabel("Avg. score (mean over spp)", fontsize=8)
    right.tick_params(axis="x", labelsize=7)
    right.set_xlim(0, float(averages.max()) * 1.12 if len(averages) else 1.0)
    right.set_ylim(-0.6, len(averages) - 0.4)
    figure.tight_layout()
    save_figure(figure, path)


def _jitter(points: pd.DataFrame, *, width: float = 0.5) -> np.ndarray:
    """Deterministic horizontal offsets: the candidates of one size spread evenly over ``width``
    in score order (no random jitter, so the figure is reproducible)."""
    offsets = np.zeros(len(points))
    for _, group in points.groupby("size"):
        positions = [points.index.get_loc(name) for name in group.sort_values("score").index]
        offsets[positions] = np.linspace(-width / 2, width / 2, len(group)) if len(group) > 1 else 0.0
    return offsets


def score_size_figure(points: pd.DataFrame, summary: pd.DataFrame, path: str | Path, *, metric: str,
                      labels: dict[str, str] | None = None, annotate: list[str] = (),
                      ci: pd.DataFrame | None = None) -> None:
    """Each candidate's ``Avg.`` score against its ensemble size
    (:func:`~mcbench.analysis.study.scores_and_costs.score_size_points`, spread sideways within a size), the
    mean per size with ±1 standard deviation over that size's candidates
    (:func:`~mcbench.analysis.study.scores_and_costs.score_size_summary`), the names of ``annotate`` written
    beside their points. ``ci``: optional per-candidate confidence intervals, a frame indexed by candidate with
    columns ``ci_low``, ``ci_high`` (scores), drawn as thin vertical bars."""
    plt = pyplot_agg()
    figure, axis = plt.subplots(figsize=(7.2, 4.8))
    x = points["size"].to_numpy(np.float64) + _jitter(points)
    y = points["score"].to_numpy(np.float64)
    if ci is not None:
        ci = ci.set_index("candidate") if "candidate" in ci.columns else ci
        shown = [name for name in points.index if name in ci.index]
        where = [points.index.get_loc(name) for name in shown]
        low = np.clip(y[where] - ci.loc[shown, "ci_low"].to_numpy(np.float64), 0, None)
        high = np.clip(ci.loc[shown, "ci_high"].to_numpy(np.float64) - y[where], 0, None)
        axis.errorbar(x[where], y[where], yerr=[low, high], fmt="none", ecolor="0.6", elinewidth=0.8, zorder=2)
    axis.scatter(x, y, s=18, color="tab:blue", alpha=0.75, zorder=3, label="candidate (Avg. score)")
    axis.errorbar(summary.index.to_numpy(np.float64), summary["mean"].to_numpy(np.float64),
                  yerr=summary["std"].to_numpy(np.float64), fmt="s-", color="black", markersize=5, capsize=4,
                  linewidth=1.2, zorder=4, label="mean per size ± 1 s.d.")
    for name in annotate:
        if name in points.index:
            where = points.index.get_loc(name)
            axis.annotate(_label(name, labels), (x[where], y[where]), fontsize=6.5, xytext=(5, 3),
                          textcoords="offset points", zorder=5)
            axis.scatter([x[where]], [y[where]], s=36, facecolors="none", edgecolors="tab:red", zorder=4)
    sizes = summary.index.to_numpy()
    axis.set_xticks(sizes, [f"{s}\n(n={n})" for s, n in zip(sizes, summary["n"])])
    axis.set_xlabel("ensemble size (bases at 1)", fontsize=8)
    axis.set_ylabel(f"Avg. score ({metric}; higher is better)", fontsize=8)
    axis.tick_params(labelsize=7)
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=7, loc="lower right")
    figure.tight_layout()
    save_figure(figure, path)


def _short(label: str) -> str:
    """A pool label's ID (``"#27"`` of ``"#27 KPCN+NFOR+OIDN+RDFC"``), other labels whole."""
    head = label.split(" ", 1)[0]
    return head if head.startswith("#") and head[1:].isdigit() else label


# label offsets (points) cycled over annotated points in cost order, so neighbours differ
_OFFSETS = ((5, 5), (5, -10), (-14, 8), (6, 14), (-16, -12))


def speed_score_figure(points: pd.DataFrame, path: str | Path, *, metric: str, labels: dict[str, str] | None = None,
                       annotate: list[str] = ()) -> None:
    """Every candidate's total cost per case (log x, seconds) against its ``Avg.`` score
    (:func:`~mcbench.analysis.study.scores_and_costs.speed_score_points`), coloured by ensemble size; the Pareto
    front (max score, min cost) as a step line through ringed points. Only the front and ``annotate`` are
    labelled, by their pool ID beside the point and in full in the legend, so 39 candidates stay legible. Upper
    left is better."""
    from matplotlib.ticker import FuncFormatter

    plt = pyplot_agg()
    figure, axis = plt.subplots(figsize=(9.6, 5.4))
    cmap = plt.get_cmap("tab10")
    sizes = sorted(set(int(s) for s in points["size"]))
    for index, size in enumerate(sizes):
        rows = points[points["size"] == size]
        axis.scatter(rows["total_seconds"], rows["score"], s=22, color=cmap(index % cmap.N), zorder=3,
                     label=f"size {size}" if size else "other")
    front = points[points["pareto"]].sort_values("total_seconds")
    if len(front):
        xs = np.append(front["total_seconds"].to_numpy(np.float64), float(points["total_seconds"].max()))
        ys = np.append(front["score"].to_numpy(np.float64), float(front["score"].iloc[-1]))
        axis.step(xs, ys, where="post", color="tab:red", linewidth=1.0, alpha=0.8, zorder=2, label="Pareto front")
        axis.scatter(front["total_seconds"], front["score"], s=60, facecolors="none", edgecolors="tab:red", zorder=4)
    shown = sorted(dict.fromkeys(list(front.index) + [n for n in annotate if n in points.index]),
                   key=lambda n: points.loc[n, "total_seconds"])
    for rank, name in enumerate(shown):
        axis.annotate(_short(_label(name, labels)), (points.loc[name, "total_seconds"], points.loc[name, "score"]),
                      fontsize=7, xytext=_OFFSETS[rank % len(_OFFSETS)], textcoords="offset points", zorder=5,
                      color="tab:red" if points.loc[name, "pareto"] else "black")
    handles, texts = axis.get_legend_handles_labels()
    for name in shown:
        full = _label(name, labels)
        mark = "front" if points.loc[name, "pareto"] else "named"
        handles.append(plt.Line2D([], [], linestyle="none"))
        texts.append(f"{full} ({mark}; {points.loc[name, 'total_seconds']:.3g} s, {points.loc[name, 'score']:.1f})")
    axis.set_xscale("log")
    plain = FuncFormatter(lambda value, _: f"{value:g}")
    axis.xaxis.set_major_formatter(plain)
    axis.set_xlabel("total compute seconds per case (the candidate and all it takes, each once)", fontsize=8)
    axis.set_ylabel(f"Avg. score ({metric}; higher is better)", fontsize=8)
    axis.tick_params(which="both", labelsize=7)
    axis.grid(True, which="both", alpha=0.3)
    axis.margins(x=0.15, y=0.08)
    axis.legend(handles, texts, fontsize=6.5, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False,
                handlelength=1.2)
    figure.tight_layout()
    save_figure(figure, path)


def equal_time_figure(ratios: pd.DataFrame, path: str | Path, *, metric: str, labels: dict[str, str] | None = None,
                      extrapolated: pd.DataFrame | None = None, noisy: str = "noisy") -> None:
    """Each candidate's error over the equal-time noisy render's error (geometric mean over scenes,
    :func:`~mcbench.analysis.study.equal_time.equal_time_curves`) against spp, log-y with a line at 1 (below:
    the candidate beats spending its time on more samples). Points relying on extrapolation beyond the largest
    measured spp (``extrapolated``) are hollow and footnoted."""
    plt = pyplot_agg()
    names = list(ratios.columns)
    styles = entry_styles([noisy] + [n for n in names if n != noisy], noisy)
    figure, axis = plt.subplots(figsize=(8.6, 4.8))
    spps = ratios.index.to_numpy()
    any_beyond = False
    for name in names:
        values = ratios[name].to_numpy(np.float64)
        axis.plot(spps, values, linewidth=1.3, label=_label(name, labels), **styles[name])
        beyond = extrapolated[name].to_numpy(bool) if extrapolated is not None and name in extrapolated else \
            np.zeros(len(spps), dtype=bool)
        any_beyond |= bool(beyond.any())
        axis.scatter(spps[~beyond], values[~beyond], s=14, color=styles[name]["color"], zorder=3)
        axis.scatter(spps[beyond], values[beyond], s=18, facecolors="white", edgecolors=styles[name]["color"],
                     zorder=3)
    axis.axhline(1.0, color="0.3", linewidth=1.0, linestyle="--")
    _spp_axis(axis, spps)
    axis.set_yscale("log")
    axis.set_ylabel(f"{metric} / noisy {metric} at equal time (geo. mean)", fontsize=8)
    axis.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    if any_beyond:
        figure.text(0.01, 0.01, "hollow: the equal-time noisy render lies beyond the largest rendered spp "
                                "(render time and noisy error extrapolated log-log)", fontsize=6.5)
    figure.tight_layout(rect=(0, 0.03 if any_beyond else 0, 1, 1))
    save_figure(figure, path)


# --------------------------------------------------------------------------- writer


def _pool_inputs() -> dict[str, list[str]]:
    from mcbench.analysis.pool import pool_methods

    _, combiners = pool_methods()
    return {entry["name"]: list(entry["inputs"]) for entry in combiners}


def write_study_figures(metrics_csv: str, timings_csv: str, render_records: list[str], paths: dict[str, str], *,
                        metric: str, candidates: list[str], curves: list[str], recommended: list[str] = (),
                        labels: dict[str, str] | None = None, inputs: dict[str, list[str]] | None = None,
                        noisy: str = "noisy", ci: pd.DataFrame | None = None) -> pd.DataFrame:
    """Write the study's figures for one ``metric`` (keys of ``paths``: :data:`STUDY_FIGURES`,
    e.g. from :func:`study_figure_paths`; a key left out is not drawn).

    ``candidates``: the ranking pool (the 39 candidates; ``noisy`` is added), scored per case by
    :func:`mcbench.analysis.ranking.case_scores`; ``curves``: the candidates drawn as lines (the bases and the
    recommended ensembles); ``recommended``: names written beside their points in the size and speed figures;
    ``render_records``: the noisy renders' EXRs or benchmark TSVs
    (:func:`~mcbench.analysis.study.equal_time.read_render_seconds`; only read for ``equal_time``); ``inputs``:
    method -> the methods it takes (default: the pool's). Returns the equal-time table (empty when not drawn).
    """
    from mcbench.io.tables import read_table
    from mcbench.analysis.ranking import case_scores

    unknown = sorted(set(paths) - set(STUDY_FIGURES))
    if unknown:
        raise ValueError(f"unknown study figure(s) {unknown}; known: {', '.join(STUDY_FIGURES)}")
    inputs = _pool_inputs() if inputs is None else inputs
    pool = [noisy] + [c for c in candidates if c != noisy]
    metrics = read_table(metrics_csv, columns=METRICS_COLUMNS)
    metrics = metrics[metrics["entry"].isin(pool) & (metrics["metric"] == metric)]
    timings = read_table(timings_csv, columns=["scene", "spp", "method", "seconds"])
    scores = case_scores(metrics, metric)
    lines = [c for c in curves if c != noisy]
    if "error_curves" in paths:
        study_error_curves_figure(metrics, paths["error_curves"], metric=metric, candidates=lines, labels=labels,
                                  noisy=noisy)
    if "score_curves" in paths:
        score_curves_figure(score_curves(scores, candidates=lines), average_scores(scores), paths["score_curves"],
                            metric=metric, labels=labels, noisy=noisy)
    if "score_size" in paths:
        points = score_size_points(scores)
        score_size_figure(points, score_size_summary(points), paths["score_size"], metric=metric, labels=labels,
                          annotate=list(recommended), ci=ci)
    if "speed_score" in paths:
        speed_score_figure(speed_score_points(scores, timings, inputs=inputs, noisy=noisy), paths["speed_score"],
                           metric=metric, labels=labels, annotate=list(recommended))
    table = pd.DataFrame()
    if "equal_time" in paths:
        table = equal_time_table(metrics, timings, read_render_seconds(render_records), metric=metric,
                                 inputs=inputs, candidates=[c for c in pool if c != noisy], noisy=noisy)
        ratios, beyond = equal_time_curves(table, candidates=lines)
        equal_time_figure(ratios, paths["equal_time"], metric=metric, labels=labels, extrapolated=beyond,
                          noisy=noisy)
    return table

