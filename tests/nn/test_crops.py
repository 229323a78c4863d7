"""The plane-sharing CropSet of mcbench.nn.crops against the dense layout it replaced: a
hand-built ``(items, levels, 3, C, H, W)`` array of synthetic crops (every plane random, so any
mix-up of crop, base, level, buffer or channel shows), and batches drawn from it by the original
dense sampler, must equal the new ones bit for bit (the trained weights stay the same)."""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from mcbench import BenchError
from mcbench.io.exr import write_layers
from mcbench.nn.crops import (BUFFER_KEYS, CropSet, PlaneStore, dihedral, is_validation_seed, load_combiner_crops,
                              load_crops, sample_batch, validation_batches)

LEVELS = (4, 16)
SIZE = 12
HALVES = ("", "_a", "_b")
# the sample subsets of each image (full: A and B; A: bins 0-1; B: bins 2-3)
SUBSETS = {"": ("_a", "_b"), "_a": ("_bin0", "_bin1"), "_b": ("_bin2", "_bin3")}
COMBINER_KEYS = {"correlated": 3, "albedo_variance": 3, "depth_variance": 1, "color_sub": 6, "variance_sub": 6,
                 "correlated_sub": 6}
ONE_CHANNEL = ("depth", "depth_variance")


def plane(rng, name):
    shape = (SIZE, SIZE) if name.split("_spp")[0].rstrip("_ab") in ONE_CHANNEL else (SIZE, SIZE, 3)
    return rng.gamma(2.0, 0.5, shape).astype(np.float32)


def crop_layers(rng, seed, k):
    layers = {"target": plane(rng, "target")}
    for level in LEVELS:
        for quantity in ("color", "variance", "albedo", "normal", "depth", "albedo_variance", "depth_variance"):
            for half in HALVES:
                layers[f"{quantity}{half}_spp{level}"] = plane(rng, f"{quantity}{half}")
        for j in range(4):
            for quantity in ("color", "variance"):
                layers[f"{quantity}_bin{j}_spp{level}"] = plane(rng, quantity)
    meta = {"seed": str(seed), "crop": str(k), "spp_levels": ",".join(map(str, LEVELS)), "target_spp": "4096",
            "resolution": f"{4 * SIZE}x{4 * SIZE}"}
    return layers, meta


def base_layers(rng):
    return {f"correlated{half}{sub}_spp{level}": plane(rng, "correlated") for level in LEVELS for half in HALVES
            for sub in ("", "_sub0", "_sub1")}


def channels_first(array):
    return array[None] if array.ndim == 2 else np.moveaxis(array, 2, 0)


def dense_item(crop, base, keys):
    """(L, 3, C, H, W) float32 of one item, by the documented layout: per level and buffer the
    keys' channels in order; ``*_sub`` are the image's two sample subsets, ``correlated*`` the base's."""
    levels = []
    for level in LEVELS:
        buffers = []
        for half in HALVES:
            parts = []
            for key in keys:
                if key == "correlated":
                    arrays = [base[f"correlated{half}_spp{level}"]]
                elif key == "correlated_sub":
                    arrays = [base[f"correlated{half}_sub{j}_spp{level}"] for j in (0, 1)]
                elif key in ("color_sub", "variance_sub"):
                    arrays = [crop[f"{key[:-4]}{s}_spp{level}"] for s in SUBSETS[half]]
                else:
                    arrays = [crop[f"{key}{half}_spp{level}"]]
                parts += [channels_first(a) for a in arrays]
            buffers.append(np.concatenate(parts))
        levels.append(np.stack(buffers))
    return np.stack(levels).astype(np.float32)


def dense_sample_batch(inputs, targets, keys, seed, step, batch_size, patch):
    """The sampler of the dense layout (mcbench before plane sharing), as the reference."""
    n, levels, buffers, channels, height, width = inputs.shape
    rng = np.random.default_rng([int(seed), int(step)])
    x_out = np.empty((batch_size, channels, patch, patch), dtype=np.float32)
    t_out = np.empty((batch_size, 3, patch, patch), dtype=np.float32)
    for i in range(batch_size):
        c, l, b = rng.integers(n), rng.integers(levels), rng.integers(buffers)
        y, x = rng.integers(height - patch + 1), rng.integers(width - patch + 1)
        transform = int(rng.integers(8))
        x_out[i] = dihedral(inputs[c, l, b, :, y:y + patch, x:x + patch], transform)
        t_out[i] = dihedral(targets[c, :, y:y + patch, x:x + patch], transform)
    return x_out, t_out


