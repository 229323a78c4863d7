"""Training crops (from :mod:`mcbench.training_data`) as arrays, the train/validation split and
seeded, augmented batches.

A crop file ``example_<seed>_<k>.exr`` holds, for every noisy level N, the layers
``<layer>_spp<N>`` of the full buffer and of the half buffers A and B, plus ``target`` (the
high-spp mean). Every (crop, level, buffer) is one training input: the half buffers are
independent renders at N/2 spp of the same crop, so one level gives inputs at N and N/2 spp,
exactly what the denoisers see at test time (full image and halves).

Storage: a :class:`CropSet` keeps every image plane it uses (one channel of one layer of one
file) once, losslessly compressed, in a temporary file (:class:`PlaneStore`), and an item is a
table of plane numbers: its input channels per level and buffer, and its target. A combiner's
items (one per crop and base) share their crop's render planes and differ only in the base's; a
subset or a split shares the planes of the set it comes from. Batches read and decompress the
planes they draw from (a dense ``(items, L, 3, C, H, W)`` copy, which :attr:`CropSet.inputs`
builds for inspection, is never made in training), bit-identical to the dense layout's: the
crops live on disk and in the page cache, not in the training process's memory
(``benchmarks/training_memory.py`` measures the peak).

Split: training scenes with ``seed % VALIDATION_MODULUS == VALIDATION_REMAINDER`` (every 8th)
are the validation set; all crops of a scene go to the same side.

Combiners (the deep combiner, Back et al. 2020) also need a base denoiser's result on each
training input: :func:`load_combiner_crops` reads the crops together with the base outputs written
by :func:`mcbench.pipeline.training.write_correlated_training_inputs` (``correlated/<base>/example_<seed>_<k>.exr``,
layers ``correlated<half>_spp<N>`` and, for bases that expose a kernel, ``correlated<half>_sub<j>_spp<N>``),
one item per (crop, base), with the extra input keys the combiner declares (``training_keys``):
render layers by name (e.g. ``albedo_variance``), ``correlated`` (the base's result on that image),
``color_sub``/``variance_sub`` (the image's two sample subsets, :data:`mcbench.io.buffers.SUB_BUFFERS`,
concatenated), ``correlated_sub`` (the base's result on each) and ``divergence`` (layers
``divergence<half>_spp<N>``: the base's SURE divergence term, written for a base named
``<base>+sure``, :func:`mcbench.pipeline.training.write_correlated_training_inputs`).

Batches: step ``s`` of a run seeded ``seed`` draws from ``numpy.random.default_rng([seed, s])``
item, level, buffer, patch position and one of the 8 rotations/flips of the square patch, so a
resumed run sees exactly the batches an uninterrupted one would. Normals and depth are not
rotated with the image (world-space normals bear no fixed relation to screen axes anyway).
"""

from __future__ import annotations

import os
import re
import tempfile
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from mcbench import BenchError
from mcbench.io.exr import check_finite, read_layers, read_metadata

# Raw buffers a network receives: name -> channels (layout of the (13, H, W) input arrays).
BUFFER_KEYS = {"color": 3, "variance": 3, "albedo": 3, "normal": 3, "depth": 1}
HALVES = ("", "_a", "_b")   # full, A, B
HALF_OF = {"": "full", "_a": "a", "_b": "b"}
VALIDATION_MODULUS = 8
VALIDATION_REMAINDER = 7
_EXAMPLE = re.compile(r"example_(\d+)_(\d+)\.exr$")


def is_validation_seed(seed: int) -> bool:
    """Whether training scene ``seed`` belongs to the validation set."""
    return int(seed) % VALIDATION_MODULUS == VALIDATION_REMAINDER


