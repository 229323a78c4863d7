"""Checksums of the files the workflow writes, so that a damaged file is refused, never read.

A file that the harness reads back (a render, a reference, a method's output, a per-case metrics
CSV, a timing record, a viewer case) can be damaged between its writing and its reading: a disk
or copy error, a truncated transfer, a hand edit. Most damage makes the file unreadable, and the
reader says so; but a flipped bit in a pixel or a digit leaves a valid file holding a wrong
number, which no format check can see. So every file the harness writes carries a CRC-32
(``zlib.crc32``: the standard's polynomial, fast, in the standard library; it detects every
single-bit and burst error up to 32 bits, which is what it is for here — not an adversary):

* an EXR written by :func:`mcbench.io.exr.write_layers` holds it as the header attribute
  ``mcbench.crc32`` (:func:`exr_checksum`: over its size, its layer names, its other
  ``mcbench.*`` attributes and every layer's float32 pixels), checked by every reader of
  :mod:`mcbench.io.exr`;
* a text file (CSV, JSON, Markdown) written by :mod:`mcbench.io.tables` has it in a hidden
  side file ``.NAME.crc32`` beside it (:func:`sidecar_path`, written by
  :func:`mcbench.io.tables.write_sidecar`), so that the file itself stays
  plain CSV/JSON for pandas, a spreadsheet or a notebook; its readers check it.

A file without a checksum (written by another program, or by an older mcbench) is read as it
is: the checksum guards what the harness wrote, it does not refuse outside data. A file whose
checksum does not match is refused with :class:`ChecksumError`, naming the file; a file edited on
purpose is accepted again once its side file is deleted (the message says so).
"""

from __future__ import annotations

import os
import zlib
from pathlib import Path

import numpy as np

from mcbench import BenchError

__all__ = ["ChecksumError", "CHECKSUM_ATTRIBUTE", "crc32_hex", "sidecar_path", "read_sidecar",
           "check_bytes", "layer_crc", "exr_checksum"]

#: The EXR header attribute (without the ``mcbench.`` prefix) that holds an EXR's checksum.
CHECKSUM_ATTRIBUTE = "crc32"


class ChecksumError(BenchError):
    """A file's content does not match the checksum written with it; the message names the file."""


def crc32_hex(data: bytes | memoryview, start: int = 0) -> str:
    """The CRC-32 of ``data`` (continuing from ``start``) as 8 lowercase hex digits."""
    return f"{zlib.crc32(data, start) & 0xFFFFFFFF:08x}"


def sidecar_path(path: str | os.PathLike) -> Path:
    """The hidden side file holding the checksum of text file ``path``: ``.NAME.crc32`` beside it."""
    path = Path(path)
    return path.parent / f".{path.name}.crc32"


def read_sidecar(path: str | os.PathLike) -> str | None:
    """The checksum recorded for text file ``path``, or None when it has no side file."""
    side = sidecar_path(path)
    try:
        text = side.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise ChecksumError(f"{path}: cannot read its checksum file {side} ({exc})") from exc
    digest = text.strip()
    if len(digest) != 8 or any(c not in "0123456789abcdef" for c in digest):
        raise ChecksumError(f"{path}: its checksum file {side} is damaged ({text[:40]!r}); rerun the job "
                            f"that writes {Path(path).name}")
    return digest


def check_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Refuse the content ``data`` of text file ``path`` when it has a side file that disagrees."""
    recorded = read_sidecar(path)
    if recorded is not None and crc32_hex(data) != recorded:
        raise ChecksumError(f"{path}: content does not match its checksum {sidecar_path(path).name} "
                            f"(damaged after it was written); rerun the job that writes it (or delete "
                            f"the checksum file if you edited it on purpose)")


def layer_crc(pixels: np.ndarray, start: int = 0) -> int:
    """CRC-32 of a layer's pixels as C-ordered float32 bytes (continuing from ``start``: a layer
    read by row blocks gives the same value as read whole)."""
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    return zlib.crc32(memoryview(pixels).cast("B"), start) & 0xFFFFFFFF


def exr_checksum(*, width: int, height: int, layer_crcs: dict[str, int], metadata: dict[str, str]) -> str:
    """The checksum of an EXR written by :func:`mcbench.io.exr.write_layers`: the CRC-32 of a
    descriptor (size, sorted layer names, the sorted ``mcbench.*`` attributes other than the
    checksum, as ``key=value``) followed by each layer's pixel CRC (:func:`layer_crc`) in the
    order of the sorted names, 4 bytes big-endian each."""
    names = sorted(layer_crcs)
    fields = [f"{width}x{height}", ",".join(names)]
    fields += [f"{key}={metadata[key]}" for key in sorted(metadata)
               if key not in (CHECKSUM_ATTRIBUTE, f"mcbench.{CHECKSUM_ATTRIBUTE}")]
    data = "\n".join(fields).encode("utf-8") + b"".join(layer_crcs[n].to_bytes(4, "big") for n in names)
    return crc32_hex(data)
