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


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _current_umask()   # read once at import (os.umask can only be read by setting it)


def write_atomically(path: str | os.PathLike, save, *, suffix: str = ".tmp") -> None:
    """Write ``path`` atomically: ``save(tmp)`` writes a temporary file in the same folder (its
    name ends in ``suffix``, e.g. ``.tmp.png`` for writers that infer the format), which then
    replaces ``path``; on any failure the temporary file is removed and ``path`` is untouched. An
    OSError (no space left, a read-only file system) becomes a :class:`BenchError` naming ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    except OSError as exc:        # a read-only or full file system: name the file and the reason
        raise BenchError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    os.close(fd)
    try:
        save(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)   # mkstemp makes the file private; give it the usual mode
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise BenchError(f"{path}: cannot write ({exc.strerror or exc})") from exc
        raise


def write_sidecar(path: str | os.PathLike, data: bytes) -> None:
    """Write the checksum side file of text file ``path`` for its content ``data``
    (:func:`mcbench.io.checksums.sidecar_path`), atomically, before ``path`` is replaced: a run
    killed between the two leaves a checksum that refuses the old content, and Snakemake reruns
    the job whose output was incomplete anyway."""
    from mcbench.io.checksums import crc32_hex, sidecar_path

    digest = crc32_hex(data)

    def save(tmp):
        with open(tmp, "w") as handle:
            handle.write(digest + "\n")

    write_atomically(sidecar_path(path), save)


def _atomic_text(path: str | os.PathLike, text: str, *, checksum: bool = True) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, with its checksum side file unless
    ``checksum`` is false (:mod:`mcbench.io.checksums`; written first, so a run killed between
    the two leaves a checksum that refuses the old content)."""
    data = text.encode("utf-8")
    if checksum:
        write_sidecar(path, data)

    def save(tmp):
        with open(tmp, "wb") as handle:
            handle.write(data)

    write_atomically(path, save)


def read_checked_bytes(path: str | os.PathLike) -> bytes:
    """The bytes of a text file the workflow wrote, refused (naming the file) when it cannot be read
    or does not match its checksum side file (:func:`mcbench.io.checksums.check_bytes`)."""
    from mcbench.io.checksums import check_bytes

    try:
        with open(path, "rb") as handle:
            data = handle.read()
    except OSError as exc:
        raise BenchError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    check_bytes(path, data)
    return data


def write_csv(path, frame: pd.DataFrame, **kwargs) -> None:
    """Write a DataFrame as CSV atomically (index off unless asked), with its checksum side file."""
    kwargs.setdefault("index", False)
    _atomic_text(path, frame.to_csv(**kwargs))


def write_text(path, text: str, *, checksum: bool = True) -> None:
    """Write a text file atomically, with its checksum side file unless ``checksum`` is false."""
    _atomic_text(path, text, checksum=checksum)


def write_json(path, record: dict, *, checksum: bool = True) -> None:
    """Write a JSON record atomically (no NaN/Inf: refused), with its checksum side file unless
    ``checksum`` is false (e.g. a record committed to git, which a checkout may change)."""
    _atomic_text(path, json.dumps(record, indent=2, sort_keys=True, allow_nan=False) + "\n",
                 checksum=checksum)


def read_json(path) -> dict:
    """A JSON record the workflow wrote, refused (naming the file) when it cannot be read, does not
    match its checksum, is not JSON, holds NaN/Inf or is not an object."""
    data = read_checked_bytes(path)

    def refuse_constant(name):
        raise ValueError(f"non-finite number {name}")

    try:
        record = json.loads(data.decode("utf-8"), parse_constant=refuse_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise BenchError(f"{path}: not a valid JSON record ({exc})") from exc
    if not isinstance(record, dict):
        raise BenchError(f"{path}: not a JSON record (an object), but {type(record).__name__}")
    return record


def read_table(path, *, columns=(), sep: str = ",") -> pd.DataFrame:
    """A CSV/TSV the workflow wrote, refused with the file named when it does not match its
    checksum, cannot be parsed, lacks one of ``columns`` or holds a value of the wrong kind in one of
    them (:data:`TYPED_COLUMNS`)."""
    import io

    import numpy as np
    import pandas as pd

    data = read_checked_bytes(path)
    try:
        frame = pd.read_csv(io.BytesIO(data), sep=sep)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise BenchError(f"{path}: cannot read table ({exc})") from exc
    missing = [column for column in columns if column not in frame.columns]
    if missing:
        renamed = [f"'{RENAMED_COLUMNS[c]}' (now '{c}')" for c in missing
                   if RENAMED_COLUMNS.get(c) in frame.columns]
        raise BenchError(f"{path}: missing column(s) {', '.join(missing)}" + (
            f"; it has {', '.join(renamed)}: a table of an earlier mcbench, remade by rerunning the job that "
            f"writes it (snakemake -f {path})" if renamed else ""))
    for column in columns:
        kind = TYPED_COLUMNS.get(column)
        if kind is None or not len(frame):
            continue
        values = pd.to_numeric(frame[column], errors="coerce").to_numpy(dtype=float)
        bad = ~np.isfinite(values)
        if kind == "integer":
            bad |= np.isfinite(values) & (values != np.round(values))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise BenchError(f"{path}: column '{column}' holds {frame[column].iloc[row]!r} in data row {row + 1}; "
                             f"expected {'a whole number' if kind == 'integer' else 'a finite number'}")
    return frame


#: Columns of the tables the workflow writes -> the name an earlier mcbench gave them: a table
#: with the earlier name is refused by :func:`read_table`, saying so, never read as another column.
RENAMED_COLUMNS = {"entry": "candidate"}

#: Columns whose values :func:`read_table` checks when a caller asks for them: ``spp`` (and image
#: sizes) whole numbers; times and ``value`` (an error metric) finite numbers.
TYPED_COLUMNS = {"spp": "integer", "width": "integer", "height": "integer", "seconds": "number",
                 "cpu_time": "number", "value": "number"}
