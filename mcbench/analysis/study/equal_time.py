"""The equal-time view of the 39-candidate study: each candidate's error against that of a noisy
render given the same total time (render + method), per test case (:func:`equal_time_table`)
and as the geometric mean over scenes (:func:`equal_time_curves`).

Inputs: ``metrics`` (columns ``scene, spp, entry, metric, value``; ``results/metrics.csv``),
``timings`` (columns ``scene, spp, method, seconds``; compute seconds of one method run, I/O
excluded) and render times (columns ``scene, spp, seconds``, :func:`read_render_seconds`).

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

from mcbench.analysis.error_speed_figures import input_closure
from mcbench.analysis.study.scores_and_costs import select_rows

__all__ = ["read_render_seconds", "loglog_interp", "equal_time_table", "equal_time_curves"]

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


def _closure_cost(name: str, inputs: dict[str, list[str]], per_case: pd.Series, scene: str, spp: int) -> float:
    """The seconds of ``name``'s input closure in one case (each method once), from ``per_case``
    (mean seconds by scene, spp, method); ValueError naming a method without a timing."""
    cost = 0.0
    for method in input_closure(name, inputs):
        if (scene, spp, method) not in per_case.index:
            raise ValueError(f"no timing of '{method}' (needed by '{name}') in scene '{scene}' "
                             f"at {spp} spp")
        cost += float(per_case[(scene, spp, method)])
    return cost


def _scene_equal_time(scene: str, scene_rows: pd.DataFrame, renders: pd.DataFrame, per_case: pd.Series, *,
                      names: list[str], inputs: dict[str, list[str]], metric: str, noisy: str,
                      tiny: float) -> list[dict]:
    """The rows of :func:`equal_time_table` of one scene (``scene_rows``: its ``metric`` rows;
    ``renders``: its render times)."""
    if renders.empty:
        raise ValueError(f"no render time for scene '{scene}'")
    if not (np.isfinite(renders["seconds"].to_numpy(np.float64)).all() and (renders["seconds"] > 0).all()):
        raise ValueError(f"render times of scene '{scene}' must be positive numbers")
    m_spp, m_sec = _monotone_times(renders["spp"].to_numpy(np.float64), renders["seconds"].to_numpy(np.float64))
    r_spp, r_sec = _invertible(m_spp, m_sec)
    noisy_rows = scene_rows[scene_rows["entry"] == noisy].groupby("spp")["value"].mean().sort_index()
    if noisy_rows.empty:
        raise ValueError(f"no '{metric}' of the noisy input '{noisy}' in scene '{scene}'")
    n_spp = noisy_rows.index.to_numpy(np.float64)
    n_err = np.maximum(noisy_rows.to_numpy(np.float64), tiny)
    values = scene_rows.groupby(["spp", "entry"])["value"].mean()
    out = []
    for spp in sorted(set(int(s) for s in scene_rows["spp"])):
        if not np.any(m_spp == spp):
            raise ValueError(f"no render time for scene '{scene}' at {spp} spp")
        render_time = float(m_sec[m_spp == spp][0])  # the measured time, made monotone
        for name in names:
            if (spp, name) not in values.index:
                raise ValueError(f"no '{metric}' of '{name}' in scene '{scene}' at {spp} spp")
            cost = _closure_cost(name, inputs, per_case, scene, spp)
            total = render_time + cost
            equal_spp, beyond = loglog_interp(total, r_sec, r_spp, slope=None if len(r_spp) > 1 else 1.0)
            noisy_error, beyond_error = loglog_interp(equal_spp, n_spp, n_err)
            noisy_error = np.maximum(noisy_error, tiny)
            error = max(float(values[(spp, name)]), tiny)
            out.append({"scene": scene, "spp": spp, "candidate": name, "error": error,
                        "method_seconds": cost, "render_seconds": render_time, "total_seconds": total,
                        "equal_spp": float(equal_spp[0]), "noisy_error": float(noisy_error[0]),
                        "ratio": error / float(noisy_error[0]),
                        "extrapolated": bool(beyond[0] or beyond_error[0])})
    return out


def equal_time_table(metrics: pd.DataFrame, timings: pd.DataFrame, render_seconds: pd.DataFrame, *,
                     metric: str, inputs: dict[str, list[str]], candidates: list[str] | None = None,
                     noisy: str = "noisy", tiny: float = 1e-12) -> pd.DataFrame:
    """The noisy render's error at the same total time as each candidate, per test case.

    For a candidate at (scene, spp): ``method_seconds`` is its input closure's cost in that case (each method's
    own seconds of that case, mean over repeated runs, each method once); ``render_seconds`` the noisy render's
    time at spp (made non-decreasing in spp, see below); ``total_seconds`` their sum. ``equal_spp`` is the spp
    whose render takes ``total_seconds``: the render time interpolated against spp in log-log over the scene's
    measured spp, and beyond the largest spp the last segment's log-log line continued (``extrapolated`` True;
    with one measured spp, time proportional to spp). ``noisy_error`` is the noisy render's ``metric`` at
    ``equal_spp``, interpolated in log-log against spp likewise (extrapolated by the last segment beyond the
    largest spp). ``ratio`` = ``error`` / ``noisy_error``: below 1 the candidate beats spending its time on more
    samples. Errors are floored at ``tiny`` for the logarithms (the interpolated noisy error too). Render times
    that fall as spp grows are timing noise, raised to the running maximum; of equal render times the inverse
    takes the largest spp.

    Returns columns scene, spp, candidate, error, method_seconds, render_seconds,
    total_seconds, equal_spp, noisy_error, ratio, extrapolated (bool); rows in scene, spp,
    candidate order. Raises ``ValueError`` naming a case without a render time, a noisy error
    or a timing."""
    rows = metrics[metrics["metric"] == metric]
    if rows.empty:
        raise ValueError(f"no '{metric}' values in the metrics table")
    names = [c for c in dict.fromkeys(rows["entry"]) if c != noisy] if candidates is None else \
        [c for c in candidates if c != noisy]
    per_case = timings.groupby(["scene", "spp", "method"])["seconds"].mean()
    out = []
    for scene, scene_rows in rows.groupby("scene", sort=True):
        out += _scene_equal_time(scene, scene_rows, render_seconds[render_seconds["scene"] == scene], per_case,
                                 names=names, inputs=inputs, metric=metric, noisy=noisy, tiny=tiny)
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
    rows = select_rows(table, "candidate", candidates)
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