@dataclass
class CropSet:
    """Training items as plane numbers into shared image planes.

    planes       :class:`PlaneStore` of P (H, W) float32 planes -- every image plane the items
                 use (one channel of one layer of a crop file or of a base's result file), once
    index        (n, L, 3, C) int -- per item, level and buffer (full, A, B) the planes of its
                 input channels in ``keys`` order (C = sum of their channels; 13 for
                 :data:`BUFFER_KEYS`)
    target_index (n, 3) int -- the planes of each item's high-spp reference radiance
    pairs        (n, 2) int -- each item's (crop, base): the crop's position in the files read and
                 the base's in ``info["bases"]`` (-1: no base, a denoiser's data)
    spp          (L, 3) float -- samples behind each level's full, A and B buffer
    seeds        (n,) int -- training scene seed of each item
    info         render settings of the crops (resolution, target spp, crop size, crops per
                 scene, variant), from their metadata
    """

    planes: "PlaneStore"
    index: np.ndarray
    target_index: np.ndarray
    pairs: np.ndarray
    spp: np.ndarray
    seeds: np.ndarray
    info: dict = field(default_factory=dict)
    keys: dict = field(default_factory=lambda: dict(BUFFER_KEYS))   # input name -> channels

    def __len__(self) -> int:
        return len(self.index)

    @property
    def shape(self) -> tuple[int, int, int, int, int, int]:
        """(items, levels, buffers, channels, height, width) of the dense layout :attr:`inputs`."""
        return (*self.index.shape, *self.planes.shape[1:])

    @property
    def inputs(self) -> np.ndarray:
        """Dense copy (n, L, 3, C, H, W) float32 of every item's inputs -- for inspection and tests:
        it holds each shared plane once per item (training gathers from :attr:`planes`)."""
        return self.planes.take(self.index)

    @property
    def targets(self) -> np.ndarray:
        """Dense copy (n, 3, H, W) float32 of every item's target radiance."""
        return self.planes.take(self.target_index)

    def subset(self, mask: np.ndarray) -> "CropSet":
        """The items selected by ``mask`` (boolean (n,) or item numbers); shares the planes."""
        return CropSet(self.planes, self.index[mask], self.target_index[mask], self.pairs[mask], self.spp,
                       self.seeds[mask], self.info, self.keys)

    def split(self) -> tuple["CropSet", "CropSet"]:
        """(training, validation) by scene seed."""
        validation = np.array([is_validation_seed(s) for s in self.seeds], dtype=bool)
        return self.subset(~validation), self.subset(validation)

    @classmethod
    def from_layers(cls, crops: list[tuple[dict, dict]], source: str = "<memory>") -> "CropSet":
        """Build from ``(layers, metadata)`` pairs as :func:`mcbench.training_data.training_example` returns."""
        if not crops:
            raise BenchError(f"{source}: no training crops")
        return assemble_items(((layers, meta, source, {}) for layers, meta in crops), crop_count=len(crops),
                              bases=[], keys=BUFFER_KEYS)


def crop_paths(folder: str | Path) -> list[Path]:
    """Training crop files in ``folder``, ordered by (seed, crop)."""
    paths = [p for p in Path(folder).glob("example_*.exr") if _EXAMPLE.search(p.name)]
    return sorted(paths, key=lambda p: tuple(int(v) for v in _EXAMPLE.search(p.name).groups()))


def load_crops(paths: list[str | Path]) -> CropSet:
    """Read training crop EXRs (errors name the file: missing, corrupt, NaN/Inf, wrong layers)."""
    if not paths:
        raise BenchError("no training crops given: run `snakemake --cores 2 training_data` first")
    return assemble_items(read_crop_files(list(paths), {}), crop_count=len(paths), bases=[], keys=BUFFER_KEYS,
                          folder=Path(paths[0]).parent)


def to_buffers(inputs: np.ndarray | torch.Tensor, keys: dict | None = None) -> dict[str, torch.Tensor]:
    """(B, C, H, W) input array -> dict of (B, c, H, W) float32 tensors by ``keys`` (name ->
    channels, in order; default :data:`BUFFER_KEYS`)."""
    tensor = torch.as_tensor(np.ascontiguousarray(inputs), dtype=torch.float32)
    out, start = {}, 0
    for key, channels in (keys or BUFFER_KEYS).items():
        out[key] = tensor[:, start:start + channels]
        start += channels
    return out


