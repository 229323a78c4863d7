"""Two runs' tables side by side: are they the same study, and where not, by how much.

A run's *tables* are ``results/metrics.csv`` and every CSV, Markdown and LaTeX file under
``results/tables``, ``results/oracle`` and ``results/progressive``. Two runs of the same config
and seeds must agree on all of them byte for byte, except for what measures time: columns whose
header matches :data:`TIMING_COLUMN` (seconds, CPU, speed, machine, wall, …), rows of a long
table whose quantity is one (a cell that is a timing word, :data:`TIMING_VALUE`), a Markdown
section whose heading names one, and text lines outside a table that mention one or a duration
(:data:`DURATION`, "63 s"). :func:`table_contents` gives each table with its timing left out
(and, if asked, the text an ``ignore`` pattern matches, e.g. module paths that a refactoring
renamed in the captions); :func:`compare_runs` lists the tables that differ and, for CSV tables of equal shape, the
largest absolute and relative difference of their numeric cells (``|a - b| / max(|a|, |b|)``,
zero where both are zero), so that a difference in the last printed digit reads differently
from a changed ranking.

:func:`compare_images` does the same for the EXR files of one folder (renders, references,
method outputs): the files whose layers are not bit-identical, with the largest difference.

Used by the interruption tests (a resumed run against an uninterrupted one) and by
``tools/compare_runs.py`` (a default run before and after a change).
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from mcbench.io.exr import read_layers

#: Columns that hold measured times (or are derived from them); every other value must match.
TIMING_COLUMN = re.compile(r"second|time|cpu|speed|hours|machine|wall", re.IGNORECASE)
#: A cell that names a timing quantity (the ``quantity`` column of a long table): its row is timing.
TIMING_VALUE = re.compile(r"(?:\w+_)?(?:seconds?|time|cpu|speed|hours|wall)(?:_\w+)?", re.IGNORECASE)
#: A duration in running text (a caption's "…; 63 s", "2.5 min"): the line is timing.
DURATION = re.compile(r"\b\d+(?:\.\d+)?\s?(?:s|ms|min|h)\b")
#: Folders under ``results/`` whose CSV, Markdown and LaTeX files are tables.
TABLE_FOLDERS = ("tables", "oracle", "progressive")
TABLE_SUFFIXES = (".csv", ".md", ".tex")


def _without_ignored(text: str, ignore: re.Pattern | None) -> str:
    """``text`` with what ``ignore`` matches removed (unchanged without a pattern)."""
    return text if ignore is None else ignore.sub("", text)


def table_without_timing(path: Path, *, ignore: re.Pattern | None = None) -> str:
    """The content of one table with its timing left out.

    CSV/TSV: the columns whose header matches :data:`TIMING_COLUMN` are dropped, and the rows with
    a cell that is a timing word (:data:`TIMING_VALUE`, e.g. ``quantity = seconds``); the rest is
    written back by pandas. Markdown/LaTeX: in a Markdown table, the columns whose header cell
    matches are dropped (a header row is a ``|`` row followed by a ``|---|`` rule); a section
    under a heading (``#`` line) that matches is blanked to the next heading; any other line that
    matches :data:`TIMING_COLUMN` or holds a :data:`DURATION` is blanked. ``ignore``: text it
    matches is removed first (Markdown/LaTeX) or from every cell (CSV).
    """
    path = Path(path)
    if path.suffix in (".csv", ".tsv"):
        frame = pd.read_csv(path, sep="\t" if path.suffix == ".tsv" else ",")
        frame = frame.drop(columns=[c for c in frame.columns if TIMING_COLUMN.search(str(c))])
        timing_rows = [any(isinstance(v, str) and TIMING_VALUE.fullmatch(v) for v in row)
                       for row in frame.itertuples(index=False)]
        frame = frame[[not timing for timing in timing_rows]]
        return _without_ignored(frame.to_csv(index=False), ignore)
    lines = _without_ignored(path.read_text(), ignore).splitlines()
    kept, drop, timing_section = [], set(), False
    for number, line in enumerate(lines):
        if line.startswith("#"):
            timing_section = bool(TIMING_COLUMN.search(line))
        if timing_section:
            kept.append("")
            continue
        if not line.startswith("|"):
            drop = set()
            kept.append("" if TIMING_COLUMN.search(line) or DURATION.search(line) else line)
            continue
        cells = line.strip().strip("|").split("|")
        following = lines[number + 1] if number + 1 < len(lines) else ""
        if following.startswith("|") and set(following.replace("|", "").strip()) <= set("-: "):
            drop = {i for i, cell in enumerate(cells) if TIMING_COLUMN.search(cell)}   # a header row
        kept.append("|".join(cell for i, cell in enumerate(cells) if i not in drop))
    return "\n".join(kept)


def table_paths(results: Path) -> list[Path]:
    """``results/metrics.csv`` and every CSV, Markdown and LaTeX file under :data:`TABLE_FOLDERS`
    (hidden files, the checksums, are not tables), in a fixed order."""
    results = Path(results)
    metrics = results / "metrics.csv"
    if not metrics.is_file():
        raise ValueError(f"{metrics}: no metrics.csv; is {results} the results folder of a finished run?")
    return [metrics] + [path for folder in TABLE_FOLDERS for path in sorted((results / folder).rglob("*"))
                        if path.is_file() and path.suffix in TABLE_SUFFIXES and not path.name.startswith(".")]


def table_contents(results: Path, *, ignore: re.Pattern | None = None) -> dict[str, str]:
    """``metrics.csv`` (as written) and every table of :data:`TABLE_FOLDERS` (timing and what
    ``ignore`` matches left out), keyed by the path relative to ``results``."""
    metrics, *tables = table_paths(results)
    contents = {"metrics.csv": _without_ignored(metrics.read_text(), ignore)}
    for path in tables:
        contents[str(path.relative_to(results))] = table_without_timing(path, ignore=ignore)
    return contents


@dataclass(frozen=True)
class TableDifference:
    """One table that is not the same in both runs.

    ``status`` is ``"only in a"``, ``"only in b"`` or ``"differs"``; for a CSV table of equal
    shape and columns, ``cells`` counts the differing cells and ``max_abs`` / ``max_rel`` are the
    largest differences of its numeric cells (None where the tables cannot be aligned)."""

    table: str
    status: str
    cells: int | None = None
    max_abs: float | None = None
    max_rel: float | None = None


def _largest_differences(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Largest ``|x - y|`` and ``|x - y| / max(|x|, |y|)`` over the elements finite in both
    (relative difference zero where both are zero); (0, 0) when none is."""
    both = np.isfinite(x) & np.isfinite(y)
    absolute = np.where(both, np.abs(np.where(both, x, 0.0) - np.where(both, y, 0.0)), 0.0)
    scale = np.maximum(np.abs(np.where(both, x, 0.0)), np.abs(np.where(both, y, 0.0)))
    relative = np.divide(absolute, scale, out=np.zeros_like(absolute), where=scale > 0)
    return float(absolute.max(initial=0.0)), float(relative.max(initial=0.0))


def _numeric_difference(text_a: str, text_b: str) -> tuple[int | None, float | None, float | None]:
    """Differing cells and the largest absolute/relative difference of two CSV texts of equal
    shape and header; (None, None, None) where they cannot be aligned."""
    try:
        a, b = pd.read_csv(io.StringIO(text_a)), pd.read_csv(io.StringIO(text_b))
    except (pd.errors.ParserError, pd.errors.EmptyDataError):
        return None, None, None
    if a.shape != b.shape or list(a.columns) != list(b.columns):
        return None, None, None
    differing = int((a.astype(str).to_numpy() != b.astype(str).to_numpy()).sum())
    numeric = [c for c in a.columns if pd.api.types.is_numeric_dtype(a[c]) and pd.api.types.is_numeric_dtype(b[c])]
    if not numeric:
        return differing, None, None
    return (differing, *_largest_differences(a[numeric].to_numpy(np.float64), b[numeric].to_numpy(np.float64)))


def compare_runs(results_a: Path, results_b: Path, *, ignore: re.Pattern | None = None) -> list[TableDifference]:
    """The tables of two runs' results folders that are not the same (timing and what ``ignore``
    matches left out), sorted by name; an empty list means the two runs made the same study."""
    a, b = table_contents(results_a, ignore=ignore), table_contents(results_b, ignore=ignore)
    differences = []
    for name in sorted(set(a) | set(b)):
        if name not in b:
            differences.append(TableDifference(name, "only in a"))
        elif name not in a:
            differences.append(TableDifference(name, "only in b"))
        elif a[name] != b[name]:
            cells, max_abs, max_rel = (_numeric_difference(a[name], b[name]) if name.endswith(".csv")
                                       else (None, None, None))
            differences.append(TableDifference(name, "differs", cells, max_abs, max_rel))
    return differences


def compare_images(results_a: Path, results_b: Path, folder: str) -> list[TableDifference]:
    """The EXR files under ``results_*/folder`` whose layers are not bit-identical (NaN equal to
    NaN), by path relative to ``results``; ``cells`` counts the differing values, ``max_abs`` /
    ``max_rel`` the largest differences among the finite ones (relative as in
    :func:`compare_runs`). Header attributes (checksums, render times) are not compared."""
    root_a, root_b = Path(results_a), Path(results_b)
    files_a = {p.relative_to(root_a) for p in (root_a / folder).rglob("*.exr")}
    files_b = {p.relative_to(root_b) for p in (root_b / folder).rglob("*.exr")}
    differences = []
    for name in sorted(files_a | files_b):
        if name not in files_b:
            differences.append(TableDifference(str(name), "only in a"))
            continue
        if name not in files_a:
            differences.append(TableDifference(str(name), "only in b"))
            continue
        layers_a, layers_b = read_layers(root_a / name), read_layers(root_b / name)
        if sorted(layers_a) != sorted(layers_b) or any(layers_a[k].shape != layers_b[k].shape for k in layers_a):
            differences.append(TableDifference(str(name), "differs"))
            continue
        x = np.concatenate([layers_a[k].astype(np.float64).ravel() for k in sorted(layers_a)])
        y = np.concatenate([layers_b[k].astype(np.float64).ravel() for k in sorted(layers_a)])
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        if same.all():
            continue
        differences.append(TableDifference(str(name), "differs", int((~same).sum()), *_largest_differences(x, y)))
    return differences