def flatten(buffers, keys):
    assert list(buffers) == list(keys)
    return torch.cat([buffers[k] for k in keys], dim=1).numpy()


def assert_same_batches(crops, inputs, targets, seeds, spp, keys):
    """Training batches (several steps, seeds and patch sizes) and validation batches of every
    buffer of ``crops`` equal those of the dense arrays, bit for bit."""
    np.testing.assert_array_equal(crops.inputs, inputs)
    np.testing.assert_array_equal(crops.targets, targets)
    for seed, step, batch, patch in [(0, 0, 5, 8), (3, 17, 7, SIZE), (11, 2, 4, 5)]:
        buffers, batch_targets = sample_batch(crops, seed, step, batch, patch)
        x, t = dense_sample_batch(inputs, targets, keys, seed, step, batch, patch)
        assert flatten(buffers, keys).tobytes() == x.tobytes()
        assert batch_targets.dtype == torch.float32 and batch_targets.numpy().tobytes() == t.tobytes()
    items = [(c, l) for c in range(len(inputs)) for l in range(len(LEVELS))]
    for buffer in range(3):
        got = list(validation_batches(crops, batch_size=3, buffer=buffer))
        assert sum(len(t) for _, t, _, _ in got) == len(items)
        for j, (buffers, batch_targets, batch_seeds, batch_spp) in enumerate(got):
            chunk = items[3 * j:3 * j + 3]
            assert flatten(buffers, keys).tobytes() == np.stack([inputs[c, l, buffer] for c, l in chunk]).tobytes()
            assert batch_targets.numpy().tobytes() == np.stack([targets[c] for c, _ in chunk]).tobytes()
            np.testing.assert_array_equal(batch_seeds, [seeds[c] for c, _ in chunk])
            np.testing.assert_array_equal(batch_spp, [spp[l][buffer] for _, l in chunk])


SEEDS = (0, 7, 15, 9)


def test_denoiser_crops_give_the_dense_layouts_batches():
    rng = np.random.default_rng(1)
    crops_in = [crop_layers(rng, seed, k) for seed in SEEDS for k in range(2)]
    crops = CropSet.from_layers(crops_in)
    inputs = np.stack([dense_item(layers, None, BUFFER_KEYS) for layers, _ in crops_in])
    targets = np.stack([np.moveaxis(layers["target"], 2, 0) for layers, _ in crops_in])
    seeds = [int(meta["seed"]) for _, meta in crops_in]
    spp = [[level, level / 2, level / 2] for level in LEVELS]
    assert crops.shape == inputs.shape == (8, 2, 3, 13, SIZE, SIZE)
    assert_same_batches(crops, inputs, targets, seeds, spp, BUFFER_KEYS)
    # each plane once: 13 input channels per level and buffer plus the target, per crop
    assert crops.planes.shape == (8 * (len(LEVELS) * 3 * 13 + 3), SIZE, SIZE)
    assert crops.planes.nbytes <= 1.01 * 4 * SIZE * SIZE * len(crops.planes)   # random bits: no gain, little loss
    train, validation = crops.split()
    assert train.planes is crops.planes and validation.planes is crops.planes      # no copy
    mask = np.array([is_validation_seed(s) for s in seeds])
    assert sorted(set(validation.seeds)) == [7, 15] and sorted(set(train.seeds)) == [0, 9]
    for part, rows in ((train, ~mask), (validation, mask)):
        assert_same_batches(part, inputs[rows], targets[rows], np.array(seeds)[rows], spp, BUFFER_KEYS)


