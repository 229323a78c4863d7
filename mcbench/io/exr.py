"""Multi-layer OpenEXR I/O through the OpenEXR Python bindings.

A file holds named layers: a 3-channel layer ``color`` is stored as the channels
``color.R``, ``color.G``, ``color.B``; a 1-channel layer ``depth`` as ``depth``.
Writes are atomic (temporary file in the same folder, then ``os.replace``), so a run
killed mid-write never leaves a truncated EXR behind that Snakemake would trust. Every file
:func:`write_layers` writes carries a checksum of its size, layer names, ``mcbench.*``
attributes and pixels (header attribute ``mcbench.crc32``, :func:`mcbench.io.checksums.exr_checksum`),
and every reader here checks it: a flipped bit that leaves a valid EXR with a wrong pixel is
refused (:class:`mcbench.io.checksums.ChecksumError`) like a truncated file. Files without the
attribute (written elsewhere) are read unchecked.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenEXR

from mcbench import BenchError
from mcbench.io.checksums import CHECKSUM_ATTRIBUTE, ChecksumError, exr_checksum, layer_crc

__all__ = ["ExrError", "NonFiniteError", "read_layers", "write_layers", "read_metadata", "recorded_spp", "recorded_checksum", "content_checksum", "check_finite",
           "check_resolution", "write_exr_atomically",
           "LayerRows", "layer_rows"]


class ExrError(BenchError):
    """A missing, corrupt or incomplete EXR file; the message names the file."""


class NonFiniteError(BenchError):
    """An EXR layer holds NaN or Inf pixels; the message names the file, layer and count."""


#: Lossless compressions :func:`write_layers` offers. ``zstd`` (OpenEXR >= 3.4: byte-shuffled
#: Zstandard) shrinks float32 layers most and decodes fastest of the compressed ones; files written
#: with it need an OpenEXR 3.4 or later to be read (older viewers and libraries refuse them).
COMPRESSIONS = {"none": OpenEXR.NO_COMPRESSION, "zip": OpenEXR.ZIP_COMPRESSION, "zstd": OpenEXR.ZSTD_COMPRESSION}


def write_layers(path: str | os.PathLike, layers: dict[str, np.ndarray],
                 metadata: dict[str, str | int | float] | None = None,
                 dtype=np.float32, *, compression: str = "none") -> None:
    """Write ``layers`` (each (H, W) or (H, W, 3)) to an EXR, atomically.

    ``metadata`` values are stored as string header attributes (``mcbench.<key>``).
    ``compression``: one of :data:`COMPRESSIONS` (default ``"none"``). Renders and the method
    outputs a case keeps (those another method reads) are ``"zstd"``: 0.49 and 0.79 of their
    uncompressed bytes (ZIP: 0.60 and 0.97), read in 1.7x and 1.6x the time of an uncompressed file
    (ZIP: 3x and 2.7x); the outputs a case removes after evaluating them are written uncompressed;
    stored references are ZIP (``benchmarks/exr_compression.py``, docs/measurements.md).
    """
    if compression not in COMPRESSIONS:
        raise ValueError(f"{path}: compression {compression!r}; expected one of {sorted(COMPRESSIONS)}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    channels = {}
    shape = None
    for name, array in layers.items():
        array = np.ascontiguousarray(array, dtype=dtype)
        if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (1, 3)):
            raise ValueError(f"{path}: layer '{name}' has shape {array.shape}; expected (H, W) or (H, W, 3)")
        if array.ndim == 3 and array.shape[2] == 1:
            array = np.ascontiguousarray(array[..., 0])
        if shape is None:
            shape = array.shape[:2]
        elif array.shape[:2] != shape:
            raise ValueError(f"{path}: layer '{name}' is {array.shape[:2]}, other layers are {shape}")
        channels[name] = array
    header = {"compression": COMPRESSIONS[compression], "type": OpenEXR.scanlineimage}
    attributes = {f"mcbench.{key}": str(value) for key, value in (metadata or {}).items()}
    attributes.pop(f"mcbench.{CHECKSUM_ATTRIBUTE}", None)
    attributes[f"mcbench.{CHECKSUM_ATTRIBUTE}"] = exr_checksum(
        width=shape[1], height=shape[0], metadata=attributes,
        layer_crcs={name: layer_crc(array) for name, array in channels.items()})
    header.update(attributes)
    write_exr_atomically(path, header, channels)


def write_exr_atomically(path: str | os.PathLike, header: dict, channels: dict) -> None:
    """Write an EXR of ``header`` and ``channels`` (the OpenEXR bindings' dicts) to ``path`` through
    a temporary file in its folder and a rename; a failure of the bindings (e.g. a full disk,
    where they raise a bare Exception) becomes :class:`ExrError` naming the file."""
    def save(tmp):
        try:
            with OpenEXR.File(header, channels) as exr:
                exr.write(tmp)
        except OSError:
            raise
        except Exception as exc:   # the bindings raise a bare Exception, e.g. on a full disk
            raise ExrError(f"{path}: cannot write EXR ({exc})") from exc

    from mcbench.io.tables import write_atomically   # at call time: readers of EXRs need no tables module

    write_atomically(path, save, suffix=".tmp.exr")


def _open(path: Path, *, header_only: bool = False) -> OpenEXR.File:
    if not path.exists():
        raise ExrError(f"{path}: EXR file is missing")
    try:
        return OpenEXR.File(str(path), header_only=header_only)
    except Exception as exc:  # the bindings raise a bare Exception on corrupt files
        raise ExrError(f"{path}: cannot read EXR ({exc})") from exc


def read_layers(path: str | os.PathLike, names: list[str] | None = None,
                dtype=np.float32) -> dict[str, np.ndarray]:
    """Read the named layers (all when ``names`` is None) as float arrays.

    Raises :class:`ExrError` naming the file when it is missing, corrupt, or lacks a layer.
    """
    path = Path(path)
    with _open(path) as exr:
        try:
            available = {name: ch.pixels for name, ch in exr.channels().items()}
        except Exception as exc:
            raise ExrError(f"{path}: cannot decode EXR pixels ({exc})") from exc
        wanted = list(available) if names is None else list(names)
        missing = [n for n in wanted if n not in available]
        if missing:
            raise ExrError(f"{path}: missing layer(s) {missing}; file has {sorted(available)}")
        if _recorded_checksum(exr.header())[0] is not None:     # no CRC work on outside files
            _check_checksum(path, exr.header(), {n: layer_crc(p) for n, p in available.items()})
        _check_pixel_types(path, {n: np.asarray(p).dtype for n, p in available.items()})
        # asarray: a float32 layer is the decoder's own array (no copy; the layers not wanted
        # are freed with the file), so reading peaks at one copy of the file's pixels, not two
        return {n: np.asarray(available[n], dtype=dtype) for n in wanted}


def recorded_checksum(path: str | os.PathLike) -> str | None:
    """The ``mcbench.crc32`` checksum an EXR's header records (None for a file written elsewhere),
    read from the header alone: the file's content identity without decoding its pixels (the
    checksum covers its size, layer names, ``mcbench.*`` attributes and pixels). ``ExrError``
    naming the file when it is missing or not an EXR."""
    with _open(Path(path), header_only=True) as exr:
        return _recorded_checksum(exr.header())[0]


def content_checksum(path: str | os.PathLike) -> str:
    """The content identity of an EXR: ``crc32:<hex>``, its recorded checksum
    (:func:`recorded_checksum`), else ``sha256:<hex>`` of the whole file."""
    recorded = recorded_checksum(path)
    if recorded is not None:
        return f"crc32:{recorded}"
    import hashlib

    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return f"sha256:{digest.hexdigest()}"


def _recorded_checksum(header: dict) -> tuple[str | None, dict[str, str]]:
    """The checksum an EXR header records and its ``mcbench.*`` attributes (prefix kept)."""
    attributes = {str(k): v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
                  for k, v in header.items() if str(k).startswith("mcbench.")}
    return attributes.get(f"mcbench.{CHECKSUM_ATTRIBUTE}"), attributes


def _check_checksum(path: Path, header: dict, layer_crcs: dict[str, int]) -> None:
    """Refuse the EXR at ``path`` when its header records a checksum its content does not match."""
    recorded, attributes = _recorded_checksum(header)
    if recorded is None:
        return
    window = header["dataWindow"]
    if hasattr(window, "min"):                       # the scanline API's Box2i
        width, height = window.max.x - window.min.x + 1, window.max.y - window.min.y + 1
    else:                                            # the File API's pair of (x, y) arrays
        (x0, y0), (x1, y1) = window
        width, height = int(x1) - int(x0) + 1, int(y1) - int(y0) + 1
    actual = exr_checksum(width=width, height=height, layer_crcs=layer_crcs, metadata=attributes)
    if actual != recorded:
        raise ChecksumError(f"{path}: content does not match its checksum (mcbench.{CHECKSUM_ATTRIBUTE} "
                            f"{recorded}, computed {actual}): the file was damaged after it was "
                            f"written; rerun the job that writes it")


def _check_pixel_types(path: Path, dtypes: dict) -> None:
    """Refuse an EXR whose pixels are not 32-bit floats (the harness writes only those: a half or
    integer layer is another program's file, or damage)."""
    odd = sorted(name for name, dtype in dtypes.items() if np.dtype(dtype) != np.float32)
    if odd:
        raise ExrError(f"{path}: layer(s) {odd} hold {np.dtype(dtypes[odd[0]]).name} pixels; the harness "
                       f"reads 32-bit float EXRs (convert the file, or rerun the job that writes it)")


def check_resolution(path: str | os.PathLike, shape: tuple[int, ...], metadata: dict | None = None) -> None:
    """Refuse a render or reference whose pixels (``shape`` (H, W, ...)) disagree with the
    ``resolution`` (``WxH``) its header records (a cropped or resized file). Only renders and
    references record their own size there (a training crop records its scene's). ``metadata``:
    the file's :func:`read_metadata`, when the caller has it (else the header is read)."""
    recorded = (read_metadata(path) if metadata is None else metadata).get("resolution")
    if recorded and recorded != f"{shape[1]}x{shape[0]}":
        raise ExrError(f"{path}: {shape[1]}x{shape[0]} pixels, but its header records resolution {recorded}")


class _FileRows:
    """The row reader one file's :class:`LayerRows` share: a request for some rows of a layer
    reads those rows of every layer of the file requested so far in one call (an uncompressed
    scanline holds all channels, so one read of a row range costs about what one layer's does)
    and keeps the others' rows for one request each (handed out, not shared: no aliasing)."""

    def __init__(self, path: Path, channels: dict[str, list[str]], width: int, first_row: int):
        self.path, self.channels, self.width, self.first_row = path, channels, width, first_row
        self.used: dict[str, None] = {}
        self.span: tuple[int, int] | None = None
        self.pending: dict[str, np.ndarray] = {}

    def rows(self, name: str, y0: int, y1: int) -> np.ndarray:
        if self.span == (y0, y1) and name in self.pending:
            return self.pending.pop(name)
        self.used[name] = None
        names = list(self.used)
        wanted = [c for n in names for c in self.channels[n]]
        import Imath   # the scanline API's pixel types (installed with the OpenEXR bindings)

        try:
            exr = OpenEXR.InputFile(str(self.path))
            try:
                planes = exr.channels(wanted, Imath.PixelType(Imath.PixelType.FLOAT),
                                      self.first_row + y0, self.first_row + y1 - 1)
            finally:
                exr.close()
        except Exception as exc:   # the bindings raise bare exceptions on truncated files
            raise ExrError(f"{self.path}: cannot read rows {y0}:{y1} of layer(s) {names} "
                           f"({exc})") from exc
        out, k = {}, 0
        for n in names:
            block = np.empty((y1 - y0, self.width, len(self.channels[n])), np.float32)
            for j in range(block.shape[2]):
                block[..., j] = np.frombuffer(planes[k], np.float32).reshape(y1 - y0, self.width)
                k += 1
            out[n] = block
        mine = out.pop(name)
        self.span, self.pending = (y0, y1), out
        return mine


class LayerRows:
    """One layer of an EXR file, read from the file by rows when indexed: a read-only stand-in
    for the (H, W, 3) or (H, W) float32 array :func:`read_layers` would return, holding no
    pixels. ``layer[y0:y1]`` (or ``layer[y0:y1, cols...]``, ``layer[y]``) decodes only those
    scanlines (OpenEXR's scanline API, ``InputFile.channels`` over a row range: for the
    uncompressed files the harness writes that reads only their bytes) and returns a new array;
    ``np.asarray(layer)`` reads the whole layer. Values equal :func:`read_layers`'s exactly. Each
    read opens the file (cheap next to the decoding), so no handle stays open; the layers of one :func:`layer_rows`
    call share one read per row range (:class:`_FileRows`)."""

    def __init__(self, reader: _FileRows, name: str, shape: tuple[int, ...]):
        self._reader, self.name, self.path = reader, name, reader.path
        self.shape = shape
        self.dtype = np.dtype(np.float32)
        self.ndim = len(shape)

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"LayerRows({str(self.path)!r}, {self.name!r}, shape={self.shape})"

    def rows(self, y0: int, y1: int) -> np.ndarray:
        """Rows y0 .. y1 - 1 (0 <= y0 <= y1 <= H): a new (y1 - y0, W[, 3]) float32 array."""
        height = self.shape[0]
        if not 0 <= y0 <= y1 <= height:
            raise IndexError(f"{self.path}: rows {y0}:{y1} of layer '{self.name}' with {height} rows")
        if y1 == y0:
            return np.empty((0,) + self.shape[1:], np.float32)
        block = self._reader.rows(self.name, y0, y1)
        return block if self.ndim == 3 else block[..., 0]

    def __getitem__(self, key) -> np.ndarray:
        first, rest = (key[0], key[1:]) if isinstance(key, tuple) else (key, ())
        if first is Ellipsis:
            return np.asarray(self)[key]
        if isinstance(first, slice):
            start, stop, step = first.indices(self.shape[0])
            stop = max(stop, start)
            block = self.rows(start, stop) if step == 1 else self.rows(0, self.shape[0])[first]
            return block[(slice(None), *rest)] if rest else block
        y = int(first)                      # one row (numpy's negative indices included)
        y = y + self.shape[0] if y < 0 else y
        if not 0 <= y < self.shape[0]:
            raise IndexError(f"row {first} out of range for {self.shape[0]} rows")
        return self.rows(y, y + 1)[(0, *rest)]

    def __array__(self, dtype=None, copy=None):
        whole = self.rows(0, self.shape[0])
        return whole if dtype is None else whole.astype(dtype, copy=False)


def layer_rows(path: str | os.PathLike, names: list[str] | None = None, *,
               finite: bool = False) -> dict[str, LayerRows]:
    """The named layers (all when ``names`` is None) of an EXR as :class:`LayerRows`, read by
    rows when indexed; only the header is read here. A layer is the channels ``name.R``,
    ``name.G``, ``name.B`` (3-channel, as :func:`write_layers` stores it) or the single channel
    ``name``. Raises :class:`ExrError` naming the file when it is missing or corrupt, or lacks
    a layer. A file with a checksum is read through once, :data:`STREAM_ROWS` rows at a time, to
    check it (:class:`mcbench.io.checksums.ChecksumError`); with ``finite`` that pass also refuses
    NaN/Inf pixels in the layers asked for (:class:`NonFiniteError` naming the file and layer)."""
    path = Path(path)
    if not path.exists():
        raise ExrError(f"{path}: EXR file is missing")
    try:
        exr = OpenEXR.InputFile(str(path))
        try:
            header = exr.header()
        finally:
            exr.close()
        window = header["dataWindow"]
        x0, y0, x1, y1 = window.min.x, window.min.y, window.max.x, window.max.y
        present = set(header["channels"])
    except Exception as exc:
        raise ExrError(f"{path}: cannot read EXR ({exc})") from exc
    shape = (y1 - y0 + 1, x1 - x0 + 1)
    layers: dict[str, list[str]] = {}
    for channel in sorted(present):
        stem, _, last = channel.rpartition(".")
        if stem and last in ("R", "G", "B") and all(f"{stem}.{c}" in present for c in "RGB"):
            layers[stem] = [f"{stem}.{c}" for c in "RGB"]
        elif not (stem and last in ("R", "G", "B", "A")):
            layers[channel] = [channel]
    wanted = list(layers) if names is None else list(names)
    missing = [n for n in wanted if n not in layers]
    if missing:
        raise ExrError(f"{path}: missing layer(s) {missing}; file has {sorted(layers)}")
    # Imath.PixelType values: 0 UINT, 1 HALF, 2 FLOAT; a layer takes the type of its first non-float channel
    numpy_type = {0: np.uint32, 1: np.float16, 2: np.float32}
    channel_type = {c: numpy_type.get(getattr(info.type, "v", 2), np.float64) for c, info in header["channels"].items()}
    _check_pixel_types(path, {n: next((channel_type[c] for c in chans if channel_type[c] != np.float32), np.float32)
                              for n, chans in layers.items()})
    recorded = _recorded_checksum(header)[0] is not None
    if recorded or finite:
        crcs, bad = _streamed_layer_crcs(path, layers, shape, y0)
        if recorded:
            _check_checksum(path, header, crcs)
        if finite and any(bad[n] for n in wanted):
            raise NonFiniteError(f"{path}: " + "; ".join(f"layer '{n}' has {bad[n]} pixel(s) with NaN/Inf"
                                                         for n in wanted if bad[n]))
    reader = _FileRows(path, {n: layers[n] for n in wanted}, shape[1], y0)
    return {n: LayerRows(reader, n, shape + ((3,) if len(layers[n]) == 3 else ()))
            for n in wanted}


STREAM_ROWS = 64  # rows per read when a file is checked by rows (bounded memory at any size)


def _streamed_layer_crcs(path: Path, layers: dict[str, list[str]], shape: tuple[int, int],
                         first_row: int) -> tuple[dict[str, int], dict[str, int]]:
    """Each layer's pixel CRC (:func:`mcbench.io.checksums.layer_crc`) of the whole file and its
    count of pixels with a NaN/Inf, read :data:`STREAM_ROWS` rows at a time, so that a file read by
    rows is checked without holding it."""
    reader = _FileRows(path, layers, shape[1], first_row)
    crcs, bad = dict.fromkeys(layers, 0), dict.fromkeys(layers, 0)
    for y0 in range(0, shape[0], STREAM_ROWS):
        y1 = min(shape[0], y0 + STREAM_ROWS)
        for name in layers:
            block = reader.rows(name, y0, y1)
            crcs[name] = layer_crc(block if len(layers[name]) == 3 else block[..., 0], crcs[name])
            bad[name] += int((~np.isfinite(block)).any(axis=2).sum())
    return crcs, bad


def read_metadata(path: str | os.PathLike) -> dict[str, str]:
    """Return the ``mcbench.*`` header attributes of an EXR (prefix stripped), its checksum
    excepted. Reads the header only, so it checks no checksum: read the layers for that."""
    path = Path(path)
    with _open(path, header_only=True) as exr:      # the pixels are not decoded
        return {k[len("mcbench."):]: str(v) for k, v in exr.header().items()
                if k.startswith("mcbench.") and k != f"mcbench.{CHECKSUM_ATTRIBUTE}"}


def recorded_spp(metadata: dict[str, str]) -> int | None:
    """The samples per pixel a header's metadata (:func:`read_metadata`) records as ``spp``: a
    positive integer, or None when it records none."""
    value = str(metadata.get("spp", ""))
    return int(value) if value.isdigit() and int(value) > 0 else None


def check_finite(path: str | os.PathLike, layers: dict[str, np.ndarray]) -> None:
    """Raise :class:`NonFiniteError` naming ``path``, the layer and the count of bad pixels."""
    problems = []
    for name, array in layers.items():
        bad = ~np.isfinite(array)
        if bad.any():
            per_pixel = bad.reshape(bad.shape[0], bad.shape[1], -1).any(axis=2)
            problems.append(f"layer '{name}' has {int(per_pixel.sum())} pixel(s) with NaN/Inf")
    if problems:
        raise NonFiniteError(f"{path}: " + "; ".join(problems))
