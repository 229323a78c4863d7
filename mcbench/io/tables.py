"""Small atomic writers for the tables and JSON records the workflow produces.

pandas is imported only by the table functions: a method job (a few hundred per run) writes
EXRs and JSON only and should not pay pandas' import time and memory.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from mcbench import BenchError

if TYPE_CHECKING:
    import pandas as pd


def write_atomically(path: str | os.PathLike, save, *, suffix: str = ".tmp") -> None:
    """Write ``path`` atomically: ``save(tmp)`` writes a temporary file in the same folder (its
    name ends in ``suffix``, e.g. ``.tmp.png`` for writers that infer the format), which then
    replaces ``path``; on any failure the temporary file is removed and ``path`` is untouched."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        save(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _atomic_text(path: str | os.PathLike, text: str) -> None:
    def save(tmp):
        with open(tmp, "w") as handle:
            handle.write(text)

    write_atomically(path, save)


def write_csv(path, frame: pd.DataFrame, **kwargs) -> None:
    """Write a DataFrame as CSV atomically (index off unless asked)."""
    kwargs.setdefault("index", False)
    _atomic_text(path, frame.to_csv(**kwargs))


def write_text(path, text: str) -> None:
    _atomic_text(path, text)


def write_json(path, record: dict) -> None:
    _atomic_text(path, json.dumps(record, indent=2, sort_keys=True) + "\n")


def read_json(path) -> dict:
    with open(path) as handle:
        return json.load(handle)


def read_table(path, *, columns=(), sep: str = ",") -> pd.DataFrame:
    """A CSV/TSV the workflow wrote, refused with the file named when it cannot be parsed or
    lacks one of ``columns``."""
    import pandas as pd

    try:
        frame = pd.read_csv(path, sep=sep)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise BenchError(f"{path}: cannot read table ({exc})") from exc
    missing = [column for column in columns if column not in frame.columns]
    if missing:
        raise BenchError(f"{path}: missing column(s) {', '.join(missing)}")
    return frame