@pytest.fixture(scope="module")
def combiner_files(tmp_path_factory):
    """Synthetic crops of scenes 0, 7 and 9 (two crops each) and three bases' results on them."""
    folder = tmp_path_factory.mktemp("combiner")
    rng = np.random.default_rng(2)
    crop_files, crops, results = [], [], {"nfor": [], "kpcn": [], "oidn": []}
    files = {base: [] for base in results}
    for seed in (0, 7, 9):
        for k in range(2):
            layers, meta = crop_layers(rng, seed, k)
            crop_files.append(folder / f"example_{seed}_{k}.exr")
            write_layers(crop_files[-1], layers, metadata=meta)
            crops.append(layers)
            for base in results:
                results[base].append(base_layers(rng))
                files[base].append(folder / "correlated" / base / crop_files[-1].name)
                files[base][-1].parent.mkdir(parents=True, exist_ok=True)
                write_layers(files[base][-1], results[base][-1], metadata={"spp_levels": meta["spp_levels"]})
    return crop_files, files, crops, results


def test_combiner_items_pair_each_crop_with_each_base_once_and_give_the_dense_batches(combiner_files):
    crop_files, files, crops_in, results = combiner_files
    crops = load_combiner_crops(crop_files, files, COMBINER_KEYS)
    keys = {**BUFFER_KEYS, **COMBINER_KEYS}
    assert crops.keys == keys and crops.info["bases"] == ["nfor", "kpcn", "oidn"]
    n = len(crop_files)
    # base by base, every crop: each (crop, base) exactly once
    assert crops.pairs.tolist() == [[c, b] for b in range(3) for c in range(n)]
    assert sorted(map(tuple, crops.pairs.tolist())) == sorted({(c, b) for c in range(n) for b in range(3)})
    inputs = np.stack([dense_item(crops_in[c], results[base][c], keys) for base in results for c in range(n)])
    targets = np.stack([np.moveaxis(crops_in[c]["target"], 2, 0) for _ in results for c in range(n)])
    seeds = [int(p.name.split("_")[1]) for _ in results for p in crop_files]
    spp = [[level, level / 2, level / 2] for level in LEVELS]
    assert crops.shape == inputs.shape == (3 * n, len(LEVELS), 3, 13 + 25, SIZE, SIZE)
    assert_same_batches(crops, inputs, targets, seeds, spp, keys)
    # a crop's render planes are stored once (not once per base); the full image's subsets are A and B
    crop_planes = len(LEVELS) * (3 * (13 + 3 + 1) + 2 * 4 * 3) + 3
    base_planes = len(LEVELS) * 3 * 9
    assert len(crops.planes) == n * (crop_planes + 3 * base_planes)
    assert crops.planes.nbytes < inputs.nbytes / 2
    train, validation = crops.split()
    assert sorted(set(validation.seeds.tolist())) == [7] and sorted(set(train.seeds.tolist())) == [0, 9]
    assert validation.pairs.tolist() == [[c, b] for b in range(3) for c in (2, 3)]   # scene 7, every base
    mask = np.array([is_validation_seed(s) for s in seeds])
    assert_same_batches(validation, inputs[mask], targets[mask], np.array(seeds)[mask], spp, keys)
    assert_same_batches(train, inputs[~mask], targets[~mask], np.array(seeds)[~mask], spp, keys)


