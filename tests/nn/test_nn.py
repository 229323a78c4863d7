"""The shared learning pipeline (mcbench.nn): kernels against brute force, RepVGG
re-parameterisation, input transforms against closed forms, data split and seeded batches,
and the training loop (resume gives the same weights, records reproduce, errors name things)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mcbench import BenchError
from mcbench.nn import features, kernels, losses
from mcbench.nn.crops import (BUFFER_KEYS, CropSet, dihedral, is_validation_seed, load_crops, sample_batch,
                              validation_batches)


# ----------------------------------------------------------------------------- kernels

def _brute_pixel_kernels(image, logits, k):
    """Per pixel: softmax over in-image neighbours of the k² logits, weighted sum (loops)."""
    n, c, h, w = image.shape
    r = k // 2
    out = np.zeros((n, c, h, w))
    for b in range(n):
        for y in range(h):
            for x in range(w):
                values, weights = [], []
                for j, (dy, dx) in enumerate((dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)):
                    if 0 <= y + dy < h and 0 <= x + dx < w:
                        weights.append(logits[b, j, y, x])
                        values.append(image[b, :, y + dy, x + dx])
                weights = np.exp(np.array(weights) - max(weights))
                out[b, :, y, x] = (weights[:, None] * np.array(values)).sum(0) / weights.sum()
    return out


def _brute_shared_kernels(image, importance, k):
    """Fan et al. Eq. 3-4 literally: w_p(q) = exp I(q) / Σ_{q'∈Ω_p} exp I(q') over in-image q."""
    n, c, h, w = image.shape
    r = k // 2
    out = np.zeros((n, c, h, w))
    for b in range(n):
        for y in range(h):
            for x in range(w):
                y0, y1, x0, x1 = max(y - r, 0), min(y + r + 1, h), max(x - r, 0), min(x + r + 1, w)
                window = importance[b, 0, y0:y1, x0:x1].astype(np.float64)
                weights = np.exp(window - window.max())
                out[b, :, y, x] = (weights * image[b, :, y0:y1, x0:x1]).sum(axis=(1, 2)) / weights.sum()
    return out


@pytest.mark.parametrize("k", [3, 5])
def test_pixel_kernels_match_brute_force(k):
    rng = np.random.default_rng(k)
    image = rng.gamma(1.0, 2.0, size=(2, 3, 7, 6)).astype(np.float32)
    logits = rng.normal(0, 3, size=(2, k * k, 7, 6)).astype(np.float32)
    got = kernels.apply_pixel_kernels(torch.from_numpy(image), torch.from_numpy(logits), k).numpy()
    np.testing.assert_allclose(got, _brute_pixel_kernels(image, logits, k), rtol=2e-5, atol=1e-6)


def test_pixel_kernels_identity_and_shape_check():
    image = torch.rand(1, 3, 5, 5)
    logits = torch.full((1, 9, 5, 5), -50.0)
    logits[:, 4] = 50.0                      # all weight on the centre tap
    torch.testing.assert_close(kernels.apply_pixel_kernels(image, logits, 3), image)
    with pytest.raises(ValueError):
        kernels.apply_pixel_kernels(image, logits[:, :8], 3)


@pytest.mark.parametrize("k", [3, 5, 13])
def test_shared_kernels_match_unfold_softmax(k):
    rng = np.random.default_rng(100 + k)
    image = rng.gamma(0.5, 10.0, size=(2, 3, 15, 17)).astype(np.float32)
    raw = rng.normal(0, 30, size=(2, 1, 15, 17)).astype(np.float32)      # saturates the bound
    importance = kernels.bound_importance(torch.from_numpy(raw))
    assert float(importance.abs().max()) <= kernels.IMPORTANCE_BOUND
    got = kernels.apply_shared_kernels(torch.from_numpy(image), importance, k).numpy()
    np.testing.assert_allclose(got, _brute_shared_kernels(image, importance.numpy(), k), rtol=1e-4, atol=1e-5)


def test_shared_kernels_extreme_importance_finite_and_convex():
    image = torch.rand(1, 3, 20, 20) * 1e4
    importance = torch.full((1, 1, 20, 20), -kernels.IMPORTANCE_BOUND)
    importance[..., ::7, ::7] = kernels.IMPORTANCE_BOUND       # huge dynamic range of weights
    out = kernels.apply_shared_kernels(image, importance, 13)
    assert torch.isfinite(out).all()
    assert float(out.min()) >= float(image.min()) - 1e-2 and float(out.max()) <= float(image.max()) + 1e-2
    # a constant image stays constant under any normalised kernel
    constant = torch.full((1, 3, 20, 20), 2.5)
    torch.testing.assert_close(kernels.apply_shared_kernels(constant, importance, 13), constant)


# ----------------------------------------------------------------------------- features and losses

def test_demodulation_round_trip_and_log_inverse():
    color = torch.rand(2, 3, 4, 5) * 10
    albedo = torch.rand(2, 3, 4, 5)
    albedo[0, :, 0, 0] = 0.0                        # environment: no albedo
    albedo[0, :, 1, 1] = torch.tensor([0.5, 0.0, 0.0])
    torch.testing.assert_close(features.remodulate(features.demodulate(color, albedo), albedo), color)
    irradiance = features.demodulate(color, albedo)
    torch.testing.assert_close(irradiance[0, :, 0, 0], color[0, :, 0, 0])          # not demodulated
    torch.testing.assert_close(irradiance[0, :, 1, 1], color[0, :, 1, 1] / torch.tensor([0.50316, 0.00316, 0.00316]))
    torch.testing.assert_close(features.exp_radiance(features.log_radiance(color)), color, rtol=1e-5, atol=1e-5)
    assert float(features.log_radiance(torch.tensor(-3.0))) == 0.0


def test_log_noise_level_matches_sampled_std():
    """Delta method: std of log(1 + X) for X ~ N(m, σ²) with small σ is σ / (1 + m)."""
    rng = np.random.default_rng(0)
    m, sigma = 3.0, 0.05
    samples = np.log1p(rng.normal(m, sigma, size=200_000))
    value = torch.full((1, 3, 1, 1), m)
    variance = torch.full((1, 3, 1, 1), sigma ** 2)
    predicted = float(features.log_noise_level(value, variance))
    assert abs(predicted - samples.std()) / samples.std() < 0.01


def test_spatial_gradients_of_a_ramp_and_normalized_depth():
    y, x = torch.meshgrid(torch.arange(4.0), torch.arange(5.0), indexing="ij")
    ramp = (2 * x + 3 * y)[None, None]
    grads = features.spatial_gradients(ramp)
    assert torch.all(grads[0, 0, :, :-1] == 2) and torch.all(grads[0, 0, :, -1] == 0)
    assert torch.all(grads[0, 1, :-1] == 3) and torch.all(grads[0, 1, -1] == 0)
    depth = torch.tensor([[[[0.0, 2.0], [4.0, 8.0]]]])
    torch.testing.assert_close(features.normalized_depth(depth), depth / 8)
    assert torch.all(features.normalized_depth(torch.zeros(1, 1, 2, 2)) == 0)


def test_losses_closed_forms():
    t = torch.tensor([1.0, 2.0, 0.0]).view(1, 3, 1, 1)
    y = torch.tensor([2.0, 2.0, 1.0]).view(1, 3, 1, 1)
    expected = np.mean([1 / (2 + 1 + 0.01), 0.0, 1 / (1 + 0 + 0.01)])
    assert abs(float(losses.smape(y, t)) - expected) < 1e-6
    assert abs(float(losses.relmse(y, t)) - np.mean([1 / 1.01, 0, 1 / 0.01])) < 1e-4
    assert abs(float(losses.l1_log(y, t)) - np.mean([np.log(3) - np.log(2), 0, np.log(2)])) < 1e-6
    image = torch.rand(1, 3, 6, 6)
    for loss in losses.LOSSES.values():
        assert float(loss(image, image)) == 0.0


# ----------------------------------------------------------------------------- data

def synthetic_crops(seeds=(0, 7), crops_per_scene=2, size=16, levels=(4, 16), noise=0.3, seed=0):
    """Crops of smooth images with Gaussian noise of std noise/sqrt(spp) and exact targets."""
    rng = np.random.default_rng(seed)
    crops = []
    yy, xx = np.mgrid[0:size, 0:size] / size
    for scene in seeds:
        for k in range(crops_per_scene):
            base = 0.5 + 0.4 * np.sin(2 * np.pi * (xx * rng.uniform(0.5, 2) + yy * rng.uniform(0.5, 2)))
            target = np.stack([base * c for c in rng.uniform(0.3, 1.0, 3)], axis=2).astype(np.float32)
            albedo = np.full((size, size, 3), 0.7, np.float32)
            layers = {"target": target}
            for level in levels:
                for half, spp in (("", level), ("_a", level / 2), ("_b", level / 2)):
                    sigma = noise / np.sqrt(spp)
                    layers[f"color{half}_spp{level}"] = (target + rng.normal(0, sigma, target.shape)).astype(np.float32)
                    layers[f"variance{half}_spp{level}"] = np.full_like(target, sigma ** 2)
                    layers[f"albedo{half}_spp{level}"] = albedo
                    layers[f"normal{half}_spp{level}"] = np.dstack([np.zeros((size, size, 2)), np.ones((size, size))]).astype(np.float32)
                    layers[f"depth{half}_spp{level}"] = np.full((size, size), 3.0, np.float32)
            meta = {"seed": str(scene), "crop": str(k), "spp_levels": ",".join(map(str, levels)),
                    "target_spp": "4096", "resolution": f"{size * 2}x{size}"}
            crops.append((layers, meta))
    return crops


def test_cropset_layout_split_and_validation_rule():
    crops = CropSet.from_layers(synthetic_crops(seeds=(0, 7, 15, 9)))
    assert crops.inputs.shape == (8, 2, 3, sum(BUFFER_KEYS.values()), 16, 16)
    np.testing.assert_array_equal(crops.spp, [[4, 2, 2], [16, 8, 8]])
    train, validation = crops.split()
    assert sorted(set(validation.seeds)) == [7, 15] and sorted(set(train.seeds)) == [0, 9]
    assert [s for s in range(40) if is_validation_seed(s)] == [7, 15, 23, 31, 39]
    assert crops.info["crop_size"] == 16 and crops.info["crops_per_scene"] == 2
    items = list(validation_batches(validation, batch_size=3))
    assert sum(len(t) for _, t, _, _ in items) == 4 * 2
    assert sorted({int(n) for *_, spp in items for n in spp}) == [4, 16]


def test_batches_are_seeded_and_augmented():
    crops = CropSet.from_layers(synthetic_crops())
    a, ta = sample_batch(crops, seed=3, step=5, batch_size=4, patch=8)
    b, tb = sample_batch(crops, seed=3, step=5, batch_size=4, patch=8)
    c, tc = sample_batch(crops, seed=3, step=6, batch_size=4, patch=8)
    assert torch.equal(ta, tb) and all(torch.equal(a[key], b[key]) for key in a)
    assert not torch.equal(ta, tc)
    assert a["color"].shape == (4, 3, 8, 8) and a["depth"].shape == (4, 1, 8, 8)
    with pytest.raises(BenchError, match="patch"):
        sample_batch(crops, 0, 0, 1, 32)


def test_dihedral_gives_eight_distinct_invertible_views():
    array = np.arange(9.0).reshape(1, 3, 3)
    views = [dihedral(array, t) for t in range(8)]
    assert len({v.tobytes() for v in views}) == 8
    for t in range(4):   # rotations undo with the opposite rotation
        np.testing.assert_array_equal(np.rot90(views[t], k=-t, axes=(-2, -1)), array)


def test_load_crops_names_bad_files(tmp_path):
    from mcbench.io.exr import write_layers

    layers, meta = synthetic_crops(seeds=(0,), crops_per_scene=1)[0]
    good = tmp_path / "example_0_0.exr"
    write_layers(good, layers, metadata=meta)
    assert load_crops([good]).inputs.shape[0] == 1
    with pytest.raises(BenchError, match="missing"):
        load_crops([tmp_path / "example_9_0.exr"])
    broken = dict(layers)
    broken["color_spp4"] = broken["color_spp4"].copy()
    broken["color_spp4"][0, 0, 0] = np.nan
    bad = tmp_path / "example_1_0.exr"
    write_layers(bad, broken, metadata=meta)
    with pytest.raises(BenchError, match="example_1_0.exr"):
        load_crops([good, bad])
    with pytest.raises(BenchError, match="no training crops"):
        load_crops([])


# ----------------------------------------------------------------------------- training loop

def write_crops(folder, **kwargs):
    from mcbench.io.exr import write_layers

    paths = []
    for layers, meta in synthetic_crops(**kwargs):
        path = folder / f"example_{meta['seed']}_{meta['crop']}.exr"
        write_layers(path, layers, metadata=meta)
        paths.append(path)
    return paths


TINY = {"steps": 6, "batch_size": 2, "patch": 16, "validate_every": 3, "checkpoint_every": 3, "threads": 1,
        "seed": 1}


@pytest.fixture(scope="module")
def crop_files(tmp_path_factory):
    return write_crops(tmp_path_factory.mktemp("crops"))


def test_training_writes_loadable_weights_and_a_faithful_record(tmp_path, crop_files):
    from mcbench.nn.train import evaluate, train_network
    import methods.optix_ae as module

    record = train_network(module, crop_files, tmp_path / "w.pt", tmp_path / "w.json", tmp_path / "ck.pt",
                           TINY, log=lambda m: None)
    blob = torch.load(tmp_path / "w.pt", weights_only=True)
    assert blob["arch"] == module.METHOD.learned.network
    network = module.build_network(**blob["arch"])
    network.load_state_dict(blob["state_dict"])
    assert record["parameters"] == sum(p.numel() for p in network.parameters())
    assert record["data"]["validation_scenes"] == [7] and record["data"]["training_scenes"] == [0]
    assert [h["step"] for h in record["history"]] == [3, 6]
    _, validation = load_crops(crop_files).split()
    assert evaluate(network, validation, record["loss"])["loss"] == pytest.approx(record["validation"]["loss"], rel=1e-6)
    from mcbench.io.tables import read_json
    assert read_json(tmp_path / "w.json")["validation"]["loss"] == record["validation"]["loss"]


def test_killed_training_resumes_to_the_same_weights(tmp_path, crop_files, monkeypatch):
    import mcbench.nn.train as train
    import methods.kpcn as kpcn

    train.train_network(kpcn, crop_files, tmp_path / "a.pt", tmp_path / "a.json", tmp_path / "a.ckpt", TINY,
                        log=lambda m: None)
    original = train.sample_batch

    def killed_at_step_4(crops, seed, step, *args):
        if step == 4:
            raise KeyboardInterrupt("killed")
        return original(crops, seed, step, *args)

    monkeypatch.setattr(train, "sample_batch", killed_at_step_4)
    with pytest.raises(KeyboardInterrupt):
        train.train_network(kpcn, crop_files, tmp_path / "b.pt", tmp_path / "b.json", tmp_path / "b.ckpt", TINY,
                            log=lambda m: None)
    assert not (tmp_path / "b.pt").exists()
    assert torch.load(tmp_path / "b.ckpt", weights_only=True)["step"] == 3
    monkeypatch.setattr(train, "sample_batch", original)
    messages = []
    train.train_network(kpcn, crop_files, tmp_path / "b.pt", tmp_path / "b.json", tmp_path / "b.ckpt", TINY,
                        log=messages.append)
    assert any("resuming" in m and "step 3" in m for m in messages)
    a = torch.load(tmp_path / "a.pt", weights_only=True)["state_dict"]
    b = torch.load(tmp_path / "b.pt", weights_only=True)["state_dict"]
    assert all(torch.equal(a[key], b[key]) for key in a)
    # a checkpoint of other settings is refused, naming the file
    with pytest.raises(BenchError, match="b.ckpt"):
        train.train_network(kpcn, crop_files, tmp_path / "c.pt", tmp_path / "c.json", tmp_path / "b.ckpt",
                            {**TINY, "learning_rate": 1e-2}, log=lambda m: None)


def test_adversarial_training_runs_and_checkpoints_the_critic(tmp_path, crop_files):
    from mcbench.nn.train import train_network
    import methods.mcgan as mcgan

    record = train_network(mcgan, crop_files, tmp_path / "g.pt", tmp_path / "g.json", tmp_path / "g.ckpt",
                           {**TINY, "steps": 2}, log=lambda m: None)
    state = torch.load(tmp_path / "g.ckpt", weights_only=True)
    assert "critic" in state and "critic_optimizer" in state
    assert record["settings"]["adversarial_weight"] > 0 and np.isfinite(record["validation"]["loss"])


def test_training_learns_to_denoise(tmp_path):
    """60 steps on smooth images with Gaussian noise lower the validation loss well below the noisy
    input's and the untrained network's."""
    from mcbench.nn.train import evaluate, train_network
    import methods.kpcn as module

    files = write_crops(tmp_path, seeds=(0, 1, 2, 7), crops_per_scene=2, noise=1.0, seed=5)
    crops = load_crops(files)
    _, validation = crops.split()
    settings = {**TINY, "steps": 60, "batch_size": 4, "learning_rate": 2e-3, "validate_every": 60,
                "checkpoint_every": 60}
    record = train_network(module, files, tmp_path / "k.pt", tmp_path / "k.json", tmp_path / "k.ckpt", settings,
                           log=lambda m: None)

    class Identity(torch.nn.Module):
        def forward(self, buffers):
            return buffers["color"]

    noisy = evaluate(Identity(), validation, record["loss"])["loss"]
    torch.manual_seed(settings["seed"])                 # the trainer's initial weights
    untrained = evaluate(module.build_network(**module.METHOD.learned.network), validation, record["loss"])["loss"]
    assert record["validation"]["loss"] < 0.7 * noisy
    assert record["validation"]["loss"] < 0.8 * untrained


def test_unknown_settings_and_non_learned_methods_are_refused(crop_files, tmp_path, capsys):
    from mcbench.nn.train import main, train_network
    import methods.kpcn as kpcn
    from methods import load_method

    with pytest.raises(BenchError, match="unknown training setting"):
        train_network(kpcn, crop_files, tmp_path / "x.pt", tmp_path / "x.json", tmp_path / "x.ckpt",
                      {"stepz": 3})
    with pytest.raises(BenchError, match=r"methods/oidn\.py is not a learned method"):
        train_network(load_method("oidn"), crop_files, tmp_path / "x.pt", tmp_path / "x.json", tmp_path / "x.ckpt")
    with pytest.raises(BenchError, match="validation"):
        train_network(kpcn, crop_files[:2], tmp_path / "x.pt", tmp_path / "x.json", tmp_path / "x.ckpt", TINY)
    # the command line resolves names with the caller's loader and reports errors in one line
    assert main(["evaluate", "oidn", "--data", str(tmp_path)], load_method=load_method) == 1
    assert "methods/oidn.py is not a learned method" in capsys.readouterr().err


@pytest.mark.parametrize("damage", ["hostile", "truncated"])
def test_damaged_checkpoint_is_refused_naming_it(crop_files, tmp_path, damage):
    """A checkpoint goes through mcbench.io.weights.load_weights: a corrupt or code-running file is
    an error that names it and never suggests loading it unsafely; nothing of it runs."""
    import os
    import traceback

    from mcbench.nn.train import train_network
    import methods.kpcn as kpcn

    class RunsCode:
        def __reduce__(self):
            return os.mkdir, (str(tmp_path / "pwned"),)

    checkpoint = tmp_path / "k.ckpt"
    torch.save({"arch": kpcn.METHOD.learned.network, "network": RunsCode(), "payload": torch.ones(256)}, checkpoint)
    if damage == "truncated":
        checkpoint.write_bytes(checkpoint.read_bytes()[:300])
    with pytest.raises(BenchError, match=r"k\.ckpt: cannot load checkpoint") as caught:
        train_network(kpcn, crop_files, tmp_path / "k.pt", tmp_path / "k.json", checkpoint, TINY, log=lambda m: None)
    assert "weights_only" not in "".join(traceback.format_exception(caught.value))
    assert not (tmp_path / "pwned").exists() and not (tmp_path / "k.pt").exists()


def test_training_prints_loss_and_time_per_interval_and_at_each_validation(tmp_path, crop_files, monkeypatch):
    """Progress of a tiny training (6 steps, validation every 3): with an interval of 2 steps,
    one line per interval with the interval's mean training loss, its seconds and seconds per
    step, elapsed time and ETA (0 at the end), and a timed line per validation."""
    import re

    import mcbench.nn.train as train
    import methods.optix_ae as module

    monkeypatch.setattr(train, "LOG_EVERY", 2)
    messages = []
    record = train.train_network(module, crop_files, tmp_path / "w.pt", tmp_path / "w.json", tmp_path / "ck.pt",
                                 TINY, log=messages.append)
    interval = re.compile(r"optix_ae: step (\d)/6 loss (\d+\.\d{5}) lr \S+, (\d+\.\d) s for 2 steps "
                          r"\((\d+\.\d{3}) s/step\), elapsed (\d+\.\d) s, eta (\d+\.\d) s")
    lines = [interval.fullmatch(m) for m in messages if re.match(r"optix_ae: step \d/6 loss", m)]
    assert all(lines) and [int(m.group(1)) for m in lines] == [2, 4, 6]
    assert lines[-1].group(6) == "0.0"
    assert all(float(m.group(2)) > 0 for m in lines)
    validations = [m for m in messages if re.match(r"optix_ae: step \d validation ", m)]
    assert [int(re.search(r"step (\d)", m).group(1)) for m in validations] == [3, 6]
    assert all(re.search(r"relMSE \d+\.\d{5} \(\d+\.\d s, elapsed \d+\.\d s\)$", m) for m in validations)
    # the printed validation loss is the record's
    assert f"{record['history'][-1]['validation_loss']:.5f}" in validations[-1]


def test_deterministic_inference_sets_and_restores_the_flag_without_inductor():
    """The flag is on inside and restored after; the process never imports torch._inductor (the
    1-2 s import torch.use_deterministic_algorithms pays), checked in a fresh interpreter."""
    import subprocess
    import sys

    code = ("import sys, torch\n"
            "from mcbench.nn.inference import deterministic_inference\n"
            "before = torch.are_deterministic_algorithms_enabled()\n"
            "with deterministic_inference():\n"
            "    inside = torch.are_deterministic_algorithms_enabled()\n"
            "after = torch.are_deterministic_algorithms_enabled()\n"
            "print(before, inside, after, 'torch._inductor' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True", "False", "False"]


def test_plateau_rule_compares_the_last_round_with_the_best_earlier_one():
    from mcbench.nn.train import plateau_reached

    def history(*losses, steps=10):
        return [{"step": steps * (k + 1), "validation_loss": loss} for k, loss in enumerate(losses)]

    assert not plateau_reached(history(1.0), 10, 0.02)                      # one round: never
    assert not plateau_reached(history(1.0, 0.97), 10, 0.02)                # 3 % better
    assert plateau_reached(history(1.0, 0.99), 10, 0.02)                    # 1 %
    assert plateau_reached(history(1.0, 1.2), 10, 0.02)                     # worse
    assert plateau_reached(history(1.0, 0.5, 0.495), 10, 0.02)              # against the best earlier round
    assert not plateau_reached(history(1.0, 0.5, 0.45), 10, 0.02)
    assert not plateau_reached(history(1.0, 0.99), 10, 0.0)                 # plateau 0: any improvement goes on
    # validations between round ends do not count
    mixed = [{"step": 5, "validation_loss": 0.1}, {"step": 10, "validation_loss": 1.0},
             {"step": 15, "validation_loss": 0.1}, {"step": 20, "validation_loss": 0.9}]
    assert not plateau_reached(mixed, 10, 0.02)


def test_training_in_rounds_stops_at_the_plateau_and_keeps_the_best_round(tmp_path, crop_files):
    from mcbench.nn.train import evaluate, train_network
    import methods.kpcn as module

    settings = {**TINY, "rounds": 4, "plateau": 100.0}      # any round after the first stops it
    record = train_network(module, crop_files, tmp_path / "w.pt", tmp_path / "w.json", tmp_path / "ck.pt",
                           settings, log=lambda m: None, provenance={"cpu": {"model": "test CPU"}})
    assert record["steps_run"] == 12 and record["rounds_run"] == 2 and record["stopped_by"] == "plateau"
    assert [h["step"] for h in record["history"]] == [3, 6, 9, 12] and record["history"][-1]["round"] == 2
    assert record["cpu"] == {"model": "test CPU"}
    ends = [h["validation_loss"] for h in record["history"] if h["step"] % TINY["steps"] == 0]
    blob = torch.load(tmp_path / "w.pt", weights_only=True)
    network = module.build_network(**blob["arch"])
    network.load_state_dict(blob["state_dict"])
    _, validation = load_crops(crop_files).split()
    assert evaluate(network, validation, record["loss"])["loss"] == pytest.approx(min(ends), rel=1e-6)
    # resumed from its final checkpoint, it trains no further and keeps the same weights
    again = train_network(module, crop_files, tmp_path / "w2.pt", tmp_path / "w2.json", tmp_path / "ck.pt",
                          settings, log=lambda m: None)
    assert again["steps_run"] == 12 and again["validation"]["loss"] == pytest.approx(min(ends), rel=1e-6)
    # plateau 0 on two rounds: both run, the record says the rounds ended it
    both = train_network(module, crop_files, tmp_path / "w3.pt", tmp_path / "w3.json", tmp_path / "ck3.pt",
                         {**TINY, "rounds": 2, "plateau": 0.0}, log=lambda m: None)
    assert both["steps_run"] == 12 and both["stopped_by"] in ("rounds", "plateau")
    with pytest.raises(BenchError, match="rounds must be an integer"):
        train_network(module, crop_files, tmp_path / "x.pt", tmp_path / "x.json", tmp_path / "x.ckpt",
                      {**TINY, "rounds": 0}, log=lambda m: None)
