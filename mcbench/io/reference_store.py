"""The reference store: references rendered once, kept in the repository, read by any run.

A stored reference is two files in ``<store>/<W>x<H>/``:

* ``<scene>.exr`` -- the layers a study reads of a reference, ``color`` and ``variance`` (the
  per-pixel variance of the mean colour), float32, ZIP-compressed (lossless), with the project's
  CRC-32 header (:mod:`mcbench.io.checksums`);
* ``<scene>.json`` -- its record: ``identity`` (what a run must match to use it: the scene and its
  digest, the resolution, the Mitsuba version, the colour mode), ``provenance`` (how it was made:
  commit, Dr.Jit version, variant, CPU, spp, seeds, render seconds, feature convention), the
  EXR's file name, size in bytes and SHA-256.

A run reads the record first (cheap, also while a DAG is planned), compares its identity with its
own (:func:`identity_mismatches`) and reads the pixels only through :func:`read_stored_layers`,
which refuses, naming the file, anything that is not exactly what was stored: a missing,
truncated or altered EXR (size, SHA-256 and CRC-32), other shapes, NaN/Inf, negative variance.
Whether a stored reference is the expected value of this machine's renderer is a statistical
question for :mod:`mcbench.analysis.reference_check`, asked by the pipeline before any table uses it.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mcbench import BenchError
from mcbench.io.exr import check_finite, read_layers, write_layers
from mcbench.io.tables import write_atomically

__all__ = ["STORE_FORMAT", "STORED_LAYERS", "IDENTITY_KEYS", "StoredReference", "StoreError",
           "store_paths", "write_stored_reference", "read_store_record", "identity_mismatches",
           "read_stored_layers", "file_sha256"]

#: The version of the record's layout; a record of another version is refused.
STORE_FORMAT = 1
#: The layers a stored reference holds (all a study reads of a reference).
STORED_LAYERS = ("color", "variance")
#: The keys of a record's identity, each of which must equal the run's for the record to be used.
IDENTITY_KEYS = ("scene", "scene_digest", "resolution", "mitsuba", "color_mode")


class StoreError(BenchError):
    """A stored reference that cannot be used as it is: damaged, truncated, malformed or foreign;
    the message names the file."""


@dataclass(frozen=True)
class StoredReference:
    """A stored reference's record (``<scene>.json``) and where its EXR lies."""

    record_path: Path
    exr_path: Path
    identity: dict
    provenance: dict
    sha256: str
    size: int


def store_paths(store: str | os.PathLike, scene: str, resolution: tuple[int, int]) -> tuple[Path, Path]:
    """The EXR and the record of ``scene`` at ``resolution`` = (width, height) in ``store``."""
    folder = Path(store) / f"{int(resolution[0])}x{int(resolution[1])}"
    return folder / f"{scene}.exr", folder / f"{scene}.json"


