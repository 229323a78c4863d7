"""Figures of the report: error against spp per scene, and speed against error.

Both read the tidy tables the workflow writes: ``metrics`` with columns ``scene, spp,
entry, metric, value`` (``results/metrics.csv``; entry ``noisy`` is the noisy input)
and ``timings`` with ``scene, spp, method, seconds`` (``results/timings.csv``; compute time of
one method run in seconds, I/O excluded).

* :func:`error_curves` / :func:`error_curves_figure`: one log-log panel per scene of a metric's
  error against spp for every entry, the candidates and the noisy input (like Fig. 13 of Zheng et al. 2021),
  plus a first panel with the mean over scenes.
* :func:`speed_error_points` / :func:`speed_error_figure`: each method's mean compute time
  against its mean error over all test cases. A combiner's time includes the runs of the
  methods it combines (what a user pays for its output), so an ensemble sits to the right of
  its base denoisers.

The plotting functions draw with matplotlib's Agg backend and write PNGs atomically.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from mcbench.io.tables import write_atomically

MEAN_PANEL = "all scenes (mean)"


def error_curves(metrics: pd.DataFrame, *, metric: str) -> dict[str, pd.DataFrame]:
    """Error of every entry (the noisy input and the candidates) against spp, per scene, for one metric.

    Returns ``{panel: frame}`` with ``frame`` indexed by spp (ascending int) and one column per
    entry (in order of first appearance in ``metrics``). The first panel,
    :data:`MEAN_PANEL`, is the arithmetic mean over scenes of each (spp, entry), the
    per-case average the ranking tables also use; then one panel per scene in order of
    appearance. Raises ``ValueError`` naming the metric when ``metrics`` has no row of it.
    """
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        known = ", ".join(sorted(metrics["metric"].unique())) or "none"
        raise ValueError(f"no '{metric}' values in the metrics table (metrics present: {known})")
    entries = list(dict.fromkeys(rows["entry"]))
    table = rows.pivot_table(index=["scene", "spp"], columns="entry", values="value", aggfunc="mean")
    table = table[entries]
    panels = {MEAN_PANEL: table.groupby(level="spp").mean().sort_index()}
    for scene in dict.fromkeys(rows["scene"]):
        panels[scene] = table.xs(scene, level="scene").sort_index()
    for frame in panels.values():
        frame.index = frame.index.astype(int)
        frame.columns.name = None
    return panels


def input_closure(name: str, inputs: dict[str, list[str]]) -> list[str]:
    """``name`` and every method it takes, transitively, each once (depth-first order). A DC
    variant's closure holds its base; an ensemble's holds its members and theirs. Raises
    ``ValueError`` on a cycle."""
    seen: list[str] = []

    def visit(method: str, chain: tuple[str, ...]) -> None:
        if method in chain:
            raise ValueError(f"method '{method}' takes itself as an input ({' -> '.join(chain + (method,))})")
        if method in seen:
            return
        seen.append(method)
        for other in inputs.get(method, []):
            visit(other, chain + (method,))

    visit(name, ())
    return seen


def combined_seconds(own_seconds: dict[str, float], inputs: dict[str, list[str]]) -> dict[str, float]:
    """Compute time of each method including every method it combines, transitively.

    ``own_seconds[name]``: mean seconds of ``name``'s own runs; ``inputs[name]``: the methods a
    combiner takes (empty or absent for a base denoiser). A method's total is the sum of the own
    seconds over its :func:`input_closure`, each method counted once: a case runs every method
    once, so a base reached along two paths (KPCN in an ensemble of KPCN and KPCN-DC) costs once.
    Raises ``ValueError`` naming a method whose input has no timing, or a cycle.
    """
    totals: dict[str, float] = {}
    for name in own_seconds:
        closure = input_closure(name, inputs)
        missing = [m for m in closure if m not in own_seconds]
        if missing:
            raise ValueError(f"no timing for method '{missing[0]}' (an input of {name})")
        totals[name] = float(sum(own_seconds[m] for m in closure))
    return totals


def speed_error_points(metrics: pd.DataFrame, timings: pd.DataFrame, *, metric: str,
                       inputs: dict[str, list[str]] | None = None) -> pd.DataFrame:
    """Each method's mean compute time and mean error over all test cases.

    Returns a frame indexed by method name (order of first appearance in ``timings``) with
    columns ``seconds`` (mean seconds of its own runs), ``total_seconds`` (with the runs of the
    methods it combines, :func:`combined_seconds`; equal to ``seconds`` for a base denoiser),
    ``error`` (mean of ``metric`` over its (scene, spp) cases) and ``runs`` (number of timed runs).
    The noisy input has no compute time and is not a row. Raises ``ValueError`` naming a timed
    method without ``metric`` values.
    """
    rows = metrics[metrics["metric"] == metric]
    methods = list(dict.fromkeys(timings["method"]))
    mean_error = rows.groupby("entry")["value"].mean()
    missing = [name for name in methods if name not in mean_error.index]
    if missing:
        raise ValueError(f"no '{metric}' values for timed method(s) {', '.join(missing)} in the metrics table")
    grouped = timings.groupby("method")["seconds"]
    own = {name: float(grouped.mean()[name]) for name in methods}
    totals = combined_seconds(own, inputs or {})
    return pd.DataFrame({
        "seconds": [own[name] for name in methods],
        "total_seconds": [totals[name] for name in methods],
        "error": [float(mean_error[name]) for name in methods],
        "runs": [int(grouped.size()[name]) for name in methods],
    }, index=pd.Index(methods, name="method"))


def save_figure(figure, path: str | Path, *, dpi: int = 110) -> None:
    """Write a matplotlib figure as PNG to ``path`` atomically (a temporary file, then a rename)
    and close it."""
    import matplotlib.pyplot as plt

    try:
        write_atomically(path, lambda tmp: figure.savefig(tmp, dpi=dpi, format="png"), suffix=".tmp.png")
    finally:
        plt.close(figure)


def pyplot_agg():
    """matplotlib.pyplot with the non-interactive Agg backend (figures are only written to files)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _ordered(names, labels: dict[str, str]) -> list[str]:
    """``names`` in the order of ``labels`` (the config's order), unknown names after them."""
    names = list(dict.fromkeys(names))
    return [name for name in labels if name in names] + [name for name in names if name not in labels]


