"""Small atomic writers for the tables and JSON records the workflow produces."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pandas as pd


def _atomic_text(path: str | os.PathLike, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