def dihedral(array: np.ndarray, transform: int) -> np.ndarray:
    """One of the 8 rotations/flips (``transform`` in 0..7) of the last two axes of ``array``."""
    out = np.rot90(array, k=transform % 4, axes=(-2, -1))
    if transform >= 4:
        out = out[..., ::-1]
    return out


def sample_batch(crops: CropSet, seed: int, step: int, batch_size: int, patch: int
                 ) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """Batch ``step`` of a run seeded ``seed``: raw buffers (dict of (B, C, P, P)) and targets (B, 3, P, P)."""
    n, levels, buffers, channels, height, width = crops.shape
    if patch > min(height, width):
        raise BenchError(f"training patch {patch} is larger than the {width}x{height} crops")
    rng = np.random.default_rng([int(seed), int(step)])
    inputs = np.empty((batch_size, channels, patch, patch), dtype=np.float32)
    targets = np.empty((batch_size, 3, patch, patch), dtype=np.float32)
    for i in range(batch_size):
        c, l, b = rng.integers(n), rng.integers(levels), rng.integers(buffers)
        y, x = rng.integers(height - patch + 1), rng.integers(width - patch + 1)
        transform = int(rng.integers(8))
        inputs[i] = dihedral(crops.planes.take(crops.index[c, l, b])[:, y:y + patch, x:x + patch], transform)
        targets[i] = dihedral(crops.planes.take(crops.target_index[c])[:, y:y + patch, x:x + patch], transform)
    return to_buffers(inputs, crops.keys), torch.from_numpy(targets)


def validation_batches(crops: CropSet, batch_size: int = 16, buffer: int = 0):
    """Every (item, level) of ``crops`` for one buffer (0 full, 1 A, 2 B), in a fixed order.

    Yields ``(buffers, targets, seeds, spp)`` with the scene seed and spp of each item.
    """
    n, levels = crops.shape[:2]
    items = np.array([(c, l) for c in range(n) for l in range(levels)], dtype=np.int64).reshape(-1, 2)
    for start in range(0, len(items), batch_size):
        item, level = items[start:start + batch_size].T
        inputs = crops.planes.take(crops.index[item, level, buffer])     # (B, C, H, W)
        targets = crops.planes.take(crops.target_index[item])            # (B, 3, H, W)
        yield to_buffers(inputs, crops.keys), torch.from_numpy(targets), crops.seeds[item], crops.spp[level, buffer]


# --------------------------------------------------------------------------- loading

def input_layers(key: str, half: str, level: int) -> tuple[str, list[str]]:
    """Where input ``key`` of one (level, buffer ``half`` in :data:`HALVES`) comes from:
    ``("crop" | "correlated", layer names)``, the layers' channels concatenated in that order."""
    from mcbench.io.buffers import SUB_BUFFERS

    if key == "correlated":
        return "correlated", [f"correlated{half}_spp{level}"]
    if key == "divergence":        # the base's SURE divergence term σ²f′ (progressive denoising, Eq. 2)
        return "correlated", [f"divergence{half}_spp{level}"]
    if key == "correlated_sub":
        return "correlated", [f"correlated{half}_sub{j}_spp{level}" for j in (0, 1)]
    if key in ("color_sub", "variance_sub"):
        quantity = key[:-len("_sub")]
        return "crop", [f"{quantity}{sub}_spp{level}" for sub in SUB_BUFFERS[HALF_OF[half]]]
    return "crop", [f"{key}{half}_spp{level}"]


def _channels_first(array: np.ndarray) -> np.ndarray:
    return array[None] if array.ndim == 2 else np.moveaxis(array, 2, 0)


