"""The deep combiner of Back et al. 2020: its combination kernels (Eq. 8, Eq. 14) against
brute-force per-pixel loops of the paper's formulas, the unbiasedness and bias of Eq. 10 on
synthetic data with known statistics, the softmax weights, and the two method modules with
randomly initialised networks (no committed weights needed) on hard images and wrong inputs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

import methods.deep_combiner as single_module
import methods.deep_combiner_mb as multi_module
from mcbench import BenchError
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.nn.combination import (IMAGE_INPUT_CHANNELS, combination_weights, combine_multi, combine_single,
                                    image_inputs, window_neighbourhoods)
from mcbench.io.weights import COMMITTED_WEIGHTS
from mcbench.nn.inference import combine_with_network, combiner_image_tensors

MODULES = (single_module, multi_module)


# --- brute force of the paper's formulas ------------------------------------------------------

def brute_force_eq14(y_sub, z_sub, weights):
    """Eq. 14 (Eq. 4/8 for B = 1) pixel by pixel in float64: for each pixel c,
    Σ_b [w_cb y_cb + Σ_{i∈Ω_c} w_ib (y_ib + z_cb − z_ib)] / Σ_b (w_cb + Σ_{i∈Ω_c} w_ib), with Ω_c
    the k×k window (row-major over (dy, dx)) without c, cut to the image."""
    y_sub, z_sub, weights = (np.asarray(a, np.float64) for a in (y_sub, z_sub, weights))
    n, bins, channels, h, w = y_sub.shape
    k = int(round(np.sqrt(weights.shape[2])))
    r = k // 2
    out = np.zeros((n, channels, h, w))
    for m in range(n):
        for py in range(h):
            for px in range(w):
                numerator, total = np.zeros(channels), 0.0
                for b in range(bins):
                    w_c = weights[m, b, r * k + r, py, px]
                    numerator += w_c * y_sub[m, b, :, py, px]
                    total += w_c
                    for dy in range(-r, r + 1):
                        for dx in range(-r, r + 1):
                            qy, qx = py + dy, px + dx
                            if (dy, dx) == (0, 0) or not (0 <= qy < h and 0 <= qx < w):
                                continue
                            w_i = weights[m, b, (dy + r) * k + (dx + r), py, px]
                            numerator += w_i * (y_sub[m, b, :, qy, qx] + z_sub[m, b, :, py, px]
                                                - z_sub[m, b, :, qy, qx])
                            total += w_i
                out[m, :, py, px] = numerator / total
    return out


def random_case(rng, n=2, bins=1, h=6, w=7, k=5):
    y = torch.from_numpy(rng.uniform(0.0, 2.0, (n, bins, 3, h, w)))
    z = torch.from_numpy(rng.uniform(0.0, 2.0, (n, bins, 3, h, w)))
    weights = torch.from_numpy(rng.uniform(0.05, 3.0, (n, bins, k * k, h, w)))   # positive, not normalised
    return y, z, weights


def test_combine_single_is_eq4_by_brute_force_including_borders():
    rng = np.random.default_rng(1)
    y, z, weights = random_case(rng, k=5)
    result = combine_single(y[:, 0], z[:, 0], weights[:, 0])
    np.testing.assert_allclose(result.numpy(), brute_force_eq14(y, z, weights), rtol=1e-12, atol=1e-12)
    # the (N, 1, k², H, W) layout is the same kernel
    np.testing.assert_array_equal(combine_single(y[:, 0], z[:, 0], weights).numpy(), result.numpy())
    # a window larger than the image: every neighbour of a 3x4 image lies in a 15x15 window
    y, z, weights = random_case(rng, n=1, h=3, w=4, k=15)
    np.testing.assert_allclose(combine_single(y[:, 0], z[:, 0], weights[:, 0]).numpy(),
                               brute_force_eq14(y, z, weights), rtol=1e-12, atol=1e-12)


def test_combine_single_is_scale_invariant_and_handles_tiny_weights():
    rng = np.random.default_rng(2)
    y, z, weights = random_case(rng, k=3)
    reference = combine_single(y[:, 0], z[:, 0], weights[:, 0])
    for scale in (1e-300, 1e-310, 1e200):      # 1e-310 makes every weight subnormal
        # (subnormal weights themselves carry only ~44 bits: agreement to 1e-12, not to the last bit)
        np.testing.assert_allclose(combine_single(y[:, 0], z[:, 0], weights[:, 0] * scale).numpy(),
                                   reference.numpy(), rtol=1e-12, atol=1e-12)


def test_centre_weight_only_gives_y_exactly_and_an_empty_window_gives_y():
    rng = np.random.default_rng(3)
    y, z, _ = random_case(rng, k=5)
    centre_only = torch.zeros(2, 25, 6, 7, dtype=torch.float64)
    centre_only[:, 12] = 1.0
    assert torch.equal(combine_single(y[:, 0], z[:, 0], centre_only), y[:, 0])
    assert torch.equal(combine_single(y[:, 0], z[:, 0], 2.5 * centre_only), y[:, 0])
    # a window without any weight inside the image: no information, the independent estimate
    empty = torch.zeros(2, 25, 6, 7, dtype=torch.float64)
    empty[:, 0, 0, 0] = 5.0                    # neighbour (-2, -2) of pixel (0, 0): outside the image
    result = combine_single(y[:, 0], z[:, 0], empty)
    assert torch.isfinite(result).all()
    assert torch.equal(result, y[:, 0])
    # ... and for sub-buffers the mean of the y_b
    y2, z2, _ = random_case(rng, bins=2, k=5)
    result = combine_multi(y2, z2, torch.zeros(2, 2, 25, 6, 7, dtype=torch.float64))
    np.testing.assert_allclose(result.numpy(), y2.mean(dim=1).numpy(), rtol=1e-15)


def test_combine_multi_with_one_buffer_is_combine_single_and_is_eq14_by_brute_force():
    rng = np.random.default_rng(4)
    y, z, weights = random_case(rng, bins=1, k=5)
    assert torch.equal(combine_multi(y, z, weights), combine_single(y[:, 0], z[:, 0], weights[:, 0]))
    for bins in (2, 3):
        y, z, weights = random_case(rng, bins=bins, k=3, h=5, w=4)
        np.testing.assert_allclose(combine_multi(y, z, weights).numpy(), brute_force_eq14(y, z, weights),
                                   rtol=1e-12, atol=1e-12)


def test_two_identical_sub_buffers_are_one_buffer_with_the_summed_weights():
    """Eq. 14 with y_0 = y_1, z_0 = z_1 is Eq. 8 with w = w_0 + w_1 (an identity, not the code)."""
    rng = np.random.default_rng(5)
    y, z, weights = random_case(rng, bins=2, k=5)
    y[:, 1], z[:, 1] = y[:, 0], z[:, 0]
    np.testing.assert_allclose(combine_multi(y, z, weights).numpy(),
                               combine_single(y[:, 0], z[:, 0], weights.sum(dim=1)).numpy(), rtol=1e-12)


def test_kernels_refuse_negative_or_non_finite_weights_and_bad_shapes():
    rng = np.random.default_rng(6)
    y, z, weights = random_case(rng, k=3)
    for bad in (-1.0, float("nan"), float("inf")):
        broken = weights.clone()
        broken[0, 0, 4, 2, 2] = bad
        with pytest.raises(ValueError, match="finite and non-negative"):
            combine_multi(y, z, broken)
    with pytest.raises(ValueError, match="k×k"):
        combine_multi(y, z, weights[:, :, :8])
    with pytest.raises(ValueError, match="expected"):
        combination_weights(torch.zeros(1, 24, 4, 4), 5)


# --- Eq. 10: unbiased for unbiased differences, biased by exactly Eq. 10 otherwise ---------------

def blur3(noise):
    """Mean over each pixel's 3×3 window (zero padded): spatially correlated noise."""
    return window_neighbourhoods(noise, 3).mean(dim=2)


