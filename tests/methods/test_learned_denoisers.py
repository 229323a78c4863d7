"""The learned base denoisers (KPCN, MCGAN, the OptiX stand-in autoencoder, WSKPN): network
structure, committed weights (weights_only loading, size, record), deterministic and finite
inference on hard cases, the recorded validation loss reproduced on a freshly rendered validation
scene, and no test scene among the training scenes."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import torch

from mcbench.analysis.training_curves import kept_round
from mcbench.io.buffers import RenderBuffers
from mcbench.io.tables import read_json
from mcbench.nn.crops import CropSet, is_validation_seed
from mcbench.nn.inference import image_tensors, load_network, run_network
from mcbench.nn.train import evaluate
from mcbench.io.weights import (COMMITTED_WEIGHTS, is_learned_method, load_weights, record_path, trained_features,
                                weights_path)
from methods import available_methods, load_method, method_spec

#: every learned method, found through its declaration
LEARNED_METHODS = [n for n in available_methods() if is_learned_method(load_method(n))]
#: the learned denoisers (the learned combiners: test_deep_combiner.py, test_progressive.py)
LEARNED = [n for n in LEARNED_METHODS if method_spec(load_method(n)).kind == "denoiser"]
# Kernel predictors output convex combinations of input pixels, so black in gives exactly black
# out; direct predictors (residual in log space) only approximately: a small bias is allowed.
BLACK_TOLERANCE = {"kpcn": 1e-7, "wskpn": 1e-7, "mcgan": 0.05, "optix_ae": 0.05}


@pytest.fixture
def noisy_buffers(make_render_buffers):
    """Synthetic buffers (tests/conftest.py) of a positive random truth (no negative radiance, as
    in renders), spp 8, noise std 0.1 per half buffer: ``noisy_buffers(height, width, seed)``."""
    def build(height=13, width=17, seed=0):
        truth = np.random.default_rng(seed).uniform(0.5, 2.0, (height, width, 3))
        return make_render_buffers(truth, spp=8, half_std=0.1, seed=seed)

    return build


def test_registry_lists_the_learned_methods_and_labels_stand_ins():
    assert {"kpcn", "mcgan", "optix_ae", "wskpn"} <= set(LEARNED)
    assert {"deep_combiner", "deep_combiner_mb", "progressive"} <= set(LEARNED_METHODS) - set(LEARNED)
    assert load_method("optix_ae").METHOD.label == "#7 OptiX† (our autoencoder, a stand-in)"
    for name in LEARNED:
        assert "†" in load_method(name).METHOD.label      # every one is our own training, and says so


def _randomise_batch_norms(network):
    """Give every batch norm non-trivial statistics and affine parameters."""
    generator = torch.Generator().manual_seed(1)
    for layer in network.modules():
        if isinstance(layer, torch.nn.BatchNorm2d):
            n = layer.num_features
            layer.running_mean.copy_(torch.randn(n, generator=generator) * 0.3)
            layer.running_var.copy_(torch.rand(n, generator=generator) + 0.5)
            layer.weight.data.copy_(torch.rand(n, generator=generator) + 0.5)
            layer.bias.data.copy_(torch.randn(n, generator=generator) * 0.1)


def test_repvgg_reparameterisation_is_exact(noisy_buffers):
    module = importlib.import_module("methods.wskpn")
    torch.manual_seed(0)
    network = module.build_network(**module.METHOD.learned.network).eval()
    _randomise_batch_norms(network)
    buffers = image_tensors(noisy_buffers().image("full"))
    with torch.no_grad():
        before = network(buffers)
        network.fuse()
        after = network(buffers)
    assert all(block.fused is not None for block in network.importance_net)
    torch.testing.assert_close(after, before, rtol=1e-4, atol=1e-5)
    block = module.network_classes().RepVGGBlock(4, 4).eval()
    _randomise_batch_norms(block)
    x = torch.randn(2, 4, 9, 9)
    with torch.no_grad():
        reference = block(x)
        block.fuse()
        torch.testing.assert_close(block(x), reference, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("name", LEARNED)
def test_untrained_networks_start_unsaturated(name, noisy_buffers):
    """At initialisation every network's output depends on its weights (non-zero gradients) and
    WSKPN's fusion weights are spread over its kernels (guards against the saturation that
    stalled a first WSKPN without batch norms)."""
    module = importlib.import_module(f"methods.{name}")
    torch.manual_seed(0)
    network = module.build_network(**module.METHOD.learned.network).train()
    buffers = image_tensors(noisy_buffers(32, 32, seed=4).image("full"))
    network(buffers).mean().backward()
    gradients = [p.grad for p in network.parameters() if p.grad is not None]
    assert gradients and all(torch.isfinite(g).all() for g in gradients)
    assert sum(float(g.abs().sum()) for g in gradients) > 0
    if name == "wskpn":
        _, inputs = module.network_inputs(buffers)
        out = network.importance_net(inputs)
        alpha = torch.softmax(out[:, len(network.kernel_sizes):], dim=1)
        assert float(alpha.detach().max(dim=1).values.mean()) < 0.6
        assert float(out.detach().std()) < 5


@pytest.mark.parametrize("name", LEARNED)
def test_untrained_networks_handle_any_size(name, noisy_buffers):
    module = importlib.import_module(f"methods.{name}")
    torch.manual_seed(0)
    network = module.build_network(**module.METHOD.learned.network).eval()
    for height, width in ((13, 17), (4, 4), (33, 20)):
        image = noisy_buffers(height, width).image("a")
        output = run_network(network, image)
        assert output.shape == (height, width, 3) and output.dtype == np.float32
        assert np.all(np.isfinite(output))


@pytest.mark.parametrize("name", LEARNED)
def test_committed_weights_load_safely_and_match_their_record(name):
    path = weights_path(COMMITTED_WEIGHTS, name)
    assert path.parent == COMMITTED_WEIGHTS and path.exists(), f"{path} missing"
    assert path.stat().st_size < 5 * 2 ** 20
    blob = load_weights(path)
    module = load_method(name)
    assert blob["arch"] == module.METHOD.learned.network
    record = read_json(record_path(COMMITTED_WEIGHTS, name))
    assert record["network"] == name and record["arch"] == module.METHOD.learned.network
    network = module.build_network(**blob["arch"])
    network.load_state_dict(blob["state_dict"])
    assert record["parameters"] == sum(p.numel() for p in network.parameters())
    for key in ("seconds", "machine", "torch", "settings", "data", "history", "validation"):
        assert key in record, key
    # whole rounds of its steps (one for a record made before rounds), the kept round's validation the record's
    steps_run = record.get("steps_run", record["settings"]["steps"])
    assert steps_run == record["history"][-1]["step"] and steps_run % record["settings"]["steps"] == 0
    assert kept_round(record["history"], record["settings"]["steps"])["validation_loss"] == record["validation"]["loss"]
    assert np.isfinite(record["validation"]["loss"])


@pytest.mark.parametrize("name", LEARNED)
def test_inference_is_deterministic_and_finite_on_hard_cases(name, noisy_buffers):
    module = load_method(name)
    buffers = noisy_buffers(24, 20, seed=3)
    first = module.denoise(buffers, weights_file=weights_path(COMMITTED_WEIGHTS, name))
    second = module.denoise(buffers, weights_file=weights_path(COMMITTED_WEIGHTS, name))
    for a, b in ((first.full, second.full), (first.a, second.a), (first.b, second.b)):
        np.testing.assert_array_equal(a, b)
    layers = dict(buffers.layers)
    layers["color"] = np.zeros_like(layers["color"])                      # black image, no noise
    layers["variance"] = np.zeros_like(layers["variance"])
    layers["albedo"] = np.zeros_like(layers["albedo"])                    # no albedo anywhere
    layers["color_a"] = layers["color_a"].copy()
    layers["color_a"][5, 5] = 1e6                                         # a firefly
    layers["variance_a"] = layers["variance_a"].copy()
    layers["variance_a"][5, 5] = 1e10
    result = module.denoise(RenderBuffers(layers=layers, spp=8), weights_file=weights_path(COMMITTED_WEIGHTS, name))
    for image in (result.full, result.a, result.b):
        assert np.all(np.isfinite(image)) and image.min() >= 0
    assert np.abs(result.full).max() < BLACK_TOLERANCE[name]  # a black input stays (near) black


@pytest.fixture(scope="module")
def validation_scene():
    """A validation scene rendered afresh with the settings recorded with the weights."""
    from mcbench.render.variants import pick_variant
    from mcbench.training_data import training_example

    data = read_json(record_path(COMMITTED_WEIGHTS, "kpcn"))["data"]
    features = trained_features(record_path(COMMITTED_WEIGHTS, "kpcn"))
    for name in LEARNED:
        other = read_json(record_path(COMMITTED_WEIGHTS, name))["data"]
        assert {k: other[k] for k in ("spp_levels", "resolution", "target_spp")} == \
               {k: data[k] for k in ("spp_levels", "resolution", "target_spp")}
        assert trained_features(record_path(COMMITTED_WEIGHTS, name)) == features
    if pick_variant("auto") == "scalar_rgb":
        pytest.skip("training renders need an LLVM or CUDA variant (libLLVM 19 missing)")
    seed = data["validation_scenes"][0]
    width, height = (int(v) for v in data["resolution"].split("x"))
    crops = training_example(seed, data["spp_levels"], int(data["target_spp"]), (width, height),
                             data["crop_size"], data["crops_per_scene"],
                             features=features)
    return seed, CropSet.from_layers(crops)


@pytest.mark.extended      # renders a validation scene afresh (about 4 minutes)
@pytest.mark.parametrize("name", LEARNED)
def test_committed_weights_reproduce_their_validation_loss(name, validation_scene):
    seed, crops = validation_scene
    record = read_json(record_path(COMMITTED_WEIGHTS, name))
    result = evaluate(load_network(load_method(name).METHOD, weights_path(COMMITTED_WEIGHTS, name)), crops, record["loss"])
    recorded = record["validation"]["per_scene"][str(seed)]
    assert result["loss"] == pytest.approx(recorded, rel=0.03)


def test_no_test_scene_is_a_training_scene():
    from mcbench.render.variants import pick_variant
    from mcbench.training_data import scene_fingerprint, training_scene_fingerprint
    from scenes import available_scenes, load_scene, scene_spec

    seeds = set()
    for name in LEARNED_METHODS:      # the learned combiners too
        data = read_json(record_path(COMMITTED_WEIGHTS, name))["data"]
        used = data["training_scenes"] + data["validation_scenes"]
        assert len(used) == len(set(used)) and not any(is_validation_seed(s) for s in data["training_scenes"])
        assert data["source"] == "procedural training scenes of mcbench.training_data (no test scene)"
        seeds.update(used)
    pick_variant("auto")
    tests = {scene_fingerprint(scene_spec(load_scene(scene)).build(16, 12)) for scene in available_scenes()}
    assert not tests & {training_scene_fingerprint(seed) for seed in seeds}