def entry_styles(entries: list[str], noisy: str) -> dict[str, dict]:
    """Line style per entry: the noisy input dashed grey, the others the colours of
    matplotlib's tab10/tab20 cycle in order (same order, same colours in every figure)."""
    plt = pyplot_agg()
    cmap = plt.get_cmap("tab10" if len(entries) <= 10 else "tab20")
    styles, index = {}, 0
    for name in entries:
        if name == noisy:
            styles[name] = {"color": "0.45", "linestyle": "--"}
        else:
            styles[name] = {"color": cmap(index % cmap.N), "linestyle": "-"}
            index += 1
    return styles


def error_curves_figure(panels: dict[str, pd.DataFrame], path: str | Path, *, metric: str,
                        labels: dict[str, str] | None = None, noisy: str = "noisy", columns: int = 6) -> None:
    """Log-log error-against-spp panels (from :func:`error_curves`) with one shared legend.

    Every entry keeps its colour in all panels; ``labels`` maps entry names to legend
    labels. Values that are not positive cannot be drawn on a log axis and are left out of
    the curve (a gap), never replaced.
    """
    plt = pyplot_agg()
    labels = labels or {}
    entries = _ordered((name for frame in panels.values() for name in frame.columns), labels)
    styles = entry_styles(entries, noisy)
    columns = max(1, min(columns, len(panels)))
    rows = math.ceil(len(panels) / columns)
    legend_rows = math.ceil(len(entries) / 6)
    legend_inches = 0.2 + 0.2 * legend_rows
    figure, axes = plt.subplots(rows, columns, figsize=(2.9 * columns, 2.5 * rows + legend_inches), squeeze=False)
    for axis in axes.ravel()[len(panels):]:
        axis.axis("off")
    for axis, (title, frame) in zip(axes.ravel(), panels.items()):
        for name in frame.columns:
            values = frame[name].to_numpy(np.float64)
            values = np.where(values > 0, values, np.nan)
            axis.plot(frame.index.to_numpy(), values, marker="o", markersize=3, linewidth=1.2, **styles[name])
        axis.set_xscale("log", base=2)
        axis.set_yscale("log")
        axis.set_xticks(frame.index.to_numpy(), [str(spp) for spp in frame.index])
        axis.minorticks_off()
        axis.set_title(title.replace("_", " "), fontsize=8, fontweight="bold" if title == MEAN_PANEL else None)
        axis.tick_params(labelsize=7)
        axis.grid(True, which="major", alpha=0.3)
        axis.set_xlabel("spp", fontsize=7)
        axis.set_ylabel(metric, fontsize=7)
    handles = [plt.Line2D([], [], marker="o", markersize=3, **styles[name]) for name in entries]
    figure.legend(handles, [labels.get(name, name) for name in entries], loc="lower center",
                  ncol=min(len(entries), 6), fontsize=7, frameon=False)
    figure.tight_layout(rect=(0, legend_inches / (2.5 * rows + legend_inches), 1, 1))
    save_figure(figure, path)


def speed_error_figure(points: pd.DataFrame, path: str | Path, *, metric: str,
                       labels: dict[str, str] | None = None, noisy: str = "noisy") -> None:
    """Scatter of each method's mean total compute time (log x, seconds) against its mean error
    (log y), from :func:`speed_error_points`, each point labelled. Lower left is better."""
    from matplotlib.ticker import FuncFormatter

    plt = pyplot_agg()
    labels = labels or {}
    # the colours of error_curves_figure (its first colour is the noisy input's grey, skipped)
    order = _ordered(points.index, labels)
    styles = entry_styles([noisy] + order, noisy)
    figure, axis = plt.subplots(figsize=(6.4, 4.6))
    by_time = sorted(order, key=lambda name: points.loc[name, "total_seconds"])
    for rank, name in enumerate(by_time):
        row = points.loc[name]
        axis.scatter([row["total_seconds"]], [row["error"]], s=28, color=styles[name]["color"], zorder=3)
        # labels of points close in time alternate above and below their point
        axis.annotate(labels.get(name, name), (row["total_seconds"], row["error"]), fontsize=7,
                      xytext=(4, 4 if rank % 2 == 0 else -10), textcoords="offset points")
    axis.set_xscale("log")
    axis.set_yscale("log")
    plain = FuncFormatter(lambda value, _: f"{value:g}")
    for scale in (axis.xaxis, axis.yaxis):
        scale.set_major_formatter(plain)
        scale.set_minor_formatter(plain)
    axis.set_xlabel("mean compute time per image, s (with the methods a combiner takes)", fontsize=8)
    axis.set_ylabel(f"mean {metric}", fontsize=8)
    axis.grid(True, which="both", alpha=0.3)
    axis.tick_params(which="both", labelsize=7)
    axis.margins(x=0.12, y=0.08)
    figure.tight_layout()
    save_figure(figure, path)