def file_sha256(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_layers(what: str, layers: dict[str, np.ndarray], resolution: tuple[int, int]) -> None:
    width, height = int(resolution[0]), int(resolution[1])
    for name in STORED_LAYERS:
        if name not in layers:
            raise StoreError(f"{what}: no '{name}' layer (a stored reference holds {list(STORED_LAYERS)})")
        if layers[name].shape != (height, width, 3):
            raise StoreError(f"{what}: layer '{name}' is {layers[name].shape}, expected ({height}, {width}, 3) "
                             f"for resolution {width}x{height}")
    check_finite(what, {name: layers[name] for name in STORED_LAYERS})
    if (layers["variance"] < 0).any():
        raise StoreError(f"{what}: layer 'variance' has negative values")


def write_stored_reference(store: str | os.PathLike, scene: str, layers: dict[str, np.ndarray], *,
                           identity: dict, provenance: dict) -> StoredReference:
    """Store ``layers`` (``color`` and ``variance``, each (H, W, 3)) as the reference of ``scene``:
    the EXR first, then its record (both atomically), so a record never names a missing EXR.

    ``identity`` must hold exactly :data:`IDENTITY_KEYS` (its ``resolution`` "WxH" matching the
    layers' shape); ``provenance`` is stored as given (JSON values)."""
    if sorted(identity) != sorted(IDENTITY_KEYS):
        raise ValueError(f"identity keys {sorted(identity)}; expected {sorted(IDENTITY_KEYS)}")
    if identity["scene"] != scene:
        raise ValueError(f"identity names scene {identity['scene']!r}, storing {scene!r}")
    height, width = np.shape(layers["color"])[:2]
    if identity["resolution"] != f"{width}x{height}":
        raise ValueError(f"identity resolution {identity['resolution']!r}; the layers are {width}x{height}")
    exr_path, record_path = store_paths(store, scene, (width, height))
    _check_layers(f"reference of scene '{scene}'", layers, (width, height))
    write_layers(exr_path, {name: layers[name] for name in STORED_LAYERS},
                 {"scene": scene, "resolution": identity["resolution"], "source": "store"}, compression="zip")
    record = {"format": STORE_FORMAT, "identity": dict(identity), "provenance": dict(provenance),
              "file": exr_path.name, "bytes": exr_path.stat().st_size, "sha256": file_sha256(exr_path)}
    text = json.dumps(record, indent=1, sort_keys=True) + "\n"
    write_atomically(record_path, lambda tmp: Path(tmp).write_text(text), suffix=".tmp.json")
    return read_store_record(store, scene, (width, height))


def read_store_record(store: str | os.PathLike, scene: str,
                      resolution: tuple[int, int]) -> StoredReference | None:
    """The record of ``scene`` at ``resolution`` in ``store``, or None when the store has none.
    A record that is not valid JSON of :data:`STORE_FORMAT` with every field is refused, naming it."""
    exr_path, record_path = store_paths(store, scene, resolution)
    if not record_path.exists():
        return None
    try:
        record = json.loads(record_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StoreError(f"{record_path}: unreadable record of a stored reference ({exc}); regenerate "
                         "the store or delete the record to render the reference") from exc
    if not isinstance(record, dict) or record.get("format") != STORE_FORMAT:
        raise StoreError(f"{record_path}: not a stored-reference record of format {STORE_FORMAT}")
    missing = [key for key in ("identity", "provenance", "file", "bytes", "sha256") if key not in record]
    identity = record.get("identity")
    if missing or not isinstance(identity, dict) or sorted(identity) != sorted(IDENTITY_KEYS):
        raise StoreError(f"{record_path}: record lacks {missing or 'identity keys ' + str(list(IDENTITY_KEYS))}")
    if record["file"] != exr_path.name or identity["scene"] != scene:
        raise StoreError(f"{record_path}: record of {identity['scene']!r} / {record['file']!r}, "
                         f"expected scene {scene!r} / {exr_path.name!r}")
    return StoredReference(record_path=record_path, exr_path=exr_path, identity=identity,
                           provenance=record["provenance"], sha256=str(record["sha256"]),
                           size=int(record["bytes"]))


def identity_mismatches(stored: StoredReference, identity: dict) -> list[str]:
    """What differs between a stored reference's identity and a run's, one line per key
    (empty: the stored reference is of this run's scene, resolution and renderer)."""
    return [f"{key}: stored {stored.identity.get(key)!r}, this run {identity.get(key)!r}"
            for key in IDENTITY_KEYS if stored.identity.get(key) != identity.get(key)]


def read_stored_layers(stored: StoredReference) -> dict[str, np.ndarray]:
    """The ``color`` and ``variance`` layers of a stored reference, (H, W, 3) float32 each, after
    checking its EXR against its record (present, same size, same SHA-256), its CRC-32, its shapes,
    finiteness and non-negative variance; :class:`StoreError` naming the file otherwise."""
    path = stored.exr_path
    if not path.exists():
        raise StoreError(f"{path}: stored reference is missing (its record {stored.record_path} names it)")
    size = path.stat().st_size
    if size != stored.size:
        raise StoreError(f"{path}: stored reference is {size} bytes, its record says {stored.size} "
                         "(truncated or replaced)")
    if file_sha256(path) != stored.sha256:
        raise StoreError(f"{path}: stored reference's SHA-256 differs from its record's (damaged or replaced)")
    layers = read_layers(path, list(STORED_LAYERS))
    width, height = (int(v) for v in stored.identity["resolution"].split("x"))
    _check_layers(str(path), layers, (width, height))
    return layers