def test_unbiased_for_correlated_z_with_zero_mean_differences_and_biased_by_eq10_otherwise():
    rng = np.random.default_rng(7)
    draws, h, w, k = 6000, 6, 6, 5
    yy, xx = np.mgrid[0:h, 0:w]
    mu = torch.from_numpy(np.stack([0.5 + 0.1 * xx + 0.05 * yy, 1.0 + 0.2 * np.sin(xx), 0.3 + 0.0 * yy]))[None]
    weights = torch.from_numpy(rng.uniform(0.1, 2.0, (1, k * k, h, w))).expand(draws, -1, -1, -1)
    y = mu + 0.3 * torch.from_numpy(rng.standard_normal((draws, 3, h, w)))
    # z: mu + blurred (spatially correlated, zero-mean) noise + a per-image constant offset of mean
    # 0.5: z itself is biased by 0.5, but every difference z_c - z_i is unbiased
    offset = 0.5 + 0.2 * torch.from_numpy(rng.standard_normal((draws, 1, 1, 1)))
    z = mu + blur3(0.5 * torch.from_numpy(rng.standard_normal((draws, 3, h, w)))) + offset
    beta = combine_single(y, z, weights)
    mean, standard_error = beta.mean(dim=0), beta.std(dim=0) / np.sqrt(draws)
    assert torch.all((mean - mu[0]).abs() < 4.5 * standard_error)
    assert standard_error.max() < 0.01                     # the test has power
    assert torch.all((z.mean(dim=0) - mu[0] - 0.5).abs() < 0.02)   # while z is biased by 0.5

    # a biased z: E[z_c - z_i] - (mu_c - mu_i) = b_c - b_i != 0 for a bias field b
    bias_field = torch.from_numpy(0.4 * (xx > w // 2) + 0.1 * yy)[None, None].expand(1, 3, h, w)
    biased = combine_single(y, z + bias_field, weights)
    neighbours = window_neighbourhoods(bias_field, k)[0]                     # (3, k², H, W), 0 outside
    inside = window_neighbourhoods(torch.ones(1, 1, h, w, dtype=torch.float64), k)[0]
    w_fixed = weights[0] * inside[0]
    predicted = (w_fixed.unsqueeze(0) * (bias_field[0].unsqueeze(1) - neighbours)).sum(dim=1) / w_fixed.sum(dim=0)
    assert predicted.abs().max() > 0.05                    # a bias the test can see
    measured = biased.mean(dim=0) - mu[0]
    standard_error = biased.std(dim=0) / np.sqrt(draws)
    assert torch.all((measured - predicted).abs() < 4.5 * standard_error)


# --- softmax weights ------------------------------------------------------------------------------

@pytest.mark.parametrize("bins", [1, 2])
def test_combination_weights_are_positive_normalised_and_zero_outside(bins):
    k, h, w = 5, 4, 6
    generator = torch.Generator().manual_seed(8)
    for scale in (1.0, 1e4):
        logits = scale * (2 * torch.rand(3, bins * k * k, h, w, generator=generator) - 1)
        weights = combination_weights(logits, k, bins=bins)
        assert weights.shape == (3, bins, k * k, h, w)
        assert torch.isfinite(weights).all() and (weights >= 0).all()
        np.testing.assert_allclose(weights.sum(dim=(1, 2)).numpy(), 1.0, rtol=1e-6)
        r = k // 2
        for j in range(k * k):
            dy, dx = j // k - r, j % k - r
            for py in range(h):
                for px in range(w):
                    outside = not (0 <= py + dy < h and 0 <= px + dx < w)
                    values = weights[:, :, j, py, px]
                    if outside:
                        assert torch.all(values == 0)
                    elif scale == 1.0:
                        assert torch.all(values > 0)
    # equal logits: uniform over the entries inside the image (a corner pixel sees (r+1)² of them)
    uniform = combination_weights(torch.zeros(1, bins * k * k, h, w), k, bins=bins)
    np.testing.assert_allclose(uniform[0, :, :, 0, 0].sum().item(), 1.0, rtol=1e-6)
    assert torch.allclose(uniform[0, :, 2 * k + 2, 0, 0], torch.tensor(1.0 / (bins * 9)))


# --- the method modules with random networks ---------------------------------------------------

def with_bins_and_feature_variances(buffers: RenderBuffers, rng) -> RenderBuffers:
    """``buffers`` with four quarter-sample bins (color_a = (bin0 + bin1)/2 etc., full = (A + B)/2)
    and feature-variance layers for every image."""
    layers = dict(buffers.layers)
    for j in range(4):
        half = "_a" if j < 2 else "_b"
        noise = rng.standard_normal(layers["color"].shape) * 0.05
        layers[f"color_bin{j}"] = np.maximum(layers["color" + half] + noise, 0.0).astype(np.float32)
        layers[f"variance_bin{j}"] = (2 * layers["variance" + half]).astype(np.float32)
    layers["color_a"] = ((layers["color_bin0"] + layers["color_bin1"]) / 2).astype(np.float32)
    layers["color_b"] = ((layers["color_bin2"] + layers["color_bin3"]) / 2).astype(np.float32)
    layers["color"] = ((layers["color_a"] + layers["color_b"]) / 2).astype(np.float32)
    shape = layers["color"].shape
    for suffix in ("", "_a", "_b"):
        layers["albedo_variance" + suffix] = rng.uniform(0, 0.01, shape).astype(np.float32)
        layers["normal_variance" + suffix] = rng.uniform(0, 0.01, shape).astype(np.float32)
        layers["depth_variance" + suffix] = rng.uniform(0, 0.5, shape[:2]).astype(np.float32)
    return RenderBuffers(layers=layers, spp=buffers.spp, source="memory.exr")


def base_result(buffers: RenderBuffers, *, sub_outputs: bool = True) -> Denoised:
    """A stand-in base: each image (and each sub-buffer) box-blurred 3×3 -- correlated pixels."""
    def blur(image):
        tensor = torch.from_numpy(np.moveaxis(np.asarray(image, np.float64), 2, 0))[None]
        return np.moveaxis(blur3(tensor)[0].numpy(), 0, 2).astype(np.float32)

    extras = None
    if sub_outputs:
        names = {"full": ("color_sub0", "color_sub1"), "a": ("color_a_sub0", "color_a_sub1"),
                 "b": ("color_b_sub0", "color_b_sub1")}
        extras = {name: blur(sub[0]) for which, pair in names.items()
                  for name, sub in zip(pair, buffers.sub_images(which))}
    return Denoised(full=blur(buffers.color), a=blur(buffers.color_a), b=blur(buffers.color_b), extras=extras,
                    source="base.exr")


def random_network(module, seed=0):
    torch.manual_seed(seed)
    return module.build_network(**module.METHOD.learned.network).eval()


def hard_case(kind, make_render_buffers, rng):
    sizes = {"fireflies": (12, 10), "black": (9, 8), "1x1": (1, 1), "1x3": (1, 3)}
    h, w = sizes[kind]
    buffers = with_bins_and_feature_variances(make_render_buffers(height=h, width=w, half_std=0.05, seed=1), rng)
    if kind == "fireflies":
        layers = dict(buffers.layers)
        for name in ("color_bin0", "color_bin3"):
            layers[name] = layers[name].copy()
            layers[name][3, 4] = 1e6
            layers[name][0, 0] = 2e6
        for half, bins in (("_a", (0, 1)), ("_b", (2, 3))):
            layers["color" + half] = ((layers[f"color_bin{bins[0]}"] + layers[f"color_bin{bins[1]}"]) / 2)
        layers["color"] = (layers["color_a"] + layers["color_b"]) / 2
        layers["variance"] = np.where(layers["color"] > 1e4, 1e11, layers["variance"]).astype(np.float32)
        buffers = RenderBuffers(layers=layers, spp=buffers.spp, source=buffers.source)
    if kind == "black":
        buffers = RenderBuffers(layers={name: np.zeros_like(value) for name, value in buffers.layers.items()},
                                spp=buffers.spp, source=buffers.source)
    return buffers


@pytest.mark.parametrize("kind", ["fireflies", "black", "1x1", "1x3"])
@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_random_networks_are_finite_and_deterministic_on_hard_images(module, kind, make_render_buffers):
    rng = np.random.default_rng(9)
    buffers = hard_case(kind, make_render_buffers, rng)
    base = base_result(buffers)
    network = random_network(module)
    first = combine_with_network(module.METHOD, buffers, [base], network=network)
    second = combine_with_network(module.METHOD, buffers, [base], network=random_network(module))
    for which in ("full", "a", "b"):
        image = first.image(which)
        assert image.dtype == np.float32 and image.shape == buffers.shape + (3,)
        assert np.isfinite(image).all() and (image >= 0).all()
        np.testing.assert_array_equal(image, second.image(which))
    if kind == "black":
        assert np.all(first.full == 0)       # the weights are normalised: zero in, zero out


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_half_buffer_results_use_only_their_own_samples(module, make_render_buffers):
    rng = np.random.default_rng(10)
    buffers = with_bins_and_feature_variances(make_render_buffers(height=10, width=12, seed=2), rng)
    base = base_result(buffers)
    network = random_network(module, seed=3)
    before = combine_with_network(module.METHOD, buffers, [base], network=network)
    # change everything that belongs to B: its colour, bins, variances, features, the base's B results
    layers = {name: (value * 1.7 + 0.3).astype(np.float32)
              if name.endswith("_b") or name.endswith(("_bin2", "_bin3")) else value
              for name, value in buffers.layers.items()}
    changed = RenderBuffers(layers=layers, spp=buffers.spp, source=buffers.source)
    extras = {name: (value * 1.7 + 0.3).astype(np.float32) if name.startswith("color_b_") else value
              for name, value in base.extras.items()}
    changed_base = Denoised(full=base.full, a=base.a, b=base.b * 1.7 + 0.3, extras=extras, source=base.source)
    after = combine_with_network(module.METHOD, changed, [changed_base], network=network)
    np.testing.assert_array_equal(after.a, before.a)
    assert not np.array_equal(after.b, before.b)


def test_combiner_tensors_follow_the_training_keys(make_render_buffers):
    rng = np.random.default_rng(11)
    buffers = with_bins_and_feature_variances(make_render_buffers(height=5, width=6, seed=4), rng)
    base = base_result(buffers)
    tensors = combiner_image_tensors(buffers, [base], "a", multi_module.METHOD.learned.training_keys)
    for key, channels in multi_module.METHOD.learned.training_keys.items():
        assert tensors[key].shape == (1, channels, 5, 6) and tensors[key].dtype == torch.float32
    np.testing.assert_array_equal(tensors["color_sub"][0, 3:].permute(1, 2, 0).numpy(), buffers.color_bin1)
    np.testing.assert_array_equal(tensors["correlated_sub"][0, :3].permute(1, 2, 0).numpy(),
                                  base.extras["color_a_sub0"])
    np.testing.assert_array_equal(tensors["depth_variance"][0, 0].numpy(), buffers.layers["depth_variance_a"])
    assert image_inputs(tensors).shape == (1, IMAGE_INPUT_CHANNELS, 5, 6)
    without = RenderBuffers(layers={k: v for k, v in buffers.layers.items() if k != "normal_variance_b"},
                            spp=buffers.spp, source="render.exr")
    with pytest.raises(BenchError, match=r"render.exr: no layer 'normal_variance_b'"):
        combine_with_network(single_module.METHOD, without, [base], network=random_network(single_module))


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_combine_refuses_other_input_counts(module, make_render_buffers):
    buffers = with_bins_and_feature_variances(make_render_buffers(height=6, width=6), np.random.default_rng(12))
    base = base_result(buffers)
    name = module.__name__.split(".")[-1]
    for inputs in ([base, base], []):
        with pytest.raises(BenchError, match=rf"{name} combines exactly 1 .*got {len(inputs)}"):
            module.combine(buffers, inputs, weights_file=COMMITTED_WEIGHTS / f"{name}.pt")


def test_multi_buffer_combiner_refuses_renders_without_bins_and_bases_without_sub_outputs(make_render_buffers):
    buffers = with_bins_and_feature_variances(make_render_buffers(height=6, width=6), np.random.default_rng(13))
    no_bins = RenderBuffers(layers={k: v for k, v in buffers.layers.items() if "_bin" not in k}, spp=6,
                            source="renders/box/spp6.exr")
    with pytest.raises(BenchError, match=r"renders/box/spp6.exr: no sample bins"):
        multi_module.combine(no_bins, [base_result(buffers)], weights_file=COMMITTED_WEIGHTS / "deep_combiner_mb.pt")
    with pytest.raises(BenchError, match=r"base.exr: no sub-buffer results"):
        multi_module.combine(buffers, [base_result(buffers, sub_outputs=False)],
                             weights_file=COMMITTED_WEIGHTS / "deep_combiner_mb.pt")
    # the single-buffer combiner needs neither
    result = combine_with_network(single_module.METHOD, no_bins, [base_result(buffers, sub_outputs=False)],
                                  network=random_network(single_module))
    assert np.isfinite(result.full).all()


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_missing_weights_are_a_clear_error(module, make_render_buffers, tmp_path):
    buffers = with_bins_and_feature_variances(make_render_buffers(height=6, width=6), np.random.default_rng(14))
    name = module.__name__.split(".")[-1]
    with pytest.raises(BenchError, match=rf"{name}.pt: weights of '{name}' are missing; train them"):
        module.combine(buffers, [base_result(buffers)], weights_file=tmp_path / f"{name}.pt")


def test_module_declarations_and_parameter_counts():
    assert single_module.METHOD.kind == multi_module.METHOD.kind == "combiner"
    assert single_module.METHOD.inputs == multi_module.METHOD.inputs == 1
    assert set(single_module.METHOD.learned.training_keys) < set(multi_module.METHOD.learned.training_keys)
    from mcbench.nn.train import DEFAULT_SETTINGS, count_parameters
    for module in MODULES:
        assert set(module.METHOD.learned.training) <= set(DEFAULT_SETTINGS) and module.METHOD.learned.training["loss"] == "relmse"
        network = module.build_network(**module.METHOD.learned.network)
        assert 100_000 <= count_parameters(network) <= 250_000
        assert network.body[-1].out_channels % (module.METHOD.learned.network["window"] ** 2) == 0


def test_importing_the_modules_does_not_import_torch():
    code = ("import sys, methods.deep_combiner, methods.deep_combiner_mb; "
            "assert 'torch' not in sys.modules, 'torch imported'")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
