"""Training crops (from :mod:`mcbench.training_data`) as arrays, the train/validation split and
seeded, augmented batches.

A crop file ``example_<seed>_<k>.exr`` holds, for every noisy level N, the layers
``<layer>_spp<N>`` of the full buffer and of the half buffers A and B, plus ``target`` (the
high-spp mean). Every (crop, level, buffer) is one training input: the half buffers are
independent renders at N/2 spp of the same crop, so one level gives inputs at N and N/2 spp,
exactly what the denoisers see at test time (full image and halves).

Split: training scenes with ``seed % VALIDATION_MODULUS == VALIDATION_REMAINDER`` (every 8th)
are the validation set; all crops of a scene go to the same side.

Combiners (the deep combiner, Back et al. 2020) also need a base denoiser's result on each
training input: :func:`load_combiner_crops` reads the crops together with the base outputs written
by :func:`mcbench.steps.write_correlated_training_inputs` (``correlated/<base>/example_<seed>_<k>.exr``,
layers ``correlated<half>_spp<N>`` and, for bases that expose a kernel, ``correlated<half>_sub<j>_spp<N>``),
one item per (crop, base), with the extra input keys the combiner declares (``TRAINING_KEYS``):
render layers by name (e.g. ``albedo_variance``), ``correlated`` (the base's result on that image),
``color_sub``/``variance_sub`` (the image's two sample subsets, :data:`mcbench.buffers.SUB_BUFFERS`,
concatenated) and ``correlated_sub`` (the base's result on each).

Batches: step ``s`` of a run seeded ``seed`` draws from ``numpy.random.default_rng([seed, s])``
crop, level, buffer, patch position and one of the 8 rotations/flips of the square patch, so a
resumed run sees exactly the batches an uninterrupted one would. Normals and depth are not
rotated with the image (world-space normals bear no fixed relation to screen axes anyway).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from mcbench import BenchError
from mcbench.exr import check_finite, read_layers, read_metadata

# Raw buffers a network receives: name -> channels (layout of the (13, H, W) input arrays).
BUFFER_KEYS = {"color": 3, "variance": 3, "albedo": 3, "normal": 3, "depth": 1}
HALVES = ("", "_a", "_b")   # full, A, B
VALIDATION_MODULUS = 8
VALIDATION_REMAINDER = 7
_EXAMPLE = re.compile(r"example_(\d+)_(\d+)\.exr$")


def is_validation_seed(seed: int) -> bool:
    """Whether training scene ``seed`` belongs to the validation set."""
    return int(seed) % VALIDATION_MODULUS == VALIDATION_REMAINDER


@dataclass
class CropSet:
    """Crops as arrays.

    inputs  (n, L, 3, C, H, W) float32 -- per crop, level and buffer (full, A, B) the raw
            buffers in ``keys`` order (C = sum of their channels; 13 for :data:`BUFFER_KEYS`)
    targets (n, 3, H, W) float32 -- high-spp reference radiance
    spp     (L, 3) float -- samples behind each level's full, A and B buffer
    seeds   (n,) int -- training scene seed of each crop
    info    render settings of the crops (resolution, target spp, crop size, crops per scene,
            variant), from their metadata
    """

    inputs: np.ndarray
    targets: np.ndarray
    spp: np.ndarray
    seeds: np.ndarray
    info: dict = field(default_factory=dict)
    keys: dict = field(default_factory=lambda: dict(BUFFER_KEYS))   # input name -> channels

    def __len__(self) -> int:
        return len(self.targets)

    def subset(self, mask: np.ndarray) -> "CropSet":
        return CropSet(self.inputs[mask], self.targets[mask], self.spp, self.seeds[mask], self.info, self.keys)

    def split(self) -> tuple["CropSet", "CropSet"]:
        """(training, validation) by scene seed."""
        validation = np.array([is_validation_seed(s) for s in self.seeds], dtype=bool)
        return self.subset(~validation), self.subset(validation)

    @classmethod
    def from_layers(cls, crops: list[tuple[dict, dict]], source: str = "<memory>") -> "CropSet":
        """Build from ``(layers, metadata)`` pairs as :func:`mcbench.training_data.training_example` returns."""
        if not crops:
            raise BenchError(f"{source}: no training crops")
        levels = None
        inputs, targets, seeds = [], [], []
        for layers, meta in crops:
            crop_levels = [int(v) for v in str(meta["spp_levels"]).split(",")]
            if levels is None:
                levels = crop_levels
            elif crop_levels != levels:
                raise BenchError(f"{source}: crops have different spp levels ({levels} vs {crop_levels}); "
                                 f"render the training data with one setting")
            per_level = []
            for level in levels:
                per_buffer = []
                for half in HALVES:
                    channels = []
                    for key in BUFFER_KEYS:
                        name = f"{key}{half}_spp{level}"
                        if name not in layers:
                            raise BenchError(f"{source}: training crop lacks layer '{name}'")
                        array = layers[name]
                        channels.append(array[None] if array.ndim == 2 else np.moveaxis(array, 2, 0))
                    per_buffer.append(np.concatenate(channels, axis=0))
                per_level.append(np.stack(per_buffer))
            inputs.append(np.stack(per_level))
            targets.append(np.moveaxis(layers["target"], 2, 0))
            seeds.append(int(meta["seed"]))
        spp = np.array([[level, level / 2, level / 2] for level in levels], dtype=np.float64)
        first = crops[0][1]
        info = {"spp_levels": levels, "crop_size": int(targets[0].shape[-1]),
                "crops_per_scene": max(seeds.count(s) for s in seeds),
                **{key: str(first[key]) for key in ("resolution", "target_spp", "variant", "mitsuba")
                   if key in first}}
        return cls(np.ascontiguousarray(np.stack(inputs), dtype=np.float32),
                   np.ascontiguousarray(np.stack(targets), dtype=np.float32), spp, np.array(seeds), info)


def crop_paths(folder: str | Path) -> list[Path]:
    """Training crop files in ``folder``, ordered by (seed, crop)."""
    paths = [p for p in Path(folder).glob("example_*.exr") if _EXAMPLE.search(p.name)]
    return sorted(paths, key=lambda p: tuple(int(v) for v in _EXAMPLE.search(p.name).groups()))


def load_crops(paths: list[str | Path]) -> CropSet:
    """Read training crop EXRs (errors name the file: missing, corrupt, NaN/Inf, wrong layers)."""
    if not paths:
        raise BenchError("no training crops given: run `snakemake --cores 2 training_data` first")
    crops = []
    for path in paths:
        meta = read_metadata(path)
        if "spp_levels" not in meta or "seed" not in meta:
            raise BenchError(f"{path}: not a training crop (no spp_levels/seed metadata)")
        levels = [int(v) for v in meta["spp_levels"].split(",")]
        names = [f"{key}{half}_spp{level}" for level in levels for half in HALVES for key in BUFFER_KEYS]
        layers = read_layers(path, names + ["target"])
        check_finite(path, layers)
        crops.append((layers, meta))
    return CropSet.from_layers(crops, source=str(Path(paths[0]).parent))


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
    n, levels, buffers, channels, height, width = crops.inputs.shape
    if patch > min(height, width):
        raise BenchError(f"training patch {patch} is larger than the {width}x{height} crops")
    rng = np.random.default_rng([int(seed), int(step)])
    inputs = np.empty((batch_size, channels, patch, patch), dtype=np.float32)
    targets = np.empty((batch_size, 3, patch, patch), dtype=np.float32)
    for i in range(batch_size):
        c, l, b = rng.integers(n), rng.integers(levels), rng.integers(buffers)
        y, x = rng.integers(height - patch + 1), rng.integers(width - patch + 1)
        transform = int(rng.integers(8))
        inputs[i] = dihedral(crops.inputs[c, l, b, :, y:y + patch, x:x + patch], transform)
        targets[i] = dihedral(crops.targets[c, :, y:y + patch, x:x + patch], transform)
    return to_buffers(inputs, crops.keys), torch.from_numpy(targets)


def validation_batches(crops: CropSet, batch_size: int = 16, buffer: int = 0):
    """Every (crop, level) of ``crops`` for one buffer (0 full, 1 A, 2 B), in a fixed order.

    Yields ``(buffers, targets, seeds, spp)`` with the scene seed and spp of each item.
    """
    n, levels = crops.inputs.shape[:2]
    items = [(c, l) for c in range(n) for l in range(levels)]
    for start in range(0, len(items), batch_size):
        chunk = items[start:start + batch_size]
        inputs = np.stack([crops.inputs[c, l, buffer] for c, l in chunk])
        targets = np.stack([crops.targets[c] for c, _ in chunk])
        yield (to_buffers(inputs, crops.keys), torch.from_numpy(targets), np.array([crops.seeds[c] for c, _ in chunk]),
               np.array([crops.spp[l, buffer] for _, l in chunk]))


# --------------------------------------------------------------------------- combiners

HALF_OF = {"": "full", "_a": "a", "_b": "b"}


def crop_render_layers(layers: dict[str, np.ndarray], level: int) -> dict[str, np.ndarray]:
    """The render layers of one noisy level of a training crop (names without ``_spp<N>``): every
    layer of :data:`mcbench.buffers.ALL_LAYERS` and, when present, the sample bins."""
    from mcbench.buffers import ALL_LAYERS, BIN_LAYERS

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


def _channels_first(array: np.ndarray) -> np.ndarray:
    return array[None] if array.ndim == 2 else np.moveaxis(array, 2, 0)


def _combiner_input(key: str, half: str, level: int, crop: dict, correlated: dict, source: str) -> np.ndarray:
    """One input key of a combiner for one (level, buffer) of a crop, channels first."""
    from mcbench.buffers import SUB_BUFFERS

    subs = SUB_BUFFERS[HALF_OF[half]]
    if key == "correlated":
        names, layers = [f"correlated{half}_spp{level}"], correlated
    elif key == "correlated_sub":
        names, layers = [f"correlated{half}_sub{j}_spp{level}" for j in (0, 1)], correlated
    elif key in ("color_sub", "variance_sub"):
        quantity = key[:-len("_sub")]
        names, layers = [f"{quantity}{sub}_spp{level}" for sub in subs], crop
    else:
        names, layers = [f"{key}{half}_spp{level}"], crop
    missing = [name for name in names if name not in layers]
    if missing:
        raise BenchError(f"{source}: lacks layer(s) {missing} needed for input '{key}'")
    return np.concatenate([_channels_first(layers[name]) for name in names], axis=0)


def load_combiner_crops(crop_files: list[str | Path], correlated_files: dict[str, list[str | Path]],
                        keys: dict[str, int]) -> CropSet:
    """Training items of a combiner: each crop once per base of ``correlated_files`` ({base:
    files}, ``files[i]`` the base's results on ``crop_files[i]``), with the inputs ``keys`` ({name:
    channels}: :data:`BUFFER_KEYS` first, then the combiner's ``TRAINING_KEYS``). Items of one
    crop share its scene seed, so the train/validation split keeps every base of a scene on one
    side. Errors name the file (missing, corrupt, NaN/Inf, missing layers, other levels)."""
    if not crop_files:
        raise BenchError("no training crops given: run `snakemake --cores 2 training_data` first")
    if not correlated_files:
        raise BenchError("no base results given for the combiner's training")
    keys = {**BUFFER_KEYS, **{k: v for k, v in keys.items() if k not in BUFFER_KEYS}}
    base_crops = load_crops(list(crop_files))
    levels = list(base_crops.info["spp_levels"])
    inputs, targets, seeds = [], [], []
    for base, files in correlated_files.items():
        if len(files) != len(crop_files):
            raise BenchError(f"{len(files)} result files of base '{base}' for {len(crop_files)} crops")
        for crop_path, path, target, seed in zip(crop_files, files, base_crops.targets, base_crops.seeds):
            meta = read_metadata(path)
            if [int(v) for v in str(meta.get("spp_levels", "")).split(",") if v] != levels:
                raise BenchError(f"{path}: spp levels {meta.get('spp_levels')} differ from the crops' {levels}")
            correlated = read_layers(path)
            check_finite(path, correlated)
            crop = read_layers(crop_path)
            per_level = []
            for level in levels:
                per_level.append(np.stack([
                    np.concatenate([_combiner_input(key, half, level, crop, correlated,
                                                    str(path) if key.startswith("correlated") else str(crop_path))
                                    for key in keys], axis=0)
                    for half in HALVES]))
            inputs.append(np.stack(per_level))
            targets.append(target)
            seeds.append(seed)
    info = {**base_crops.info, "bases": list(correlated_files), "folder": str(Path(crop_files[0]).parent)}
    return CropSet(np.ascontiguousarray(np.stack(inputs), dtype=np.float32),
                   np.ascontiguousarray(np.stack(targets), dtype=np.float32), base_crops.spp,
                   np.array(seeds), info, keys)