class PlaneStore:
    """Image planes (H, W) float32, each zlib-compressed (lossless: the bytes come back exactly;
    about half the size of the raw float32 of rendered crops, a sixth for normals) into an
    unnamed temporary file in ``folder`` (the crops' own, on disk; else or when not writable the
    system's temporary folder), read back on demand: the planes take disk and reclaimable page
    cache, not the process's memory, for a read per plane gathered (microseconds from the cache).
    Every file of one kind must give each layer name the same channels and size. The file goes
    with the store (or the process, however it ends)."""

    def __init__(self, height: int, width: int, *, folder: str | Path | None = None):
        self.height, self.width = int(height), int(width)
        self.file, problem = None, None
        for candidate in dict.fromkeys([str(folder) if folder is not None else None, tempfile.gettempdir()]):
            try:
                self.file = tempfile.TemporaryFile(prefix=".mcbench-planes-", dir=candidate, buffering=0)
                self.folder = candidate
                break
            except OSError as exc:
                problem = exc
        if self.file is None:
            raise BenchError(f"cannot create the training planes' temporary file in {folder} or "
                             f"{tempfile.gettempdir()}: {problem}")
        self.spans: list[tuple[int, int]] = []          # per plane: (start, stop) in the file
        self.channels: dict[str, int] = {}
        self.nbytes = 0                                 # bytes in the file

    def __len__(self) -> int:
        return len(self.spans)

    @property
    def shape(self) -> tuple[int, int, int]:
        return len(self.spans), self.height, self.width

    def add(self, layers: dict[str, np.ndarray], names: list[str], source: str) -> dict[str, np.ndarray]:
        """Store layers ``names`` of one file; returns {name: its plane numbers}."""
        arrays = {name: np.asarray(_channels_first(layers[name]), dtype=np.float32) for name in names}
        for name, array in arrays.items():
            depth = self.channels.get(name, array.shape[0])
            if array.shape != (depth, self.height, self.width):
                raise BenchError(f"{source}: layer '{name}' is {array.shape[0]} channel(s) of "
                                 f"{array.shape[2]}x{array.shape[1]} pixels, the first file's "
                                 f"{depth} of {self.width}x{self.height}")
        pieces = [zlib.compress(np.ascontiguousarray(channel).tobytes(), 1)
                  for array in arrays.values() for channel in array]
        block = b"".join(pieces)
        try:
            written = 0
            while written < len(block):
                written += os.pwrite(self.file.fileno(), block[written:], self.nbytes + written)
        except OSError as exc:
            raise BenchError(f"{source}: cannot store its planes in a temporary file in {self.folder}: {exc}") from exc
        numbers, first, offset = {}, len(self.spans), self.nbytes
        for name, array in arrays.items():
            self.channels.setdefault(name, array.shape[0])
            numbers[name] = np.arange(first, first + len(array))
            first += len(array)
        for piece in pieces:
            self.spans.append((offset, offset + len(piece)))
            offset += len(piece)
        self.nbytes = offset
        return numbers

    def take(self, numbers: np.ndarray) -> np.ndarray:
        """The planes ``numbers`` (any shape S of plane numbers) as a new (*S, H, W) float32 array."""
        numbers = np.asarray(numbers)
        out = np.empty((numbers.size, self.height, self.width), dtype=np.float32)
        size = self.height * self.width * 4
        for i, number in enumerate(numbers.ravel()):
            start, stop = self.spans[number]
            out[i] = np.frombuffer(zlib.decompress(os.pread(self.file.fileno(), stop - start, start), bufsize=size),
                                   dtype=np.float32).reshape(self.height, self.width)
        return out.reshape(*numbers.shape, self.height, self.width)


def _spp_levels(meta: dict) -> list[int]:
    return [int(v) for v in str(meta.get("spp_levels", "")).split(",") if v]


def _layout(keys: dict, levels: list[int]) -> list[list[list[tuple[str, str, list[str]]]]]:
    """[level][buffer] -> [(key, file kind, layer names)] for every input key, in ``keys`` order."""
    return [[[(key, *input_layers(key, half, level)) for key in keys] for half in HALVES] for level in levels]