def test_combiner_and_crop_loading_errors_name_the_file_and_input(combiner_files, tmp_path):
    crop_files, files, crops_in, results = combiner_files
    broken = {k: v for k, v in results["kpcn"][1].items() if k != "correlated_a_sub1_spp16"}
    bad = tmp_path / "bad.exr"
    write_layers(bad, broken, metadata={"spp_levels": ",".join(map(str, LEVELS))})
    with pytest.raises(BenchError, match=r"bad\.exr.*correlated_a_sub1_spp16.*'correlated_sub'"):
        load_combiner_crops(crop_files[:2], {"kpcn": [files["kpcn"][0], bad]}, COMBINER_KEYS)
    load_combiner_crops(crop_files[:2], {"kpcn": [files["kpcn"][0], bad]}, {"correlated": 3})   # not needed: fine
    with pytest.raises(BenchError, match="result files of base 'kpcn'"):
        load_combiner_crops(crop_files[:2], {"kpcn": files["kpcn"][:1]}, COMBINER_KEYS)
    small = {k: v[:SIZE - 2] for k, v in crops_in[1].items()}
    odd = tmp_path / "example_3_0.exr"
    write_layers(odd, small, metadata={"seed": "3", "spp_levels": ",".join(map(str, LEVELS))})
    with pytest.raises(BenchError, match=r"example_3_0\.exr.*pixels"):
        load_crops([crop_files[0], odd])
    nan = dict(crops_in[0])
    nan["albedo_variance_b_spp4"] = nan["albedo_variance_b_spp4"].copy()
    nan["albedo_variance_b_spp4"][1, 2] = np.inf
    infinite = tmp_path / "example_4_0.exr"
    write_layers(infinite, nan, metadata={"seed": "4", "spp_levels": ",".join(map(str, LEVELS))})
    load_crops([infinite])                          # a denoiser does not read that layer
    # crops of two feature conventions never make one training set; the set records its convention
    assert load_crops([crop_files[0]]).info["features"] == "first_hit"     # written without the key
    other = tmp_path / "example_5_0.exr"
    write_layers(other, crops_in[0], metadata={"seed": "5", "spp_levels": ",".join(map(str, LEVELS)),
                                               "features": "tungsten"})
    assert load_crops([other]).info["features"] == "tungsten"
    with pytest.raises(BenchError, match=r"example_5_0\.exr.*features 'tungsten'"):
        load_crops([crop_files[0], other])
    with pytest.raises(BenchError, match=r"example_4_0\.exr.*albedo_variance_b_spp4"):
        load_combiner_crops([infinite], {"kpcn": files["kpcn"][:1]}, COMBINER_KEYS)


def test_plane_store_gives_back_every_float32_bit_pattern_and_checks_layouts(tmp_path):
    """Compression is lossless: random finite float32 bit patterns (subnormals, -0, HDR extremes)
    and smooth images (which compress) come back byte for byte; the planes live in an unnamed
    file in the folder given (on its disk, nothing left there)."""
    rng = np.random.default_rng(4)
    bits = rng.integers(0, 2 ** 32, (SIZE, SIZE, 3), dtype=np.uint64).astype(np.uint32).view(np.float32)
    bits = np.where(np.isfinite(bits), bits, np.float32(-0.0))
    bits[0, 0] = [np.float32(1e-45), np.finfo(np.float32).max, -np.finfo(np.float32).tiny / 2]
    smooth = np.add.outer(np.arange(SIZE), np.arange(SIZE)).astype(np.float32) / 7
    store = PlaneStore(SIZE, SIZE, folder=tmp_path)
    first = store.add({"x": bits, "depth": smooth}, ["x", "depth"], "a.exr")
    second = store.add({"x": bits[::-1].copy(), "depth": smooth * 2}, ["x", "depth"], "b.exr")
    assert first["x"].tolist() == [0, 1, 2] and first["depth"].tolist() == [3] and second["depth"].tolist() == [7]
    assert store.take(first["x"]).tobytes() == np.moveaxis(bits, 2, 0).tobytes()
    assert store.take(np.array([[7], [3]])).tobytes() == np.stack([smooth[None] * 2, smooth[None]]).tobytes()
    assert store.take(second["x"][::-1])[2].tobytes() == bits[::-1, :, 0].tobytes()
    assert store.nbytes < 2 * (3 * bits[..., 0].nbytes * 1.01 + smooth.nbytes / 2)
    assert os.fstat(store.file.fileno()).st_size == store.nbytes
    assert os.fstat(store.file.fileno()).st_dev == os.stat(tmp_path).st_dev and not list(tmp_path.iterdir())
    held = store.nbytes
    with pytest.raises(BenchError, match=r"c\.exr: layer 'depth' is 3 channel"):
        store.add({"x": bits, "depth": bits}, ["x", "depth"], "c.exr")
    assert len(store) == 8 and store.nbytes == held                          # nothing of c.exr kept
    assert store.take(first["depth"]).tobytes() == smooth[None].tobytes()
    assert PlaneStore(2, 2, folder=tmp_path / "missing").folder != str(tmp_path / "missing")   # falls back
