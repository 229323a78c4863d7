"""Figures of the 39-candidate study (Zheng et al. 2021, Sec. 5.3).

Inputs are the workflow's tidy tables:

* ``metrics``: columns ``scene, spp, candidate, metric, value`` (``results/metrics.csv``;
  candidate ``noisy`` is the noisy render);
* ``scores``: :func:`mcbench.analysis.ranking.case_scores` output, columns ``scene, spp, candidate,
  score`` (score K for the best of K entries of a case, 1 for the worst; higher is better);
* ``timings``: columns ``scene, spp, method, seconds`` (``results/timings.csv``; compute seconds
  of one method run, I/O excluded);
* render times: columns ``scene, spp, seconds`` (:func:`read_render_seconds`).

Data functions return DataFrames without NaN or Inf; plotting functions write PNGs with
matplotlib's Agg backend through :func:`mcbench.analysis.figures.save_figure`.

Figures (:func:`write_study_figures`, files named by :func:`study_figure_paths`):

1. ``error_curves_<metric>.png``: error against spp per scene and the mean over scenes for the
   bases and the recommended ensembles (Fig. 13), drawn by :mod:`mcbench.analysis.figures`;
2. ``score_curves_<metric>.png``: mean score over scenes against spp for those candidates, and
   every candidate's overall score ``Avg.`` (Fig. 14 c, d);
3. ``score_size_<metric>.png``: each candidate's ``Avg.`` against its ensemble size (bases at 1),
   with the mean per size and its spread;
4. ``speed_score_<metric>.png``: each candidate's total cost per case (its whole input closure,
   each method once) against its ``Avg.``, with the Pareto front (max score, min cost);
5. ``equal_time_<metric>.png``: each candidate's error divided by the error of a noisy render
   given the same total time (render + method), geometric mean over scenes against spp.

Render times
------------
The noisy render of ``(scene, spp)`` records its time twice: the EXR header attribute
``mcbench.seconds`` (``results/renders/{scene}/spp{N}.exr``; scene loading and rendering, no
EXR writing, :func:`mcbench.render.renderer.render_buffers`) and the Snakemake benchmark record
``results/benchmarks/render_noisy/{scene}_spp{N}.tsv`` (column ``s``: wall seconds of the whole
job, with Python start-up, imports and the EXR write). :func:`read_render_seconds` reads either;
the EXR's is the closer match to the methods' compute-only seconds and is preferred, the TSV
overstates the render by the job's fixed overhead (most at low spp). Both are per (scene, spp),
so no approximation across spp is needed at measured points. Renders run with the config's
``render_threads`` and methods with their own thread counts; the equal-time view compares the
seconds as measured (wall time), not CPU-seconds.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from mcbench.analysis.figures import (candidate_styles, combined_seconds, error_curves, error_curves_figure, input_closure,
                             pyplot_agg, save_figure)

__all__ = ["STUDY_FIGURES", "study_figure_paths", "paper_recommended", "curve_candidates", "score_curves",
           "average_scores", "candidate_sizes", "score_size_points", "score_size_summary", "input_closure", "closure_seconds", "own_seconds",
           "pareto_front", "speed_score_points", "read_render_seconds", "loglog_interp", "equal_time_table",
           "equal_time_curves", "study_error_curves_figure", "score_curves_figure", "score_size_figure",
           "speed_score_figure", "equal_time_figure", "write_study_figures"]

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


# --------------------------------------------------------------------------- scores


def _select(frame: pd.DataFrame, column: str, names) -> pd.DataFrame:
    if names is None:
        return frame
    missing = [name for name in names if name not in set(frame[column])]
    if missing:
        raise ValueError(f"no rows for {', '.join(map(str, missing))} (column '{column}')")
    return frame[frame[column].isin(list(names))]


def score_curves(scores: pd.DataFrame, *, candidates: list[str] | None = None) -> pd.DataFrame:
    """Mean score over scenes per spp (Fig. 14 c): index spp (ascending int), one column per
    candidate (``candidates`` in their order, or all in order of first appearance). Scores are
    unitless (K for the best of K entries of a case)."""
    rows = _select(scores, "candidate", candidates)
    if rows.empty:
        raise ValueError("no scores to average")
    order = list(candidates) if candidates is not None else list(dict.fromkeys(rows["candidate"]))
    table = rows.groupby(["spp", "candidate"])["score"].mean().unstack("candidate")
    if table.isna().to_numpy().any():
        lacking = table.columns[table.isna().any()].tolist()
        raise ValueError(f"candidate(s) {lacking} lack scores at some spp")
    table = table[order].sort_index()
    table.index = table.index.astype(int)
    table.columns.name = None
    return table


def average_scores(scores: pd.DataFrame) -> pd.Series:
    """Overall score ``Avg.`` of every candidate (Fig. 14 d, Table 3's last column): the mean
    over spp of the mean over scenes, as :func:`mcbench.analysis.ranking.ranking_table`. A Series named
    ``score`` indexed by candidate, best first (stable on ties)."""
    averages = score_curves(scores).mean(axis=0)
    averages = averages.sort_values(ascending=False, kind="stable")
    averages.index.name = "candidate"
    return averages.rename("score")


def candidate_sizes(names, *, sizes: dict[str, int] | None = None) -> dict[str, int]:
    """Ensemble size (number of base denoisers) of each name: from ``sizes`` when given there,
    else from the candidate pool (:mod:`mcbench.analysis.pool`; 1 for a base, DC variants included).
    Names in neither (the noisy input, comparison methods) are left out."""
    from mcbench.analysis.pool import PoolError, candidate

    found = {}
    for name in names:
        if sizes and name in sizes:
            found[name] = int(sizes[name])
            continue
        try:
            found[name] = candidate(name).size
        except PoolError:
            continue
    return found


def score_size_points(scores: pd.DataFrame, *, sizes: dict[str, int] | None = None) -> pd.DataFrame:
    """Each sized candidate's ``Avg.`` score against its ensemble size: index candidate (best
    first), columns ``size`` (int) and ``score``. Candidates without a size
    (:func:`candidate_sizes`: the noisy input) are left out."""
    averages = average_scores(scores)
    known = candidate_sizes(averages.index, sizes=sizes)
    if not known:
        raise ValueError("no candidate with a known ensemble size among the scores")
    names = [name for name in averages.index if name in known]
    frame = pd.DataFrame({"size": [known[n] for n in names], "score": averages[names].to_numpy(np.float64)},
                         index=pd.Index(names, name="candidate"))
    return frame


def score_size_summary(points: pd.DataFrame) -> pd.DataFrame:
    """Per ensemble size: ``n`` candidates, ``mean``, ``std`` (sample standard deviation over the
    candidates of that size, 0 for a single one), ``min``, ``max`` of their ``Avg.`` scores.
    Index ``size`` ascending."""
    grouped = points.groupby("size")["score"]
    summary = pd.DataFrame({"n": grouped.size(), "mean": grouped.mean(), "std": grouped.std(ddof=1).fillna(0.0),
                            "min": grouped.min(), "max": grouped.max()}).sort_index()
    summary.index = summary.index.astype(int)
    return summary


# --------------------------------------------------------------------------- costs


def closure_seconds(own: dict[str, float], inputs: dict[str, list[str]], *,
                    names: list[str] | None = None) -> dict[str, float]:
    """Total cost of each method (seconds per case) of ``names`` (default: all of ``own``):
    :func:`mcbench.analysis.figures.combined_seconds`, the sum of ``own`` seconds over its input closure,
    each method counted once. Raises ``ValueError`` naming a method without a timing."""
    chosen = names if names is not None else list(own)
    needed = {m for name in chosen for m in input_closure(name, inputs)}
    missing = sorted(needed - set(own))
    if missing:
        raise ValueError(f"no timing for method(s) {', '.join(missing)}")
    totals = combined_seconds({m: own[m] for m in needed}, inputs)
    return {name: totals[name] for name in chosen}


def own_seconds(timings: pd.DataFrame) -> dict[str, float]:
    """Each method's own mean compute seconds per case: the mean over its (scene, spp) cases of
    the mean over repeated runs of a case (so a case timed twice weighs as one)."""
    per_case = timings.groupby(["method", "scene", "spp"])["seconds"].mean()
    return {str(k): float(v) for k, v in per_case.groupby(level="method").mean().items()}


def pareto_front(cost, score) -> np.ndarray:
    """Boolean mask of the points not dominated for (min ``cost``, max ``score``): a point is
    dominated when another has cost <= and score >= with one of them strict. Identical points
    are both on the front."""
    cost = np.asarray(cost, dtype=np.float64)
    score = np.asarray(score, dtype=np.float64)
    order = np.lexsort((-score, cost))  # by cost ascending, then score descending
    front = np.zeros(cost.shape, dtype=bool)
    best_score, best_cost = -np.inf, np.nan
    for index in order:
        if score[index] > best_score:
            front[index] = True
            best_score, best_cost = score[index], cost[index]
        elif score[index] == best_score and cost[index] == best_cost:
            front[index] = True
    return front


def speed_score_points(scores: pd.DataFrame, timings: pd.DataFrame, *, inputs: dict[str, list[str]],
                       noisy: str = "noisy", sizes: dict[str, int] | None = None) -> pd.DataFrame:
    """Each candidate's total cost against its ``Avg.`` score.

    Index candidate (every scored candidate but ``noisy``, best first); columns ``seconds`` (own
    mean compute seconds per case, :func:`own_seconds`), ``total_seconds`` (its whole input
    closure, :func:`closure_seconds`), ``score`` (``Avg.``), ``size`` (0 when unknown) and
    ``pareto`` (on the front of min total seconds, max score). Raises ``ValueError`` naming a
    candidate or input without timings."""
    averages = average_scores(scores).drop(noisy, errors="ignore")
    own = own_seconds(timings)
    names = list(averages.index)
    totals = closure_seconds(own, inputs, names=names)
    known = candidate_sizes(names, sizes=sizes)
    frame = pd.DataFrame({
        "seconds": [own[n] for n in names],
        "total_seconds": [totals[n] for n in names],
        "score": averages.to_numpy(np.float64),
        "size": [known.get(n, 0) for n in names],
    }, index=pd.Index(names, name="candidate"))
    frame["pareto"] = pareto_front(frame["total_seconds"], frame["score"])
    return frame


# --------------------------------------------------------------------------- equal time

_TSV_NAME = re.compile(r"(?P<scene>.+)_spp(?P<spp>\d+)\.tsv")
_EXR_NAME = re.compile(r"spp(?P<spp>\d+)\.exr")


def read_render_seconds(paths) -> pd.DataFrame:
    """Render seconds of the noisy renders, one row per (scene, spp): columns ``scene``, ``spp``
    (int), ``seconds`` (float) and ``source`` (``exr`` or ``benchmark``).

    ``paths``: noisy renders ``.../{scene}/spp{N}.exr`` (header ``mcbench.seconds``, scene and spp
    from the header) or Snakemake benchmark records ``.../{scene}_spp{N}.tsv`` (column ``s`` of
    the last repeat, scene and spp from the file name). When both kinds give a case, the EXR's
    is kept (compute only, as the methods' timings). Raises ``ValueError`` naming a file it
    cannot read."""
    rows = []
    for path in map(str, paths):
        name = Path(path).name
        if name.endswith(".exr"):
            from mcbench.io.exr import read_metadata

            meta = read_metadata(path)
            match = _EXR_NAME.fullmatch(name)
            scene = meta.get("scene") or Path(path).parent.name
            spp = meta.get("spp") or (match.group("spp") if match else None)
            if "seconds" not in meta or spp is None:
                raise ValueError(f"{path}: render without 'seconds' or 'spp' in its header")
            rows.append({"scene": scene, "spp": int(spp), "seconds": float(meta["seconds"]), "source": "exr"})
        elif name.endswith(".tsv"):
            match = _TSV_NAME.fullmatch(name)
            if match is None:
                raise ValueError(f"{path}: benchmark record not named <scene>_spp<N>.tsv")
            frame = pd.read_csv(path, sep="\t")
            if "s" not in frame.columns or not len(frame):
                raise ValueError(f"{path}: benchmark record without an 's' row")
            rows.append({"scene": match.group("scene"), "spp": int(match.group("spp")),
                         "seconds": float(frame["s"].iloc[-1]), "source": "benchmark"})
        else:
            raise ValueError(f"{path}: neither a render (.exr) nor a benchmark record (.tsv)")
    if not rows:
        raise ValueError("no render records")
    frame = pd.DataFrame(rows)
    if not np.all(np.isfinite(frame["seconds"])) or (frame["seconds"] <= 0).any():
        bad = frame[~(frame["seconds"] > 0) | ~np.isfinite(frame["seconds"])].iloc[0]
        raise ValueError(f"render time of scene {bad['scene']}, spp {bad['spp']} is not a positive number")
    frame["rank"] = (frame["source"] != "exr").astype(int)
    frame = frame.sort_values(["scene", "spp", "rank"]).drop_duplicates(["scene", "spp"]).drop(columns="rank")
    return frame.reset_index(drop=True)


def loglog_interp(x, xp, fp, *, slope: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Piecewise-linear interpolation of ``fp`` against ``xp`` in log-log (all positive; ``xp``
    strictly increasing). Beyond the range it continues the first or last segment's log-log
    line (or a line of log-log ``slope`` when given; with a single point, ``slope`` or 1).
    Returns ``(values, extrapolated)`` with ``extrapolated`` True where ``x`` is out of range."""
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    lx, lxp, lfp = np.log(x), np.log(np.asarray(xp, dtype=np.float64)), np.log(np.asarray(fp, dtype=np.float64))
    if lxp.size == 0:
        raise ValueError("no points to interpolate")
    if np.any(np.diff(lxp) <= 0):
        raise ValueError("interpolation abscissae must be strictly increasing")
    values = np.interp(lx, lxp, lfp)
    if lxp.size == 1:
        low = high = 1.0 if slope is None else slope
    else:
        low = (lfp[1] - lfp[0]) / (lxp[1] - lxp[0]) if slope is None else slope
        high = (lfp[-1] - lfp[-2]) / (lxp[-1] - lxp[-2]) if slope is None else slope
    below, above = lx < lxp[0], lx > lxp[-1]
    values = np.where(below, lfp[0] + low * (lx - lxp[0]), values)
    values = np.where(above, lfp[-1] + high * (lx - lxp[-1]), values)
    return np.exp(values), below | above


def _monotone_times(spp: np.ndarray, seconds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Render time against spp (sorted by spp) made non-decreasing: a larger spp measured faster
    than a smaller one is timing noise, raised to the running maximum."""
    order = np.argsort(spp)
    return spp[order], np.maximum.accumulate(seconds[order])


def _invertible(spp: np.ndarray, seconds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-decreasing times reduced to strictly increasing ones for the inverse (spp of a time):
    of equal times the largest spp is kept (that time buys that many samples)."""
    keep = np.append(np.diff(seconds) > 0, True)
    return spp[keep], seconds[keep]


def equal_time_table(metrics: pd.DataFrame, timings: pd.DataFrame, render_seconds: pd.DataFrame, *,
                     metric: str, inputs: dict[str, list[str]], candidates: list[str] | None = None,
                     noisy: str = "noisy", tiny: float = 1e-12) -> pd.DataFrame:
    """The noisy render's error at the same total time as each candidate, per test case.

    For a candidate at (scene, spp): ``method_seconds`` is its input closure's cost in that case
    (each method's own seconds of that case, mean over repeated runs, each method once);
    ``render_seconds`` the noisy render's time at spp (made non-decreasing in spp, see below);
    ``total_seconds`` their sum. ``equal_spp`` is the spp whose render takes ``total_seconds``:
    the render time interpolated against spp in log-log over the scene's measured spp, and
    beyond the largest spp the last segment's log-log line continued (``extrapolated`` True;
    with one measured spp, time proportional to spp). ``noisy_error`` is the noisy render's
    ``metric`` at ``equal_spp``, interpolated in log-log against spp likewise (extrapolated by
    the last segment beyond the largest spp). ``ratio`` = ``error`` / ``noisy_error``: below 1
    the candidate beats spending its time on more samples. Errors are floored at ``tiny`` for
    the logarithms (the interpolated noisy error too). Render times that fall as spp grows are timing noise, raised to the running
    maximum; of equal render times the inverse takes the largest spp.

    Returns columns scene, spp, candidate, error, method_seconds, render_seconds,
    total_seconds, equal_spp, noisy_error, ratio, extrapolated (bool); rows in scene, spp,
    candidate order. Raises ``ValueError`` naming a case without a render time, a noisy error
    or a timing."""
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        raise ValueError(f"no '{metric}' values in the metrics table")
    names = [c for c in dict.fromkeys(rows["candidate"]) if c != noisy] if candidates is None else \
        [c for c in candidates if c != noisy]
    per_case = timings.groupby(["scene", "spp", "method"])["seconds"].mean()
    out = []
    for scene, scene_rows in rows.groupby("scene", sort=True):
        renders = render_seconds[render_seconds["scene"] == scene]
        if renders.empty:
            raise ValueError(f"no render time for scene '{scene}'")
        if not (np.isfinite(renders["seconds"].to_numpy(np.float64)).all() and (renders["seconds"] > 0).all()):
            raise ValueError(f"render times of scene '{scene}' must be positive numbers")
        m_spp, m_sec = _monotone_times(renders["spp"].to_numpy(np.float64), renders["seconds"].to_numpy(np.float64))
        r_spp, r_sec = _invertible(m_spp, m_sec)
        noisy_rows = scene_rows[scene_rows["candidate"] == noisy].groupby("spp")["value"].mean().sort_index()
        if noisy_rows.empty:
            raise ValueError(f"no '{metric}' of the noisy input '{noisy}' in scene '{scene}'")
        n_spp = noisy_rows.index.to_numpy(np.float64)
        n_err = np.maximum(noisy_rows.to_numpy(np.float64), tiny)
        values = scene_rows.groupby(["spp", "candidate"])["value"].mean()
        for spp in sorted(set(int(s) for s in scene_rows["spp"])):
            if not np.any(m_spp == spp):
                raise ValueError(f"no render time for scene '{scene}' at {spp} spp")
            render_time = float(m_sec[m_spp == spp][0])  # the measured time, made monotone
            for name in names:
                if (spp, name) not in values.index:
                    raise ValueError(f"no '{metric}' of '{name}' in scene '{scene}' at {spp} spp")
                cost = 0.0
                for method in input_closure(name, inputs):
                    if (scene, spp, method) not in per_case.index:
                        raise ValueError(f"no timing of '{method}' (needed by '{name}') in scene '{scene}' "
                                         f"at {spp} spp")
                    cost += float(per_case[(scene, spp, method)])
                total = render_time + cost
                equal_spp, beyond = loglog_interp(total, r_sec, r_spp,
                                                  slope=None if len(r_spp) > 1 else 1.0)
                noisy_error, beyond_error = loglog_interp(equal_spp, n_spp, n_err)
                noisy_error = np.maximum(noisy_error, tiny)
                error = max(float(values[(spp, name)]), tiny)
                out.append({"scene": scene, "spp": spp, "candidate": name, "error": error,
                            "method_seconds": cost, "render_seconds": render_time, "total_seconds": total,
                            "equal_spp": float(equal_spp[0]), "noisy_error": float(noisy_error[0]),
                            "ratio": error / float(noisy_error[0]),
                            "extrapolated": bool(beyond[0] or beyond_error[0])})
    table = pd.DataFrame(out)
    numeric = table.drop(columns=["scene", "candidate", "extrapolated"]).to_numpy(np.float64)
    if not np.all(np.isfinite(numeric)):
        raise ValueError("equal-time table holds NaN or Inf (a non-positive time or error?)")
    return table


def equal_time_curves(table: pd.DataFrame, *, candidates: list[str] | None = None) -> tuple[pd.DataFrame,
                                                                                           pd.DataFrame]:
    """Geometric mean over scenes of :func:`equal_time_table`'s ``ratio`` per spp and candidate.

    Returns ``(ratios, extrapolated)``: both indexed by spp (ascending int) with one column per
    candidate (``candidates`` in order, or all in order of appearance); ``ratios`` float,
    ``extrapolated`` bool (True when any scene's value was extrapolated)."""
    rows = _select(table, "candidate", candidates)
    order = list(candidates) if candidates is not None else list(dict.fromkeys(rows["candidate"]))
    rows = rows.assign(log_ratio=np.log(rows["ratio"].to_numpy(np.float64)))
    ratios = np.exp(rows.groupby(["spp", "candidate"])["log_ratio"].mean().unstack("candidate"))[order].sort_index()
    beyond = rows.groupby(["spp", "candidate"])["extrapolated"].any().unstack("candidate")[order].sort_index()
    for frame in (ratios, beyond):
        frame.index = frame.index.astype(int)
        frame.columns.name = None
    if ratios.isna().to_numpy().any():
        raise ValueError("some candidate lacks an equal-time ratio at some spp")
    return ratios, beyond.astype(bool)


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
    :func:`mcbench.analysis.figures.error_curves_figure`."""
    wanted = [noisy] + [c for c in candidates if c != noisy]
    rows = metrics[metrics["candidate"].isin(wanted)]
    labels = {name: _label(name, labels) for name in wanted}
    error_curves_figure(error_curves(rows, metric=metric), path, metric=metric, labels=labels, noisy=noisy)


def score_curves_figure(curves: pd.DataFrame, averages: pd.Series, path: str | Path, *, metric: str,
                        labels: dict[str, str] | None = None, noisy: str = "noisy") -> None:
    """Fig. 14 c, d: left, the mean score over scenes against spp of the candidates in
    ``curves`` (:func:`score_curves`), one line each; right, every candidate's ``Avg.``
    (:func:`average_scores`) as horizontal bars, best on top, those of the left panel in their
    colours and the others grey."""
    plt = pyplot_agg()
    names = list(curves.columns)
    styles = candidate_styles([noisy] + [n for n in names if n != noisy], noisy)
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
    """Each candidate's ``Avg.`` score against its ensemble size (:func:`score_size_points`,
    spread sideways within a size), the mean per size with ±1 standard deviation over that
    size's candidates (:func:`score_size_summary`), the names of ``annotate`` written beside
    their points. ``ci``: optional per-candidate confidence intervals, a frame indexed by
    candidate with columns ``ci_low``, ``ci_high`` (scores), drawn as thin vertical bars."""
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
    (:func:`speed_score_points`), coloured by ensemble size; the Pareto front (max score, min
    cost) as a step line through ringed points. Only the front and ``annotate`` are labelled,
    by their pool ID beside the point and in full in the legend, so 39 candidates stay legible.
    Upper left is better."""
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
    """Each candidate's error over the equal-time noisy render's error (geometric mean over
    scenes, :func:`equal_time_curves`) against spp, log-y with a line at 1 (below: the
    candidate beats spending its time on more samples). Points relying on extrapolation beyond
    the largest measured spp (``extrapolated``) are hollow and footnoted."""
    plt = pyplot_agg()
    names = list(ratios.columns)
    styles = candidate_styles([noisy] + [n for n in names if n != noisy], noisy)
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
    :func:`mcbench.analysis.ranking.case_scores`; ``curves``: the candidates drawn as lines (the bases and
    the recommended ensembles); ``recommended``: names written beside their points in the size
    and speed figures; ``render_records``: the noisy renders' EXRs or benchmark TSVs
    (:func:`read_render_seconds`; only read for ``equal_time``); ``inputs``: method -> the
    methods it takes (default: the pool's). Returns the equal-time table (empty when not drawn).
    """
    from mcbench.io.tables import read_table
    from mcbench.analysis.ranking import case_scores

    unknown = sorted(set(paths) - set(STUDY_FIGURES))
    if unknown:
        raise ValueError(f"unknown study figure(s) {unknown}; known: {', '.join(STUDY_FIGURES)}")
    inputs = _pool_inputs() if inputs is None else inputs
    pool = [noisy] + [c for c in candidates if c != noisy]
    metrics = read_table(metrics_csv, columns=["scene", "spp", "candidate", "metric", "value"])
    metrics = metrics[metrics["candidate"].isin(pool) & (metrics["metric"] == metric)]
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