def _names_of(layout, kind: str) -> list[str]:
    """Distinct layer names of file kind ``kind`` in ``layout``, in first-use order."""
    names = [name for level in layout for buffer in level for _, k, names in buffer if k == kind for name in names]
    return list(dict.fromkeys(names))


def _check_layers(layers: dict, layout, kind: str, source: str) -> list[str]:
    """The layer names of kind ``kind`` that ``layout`` needs, checked present (errors name the
    input key) and finite."""
    for level in layout:
        for buffer in level:
            for key, k, names in buffer:
                missing = [name for name in names if k == kind and name not in layers]
                if missing:
                    raise BenchError(f"{source}: lacks layer(s) {missing} needed for input '{key}'")
    names = _names_of(layout, kind)
    if kind == "crop":
        if "target" not in layers:
            raise BenchError(f"{source}: training crop lacks layer 'target'")
        names.append("target")
    check_finite(source, {name: layers[name] for name in names})
    return names


def read_crop_files(crop_files: list[str | Path], correlated_files: dict[str, list[str | Path]]
                    ) -> Iterator[tuple[dict, dict, str, dict[str, tuple[dict, dict, str]]]]:
    """Per crop file, read one at a time: ``(layers, metadata, path, {base: (layers, metadata,
    path)})`` of it and of each base's result on it (``correlated_files[base][i]`` for
    ``crop_files[i]``)."""
    for i, crop_path in enumerate(crop_files):
        meta = read_metadata(crop_path)
        if "spp_levels" not in meta or "seed" not in meta:
            raise BenchError(f"{crop_path}: not a training crop (no spp_levels/seed metadata)")
        correlated = {base: (read_layers(files[i]), read_metadata(files[i]), str(files[i]))
                      for base, files in correlated_files.items()}
        yield read_layers(crop_path), meta, str(crop_path), correlated


def assemble_items(crops: Iterable[tuple[dict, dict, str, dict[str, tuple[dict, dict, str]]]], *,
                   crop_count: int, bases: list[str], keys: dict[str, int], folder: str | Path | None = None
                   ) -> CropSet:
    """A :class:`CropSet` of ``crop_count`` crops given as :func:`read_crop_files` yields them:
    one item per crop (no ``bases``) or per (base, crop), base by base, each crop's and each
    base result's planes stored once (a :class:`PlaneStore` in ``folder``). ``keys``: {input
    name: channels}."""
    store, levels, layout, first = None, None, None, None
    crop_planes, base_planes, seeds = [], {base: [] for base in bases}, []
    for layers, meta, source, correlated in crops:
        crop_levels = _spp_levels(meta)
        if levels is None:
            levels, layout, first = crop_levels, _layout(keys, crop_levels), meta
            if _names_of(layout, "correlated") and not bases:
                raise BenchError(f"{source}: inputs {list(keys)} need a base's results")
        elif crop_levels != levels:
            raise BenchError(f"{source}: crops have different spp levels ({levels} vs {crop_levels}); "
                             f"render the training data with one setting")
        elif meta.get("features", "first_hit") != first.get("features", "first_hit"):
            raise BenchError(f"{source}: crop features '{meta.get('features', 'first_hit')}' differ from the "
                             f"first crop's '{first.get('features', 'first_hit')}'; render the training data "
                             f"under one feature convention")
        crop_names = _check_layers(layers, layout, "crop", source)
        base_names = {}
        for base in bases:
            base_layers, base_meta, base_source = correlated[base]
            if _spp_levels(base_meta) != levels:
                raise BenchError(f"{base_source}: spp levels {base_meta.get('spp_levels')} differ from the "
                                 f"crops' {levels}")
            base_names[base] = _check_layers(base_layers, layout, "correlated", base_source)
        if store is None:
            store = PlaneStore(*layers["target"].shape[:2], folder=folder)
        crop_planes.append(store.add(layers, crop_names, source))
        for base in bases:
            base_planes[base].append(store.add(correlated[base][0], base_names[base], correlated[base][2]))
        seeds.append(int(meta["seed"]))
    if len(seeds) != crop_count:
        raise BenchError(f"{len(seeds)} training crops read of {crop_count}")

    groups = list(enumerate(bases)) or [(-1, None)]
    rows, pairs = [], []
    for number, base in groups:
        for crop, planes in enumerate(crop_planes):
            source = {"crop": planes, "correlated": base_planes[base][crop] if base is not None else {}}
            rows.append([[np.concatenate([source[kind][name] for _, kind, names in buffer for name in names])
                          for buffer in level] for level in layout] + [planes["target"]])
            pairs.append((crop, number))
    index = np.array([row[:-1] for row in rows], dtype=np.int64)
    target_index = np.array([row[-1] for row in rows], dtype=np.int64)
    spp = np.array([[level, level / 2, level / 2] for level in levels], dtype=np.float64)
    info = {"spp_levels": levels, "crop_size": store.width,
            "crops_per_scene": max(seeds.count(s) for s in seeds),
            **{key: str(first[key]) for key in ("resolution", "target_spp", "variant", "mitsuba") if key in first},
            # crops rendered before the key existed have first-hit features
            "features": str(first.get("features", "first_hit"))}
    return CropSet(store, index, target_index, np.array(pairs, dtype=np.int64).reshape(-1, 2), spp,
                   np.array([seeds[crop] for crop, _ in pairs]), info, dict(keys))


# --------------------------------------------------------------------------- combiners

def crop_render_layers(layers: dict[str, np.ndarray], level: int) -> dict[str, np.ndarray]:
    """The render layers of one noisy level of a training crop (names without ``_spp<N>``): every
    layer of :data:`mcbench.io.buffers.ALL_LAYERS` and, when present, the sample bins."""
    from mcbench.io.buffers import ALL_LAYERS, BIN_LAYERS

    suffix = f"_spp{level}"
    out = {name: layers[name + suffix] for name in ALL_LAYERS if name + suffix in layers}
    out.update({name: layers[name + suffix] for name in BIN_LAYERS if name + suffix in layers})
    return out


def correlated_layer_names(level: int, *, sub_buffers: bool) -> list[str]:
    """Layer names of a base's results in a correlated-inputs file for one level."""
    names = [f"correlated{half}_spp{level}" for half in HALVES]
    if sub_buffers:
        names += [f"correlated{half}_sub{j}_spp{level}" for half in HALVES for j in (0, 1)]
    return names


def load_combiner_crops(crop_files: list[str | Path], correlated_files: dict[str, list[str | Path]],
                        keys: dict[str, int]) -> CropSet:
    """Training items of a combiner: each crop once per base of ``correlated_files`` ({base:
    files}, ``files[i]`` the base's results on ``crop_files[i]``), base by base, with the inputs
    ``keys`` ({name: channels}: :data:`BUFFER_KEYS` first, then the combiner's ``training_keys``).
    Items of one crop share its scene seed, so the train/validation split keeps every base of a
    scene on one side, and its render planes (only the base's planes are per item). Errors name
    the file (missing, corrupt, NaN/Inf, missing layers, other levels)."""
    if not crop_files:
        raise BenchError("no training crops given: run `snakemake --cores 2 training_data` first")
    if not correlated_files:
        raise BenchError("no base results given for the combiner's training")
    keys = {**BUFFER_KEYS, **{k: v for k, v in keys.items() if k not in BUFFER_KEYS}}
    for base, files in correlated_files.items():
        if len(files) != len(crop_files):
            raise BenchError(f"{len(files)} result files of base '{base}' for {len(crop_files)} crops")
    crops = assemble_items(read_crop_files(list(crop_files), correlated_files), crop_count=len(crop_files),
                           bases=list(correlated_files), keys=keys, folder=Path(crop_files[0]).parent)
    crops.info.update(bases=list(correlated_files), folder=str(Path(crop_files[0]).parent))
    return crops
