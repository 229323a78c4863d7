"""Progressive denoising (Firmino et al. 2022): SURE against the true MSE of a linear filter with a
known divergence, f_act and the t-test against hand-computed values and a brute-force loop of
Eq. 12-18, the swap augmentation, and the combiner on hard images (finite, deterministic)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mcbench.filters import sure

KERNEL = np.array([[0.05, 0.1, 0.05], [0.1, 0.4, 0.1], [0.05, 0.1, 0.05]])   # sums to 1, centre 0.4


def linear_filter(image: np.ndarray) -> np.ndarray:
    """3×3 convolution with KERNEL, periodic borders: F(x) = K x, ∂F_i/∂x_i = 0.4 everywhere."""
    image = np.asarray(image, np.float64)
    out = np.zeros_like(image)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out += KERNEL[dy + 1, dx + 1] * np.roll(image, (dy, dx), axis=(0, 1))
    return out


def truth_and_variance(h=24, w=20):
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    truth = np.stack([0.2 + 0.8 * (x > w / 2), 0.5 + 0.3 * np.sin(y / 3), 0.1 + 0.05 * x], axis=-1)
    variance = 0.01 + 0.05 * np.stack([x / w, y / h, np.ones_like(x) * 0.5], axis=-1)
    return truth, variance


def test_mc_divergence_of_a_linear_filter_is_its_known_divergence():
    """For a linear F the finite difference is exact and E[b_i (J b)_i] = J_ii σ_i²: the mean of
    many K=1 estimates converges to 0.4 σ² per pixel (tolerance: 5 standard errors)."""
    truth, variance = truth_and_variance()
    x = truth.astype(np.float32)
    runs = np.stack([sure.mc_divergence(linear_filter, x, variance, seed=s) for s in range(400)])
    expected = 0.4 * variance
    standard_error = runs.std(axis=0) / math.sqrt(len(runs))
    assert np.all(np.abs(runs.mean(axis=0) - expected) < 5 * standard_error + 1e-9)
    # the image mean of one K=4 estimate is already close (3600 independent terms)
    one = sure.mc_divergence(linear_filter, x, variance, iterations=4, seed=7)
    assert abs(one.mean() / expected.mean() - 1) < 0.05


def test_sure_is_unbiased_for_the_true_mse_of_a_linear_filter():
    """SURE with the Monte Carlo divergence (K = 1, ε = 1e-4 as the paper) against the closed-form
    MSE of F(x) = Kx, x ~ N(μ, σ²): E[(Kx − μ)²]_i = ((Kμ − μ)_i)² + Σ_j K_ij² σ_j²."""
    truth, variance = truth_and_variance()
    bias_sq = (linear_filter(truth) - truth) ** 2
    noise = np.zeros_like(truth)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            noise += KERNEL[dy + 1, dx + 1] ** 2 * np.roll(variance, (dy, dx), axis=(0, 1))
    true_mse = bias_sq + noise
    rng = np.random.default_rng(3)
    estimates, errors = [], []
    for trial in range(300):
        x = (truth + np.sqrt(variance) * rng.standard_normal(truth.shape)).astype(np.float32)
        y = linear_filter(x)
        d = sure.mc_divergence(linear_filter, x, variance, seed=(trial, 1), reference=y)
        terms = sure.sure_terms(x, y, variance, d)
        np.testing.assert_allclose(terms.sure, terms.residual_sq + 2 * terms.divergence - terms.variance)
        estimates.append(terms.sure)
        errors.append((y - truth) ** 2)
    estimates, errors = np.stack(estimates), np.stack(errors)
    # unbiased per pixel (5 standard errors) and for the image mean (within 3 %)
    standard_error = estimates.std(axis=0) / math.sqrt(len(estimates))
    assert np.all(np.abs(estimates.mean(axis=0) - true_mse) < 5 * standard_error)
    assert abs(estimates.mean() / true_mse.mean() - 1) < 0.03
    # the Monte Carlo check itself: the observed squared errors average to the closed form
    assert abs(errors.mean() / true_mse.mean() - 1) < 0.03
    # without the divergence term the estimate is biased low by 2 · 0.4 σ²
    assert (estimates.mean() - 2 * 0.4 * variance.mean()) < 0.5 * true_mse.mean()


def test_mc_divergence_is_reproducible_and_finite_on_black_and_firefly_pixels():
    truth, variance = truth_and_variance(8, 8)
    variance[:, :4] = 0.0
    truth[:, :4] = 0.0
    truth[2, 6] = 1e4
    variance[2, 6] = 1e8
    x = truth.astype(np.float32)
    a = sure.mc_divergence(linear_filter, x, variance, seed=5)
    b = sure.mc_divergence(linear_filter, x, variance, seed=5)
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()
    assert np.all(a[:, :4] == 0.0)     # no variance, no perturbation
    with pytest.raises(ValueError):
        sure.mc_divergence(linear_filter, x, variance, iterations=0)


# --- f_act (Eq. 19) and the mix (Eq. 11) -----------------------------------------------------

def test_f_act_against_hand_computed_values():
    np.testing.assert_allclose(sure.f_act(3.0, 1.0, 4.0), 0.5)
    np.testing.assert_allclose(sure.f_act(1.0, 3.0, 0.5), -4.0)
    np.testing.assert_allclose(sure.f_act(1.0, 0.5, 0.0), 0.5e6)        # max(0, 1e-6)
    np.testing.assert_allclose(sure.f_act(1.0, 0.5, -3.0), 0.5e6)       # a negative x3 is guarded too
    np.testing.assert_allclose(sure.f_act(2e-6, 1e-6, 1e-7), 1.0)
    np.testing.assert_allclose(sure.mixing_alpha([3.0, 1.0, 5.0], [1.0, 3.0, 0.0], [4.0, 0.5, 2.0]),
                               [0.5, 0.0, 1.0])
    assert np.isfinite(sure.f_act(1e308, -1e308, 1e-300))


def test_mix_and_its_swap():
    rng = np.random.default_rng(0)
    x, y, alpha = rng.uniform(0, 5, (3, 6, 7, 3))
    alpha = np.clip(alpha / 5, 0, 1)
    z = sure.mix(x, y, alpha)
    np.testing.assert_allclose(z, (1 - alpha) * x + alpha * y, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sure.mix(y, x, 1 - alpha), z, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(sure.mix(x, y, 0.0), x)
    np.testing.assert_allclose(sure.mix(x, y, 1.0), y, rtol=1e-15, atol=1e-15)


# --- the t-test (Eq. 12-18) ---------------------------------------------------------------------

def brute_force_t_test(x, y, variance, alpha, window, sigma_s, a=2.0, c=4.2, eps=1e-6):
    """Eq. 12-18 pixel by pixel, channel by channel, straight from the paper's formulas."""
    h, w, channels = x.shape
    r = window // 2
    out = np.zeros_like(x)
    t_out = np.zeros_like(x)
    z = x + alpha * (y - x)
    for py in range(h):
        for px in range(w):
            for ch in range(channels):
                neighbours = [(qy, qx) for qy in range(py - r, py + r + 1) for qx in range(px - r, px + r + 1)
                              if 0 <= qy < h and 0 <= qx < w]
                m = max(neighbours, key=lambda q: (variance[q[0], q[1], ch],
                                                   -neighbours.index(q)))     # first of the largest
                kappa = {q: math.exp(-((q[0] - py) ** 2 + (q[1] - px) ** 2) / (2 * sigma_s ** 2))
                         / (sigma_s * math.sqrt(2 * math.pi)) for q in neighbours}
                x_bar = x[m[0], m[1], ch] + sum(k * x[q[0], q[1], ch] for q, k in kappa.items())
                var_bar = variance[m[0], m[1], ch] + sum(k * k * variance[q[0], q[1], ch] for q, k in kappa.items())
                z_bar = z[m[0], m[1], ch] + sum(k * z[q[0], q[1], ch] for q, k in kappa.items())
                t = (z_bar - x_bar) / (math.sqrt(var_bar) + eps)
                phi = 0.5 * (1 + math.erf(a * (abs(t) - c) / math.sqrt(2)))
                out[py, px, ch] = (1 - phi) * alpha[py, px, ch]
                t_out[py, px, ch] = t
    return out, t_out


@pytest.mark.parametrize("sigma_s", [0.7, 2.0, 30.0])
def test_t_test_matches_a_brute_force_loop_of_eq12_to_18(sigma_s):
    rng = np.random.default_rng(11)
    h, w = 7, 9
    x = rng.uniform(0, 2, (h, w, 3))
    y = x + rng.normal(0, 0.3, (h, w, 3))
    variance = rng.uniform(0.001, 0.05, (h, w, 3))
    variance[3, 4, 1] = variance[3, 5, 1] = 0.2           # a tie in M_p: the first wins
    alpha = rng.uniform(0, 1, (h, w, 3))
    result = sure.t_test(x, y, variance, alpha, window=5, sigma_s=sigma_s)
    expected, t = brute_force_t_test(x, y, variance, alpha, 5, sigma_s)
    np.testing.assert_allclose(result.t, t, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(result.alpha, expected, rtol=1e-10, atol=1e-14)


def test_t_test_against_hand_computed_values():
    """A constant image, constant variance v and constant shift δ = α(y − x), window 3 and σ_s = 1:
    at the centre pixel Σκ = (1 + 4e^{-1/2} + 4e^{-1}) / sqrt(2π), Σκ² likewise squared terms;
    t = (1 + Σκ) δ / sqrt(v (1 + Σκ²)); choosing δ so that t = c = 4.2 gives α′ = α / 2."""
    e1, e2 = math.exp(-0.5), math.exp(-1.0)
    norm = 1 / math.sqrt(2 * math.pi)
    sum_k = norm * (1 + 4 * e1 + 4 * e2)
    sum_k2 = norm ** 2 * (1 + 4 * e1 ** 2 + 4 * e2 ** 2)
    v, alpha = 0.04, 0.8
    delta = 4.2 * math.sqrt(v * (1 + sum_k2)) / (1 + sum_k)   # (ε = 1e-6 changes t by < 1e-4)
    x = np.full((3, 3, 3), 0.5)
    y = x + delta / alpha
    result = sure.t_test(x, y, np.full_like(x, v), np.full_like(x, alpha), window=3, sigma_s=1.0)
    assert result.t[1, 1, 0] == pytest.approx(4.2, abs=1e-3)
    assert result.alpha[1, 1, 0] == pytest.approx(alpha / 2, abs=1e-3)
    # the factor 1 − Φ(2(|t| − 4.2)): ≈ 1 at t = 0, ≈ 0.5 at |t| = 4.2, ≈ 0 at |t| = 8
    factor = lambda t: 1 - 0.5 * (1 + math.erf(2 * (abs(t) - 4.2) / math.sqrt(2)))   # noqa: E731
    assert factor(0) == pytest.approx(1 - 1.3e-17, abs=1e-12)
    assert factor(-8) < 1e-13
    # no shift: t = 0, α′ = α (1 − Φ(−8.4))
    still = sure.t_test(x, x, np.full_like(x, v), np.full_like(x, alpha), window=3, sigma_s=1.0)
    np.testing.assert_allclose(still.t, 0.0)
    np.testing.assert_allclose(still.alpha, alpha * factor(0))


def test_spatial_sigma_and_kappa():
    assert sure.spatial_sigma(np.full((4, 4, 3), 0.04)) == pytest.approx(20.0)    # sqrt(0.04) × 100
    assert sure.spatial_sigma(np.full((4, 4, 3), 9.0)) == pytest.approx(100.0)    # min(·, 1) × 100
    assert sure.spatial_sigma(np.zeros((4, 4, 3))) == sure.MIN_SIGMA_S
    kappa = sure.gaussian_kappa(2.0, 11)
    assert kappa.shape == (11, 11) and kappa[5, 5] == pytest.approx(1 / (2 * math.sqrt(2 * math.pi)))
    assert kappa[5, 7] == pytest.approx(kappa[5, 5] * math.exp(-4 / 8))
    spike = sure.gaussian_kappa(sure.MIN_SIGMA_S, 11)
    assert np.isfinite(spike).all() and spike.sum() == spike[5, 5]
    with pytest.raises(ValueError):
        sure.gaussian_kappa(1.0, 4)


def test_t_test_is_finite_on_fireflies_and_black_regions_and_converges():
    rng = np.random.default_rng(2)
    x = rng.uniform(0, 1, (16, 16, 3))
    variance = np.full_like(x, 0.01)
    x[:, :8] = 0.0
    variance[:, :8] = 0.0
    x[3, 12] = 1e5
    variance[3, 12] = 1e10
    y = np.clip(x, 0, 1) * 0.9
    result = sure.t_test(x, y, variance, np.ones_like(x))
    for field in ("x_bar", "var_bar", "z_bar", "t", "scale", "alpha"):
        assert np.isfinite(getattr(result, field)).all(), field
    assert np.all((result.alpha >= 0) & (result.alpha <= 1))
    # consistency: a biased y against ever smaller variance is rejected (α′ → 0)
    truth = rng.uniform(0.2, 1, (16, 16, 3))
    biased = truth * 1.05
    scales = [sure.t_test(truth, biased, np.full_like(truth, v), np.ones_like(truth)).alpha.mean()
              for v in (1e-2, 1e-4, 1e-6)]
    assert scales[0] > 0.5 and scales[-1] < 1e-3 and scales[0] > scales[1] > scales[2]


# --- the network's inputs, the swap, f_act in torch ---------------------------------------------

def random_batch(rng, n=2, h=9, w=11):
    import torch

    x = rng.uniform(0, 3, (n, 3, h, w))
    y = x * rng.uniform(0.5, 1.5, (n, 3, h, w))
    variance = rng.uniform(0, 0.2, (n, 3, h, w))
    divergence = variance * rng.uniform(0, 1, (n, 3, h, w))
    return {k: torch.from_numpy(v).float() for k, v in
            dict(color=x, correlated=y, variance=variance, divergence=divergence).items()}


def random_network(**arch):
    import torch

    import methods.progressive as progressive

    torch.manual_seed(0)
    net = progressive.build_network(**{**progressive.METHOD.learned.network, **arch})
    with torch.no_grad():                       # a network whose α varies over [0, 1]
        net.conv_out.weight.mul_(30.0)
    return net.eval()


def test_network_inputs_follow_sec_4_3_and_the_swap_exchanges_the_pairs():
    import torch

    from mcbench.nn.progressive_mixing import network_inputs

    batch = random_batch(np.random.default_rng(1))
    x, y, v, d = (batch[k].double() for k in ("color", "correlated", "variance", "divergence"))
    inputs = network_inputs(x, y, v, d)
    terms = sure.sure_terms(x.numpy(), y.numpy(), v.numpy(), d.numpy())
    expected = [np.log1p(x.numpy()), np.log1p(y.numpy()), np.arctan(v.numpy()), np.arctan(terms.sure),
                np.arctan(d.numpy()), np.arctan(terms.residual_sq)]
    np.testing.assert_allclose(inputs.numpy(), np.concatenate(expected, axis=1), rtol=1e-12, atol=1e-12)
    swap = torch.tensor([1.0, 0.0]).view(2, 1, 1, 1)
    both = network_inputs(x, y, v, d, swap=swap).numpy()
    blocks = np.split(inputs.numpy(), 6, axis=1)
    swapped = np.concatenate([blocks[1], blocks[0], blocks[3], blocks[2], blocks[4], blocks[5]], axis=1)
    np.testing.assert_array_equal(both[0], swapped[0])       # HDR↔DEN, VAR↔SURE, the rest kept
    np.testing.assert_array_equal(both[1], inputs.numpy()[1])
    no_sure = network_inputs(x, y, v, d, sure_input=False).numpy()
    assert np.all(no_sure[:, 9:15] == 0) and np.array_equal(no_sure[:, :9], inputs.numpy()[:, :9])


def test_swap_mixes_towards_the_other_image_so_the_target_alpha_is_one_minus_alpha():
    """With the same inputs a swapped item's z is y + α_s (x − y): the network output that
    reproduces an unswapped z = x + α (y − x) is α_s = 1 − α (the augmentation's target)."""
    import torch

    from mcbench.nn.progressive_mixing import MixingNetwork

    net = random_network()
    batch = random_batch(np.random.default_rng(2))
    x, y = batch["color"].double(), batch["correlated"].double()
    with torch.no_grad():
        for flag in (0.0, 1.0):
            swap = torch.full((2, 1, 1, 1), flag)
            alpha = net.alpha(batch, swap).double()
            z = net({**batch, "swap": swap}).double()
            a, b = (y, x) if flag else (x, y)
            np.testing.assert_allclose(z.numpy(), (a + alpha * (b - a)).numpy(), rtol=1e-5, atol=1e-5)
            np.testing.assert_allclose(z.numpy(), sure.mix(x.numpy(), y.numpy(), (1 - alpha.numpy()) if flag
                                                           else alpha.numpy()), rtol=1e-5, atol=1e-5)
        assert isinstance(net, MixingNetwork)
        np.testing.assert_array_equal(net(batch).numpy(), net({**batch, "swap": torch.zeros(2, 1, 1, 1)}).numpy())


def test_torch_f_act_matches_numpy_and_alpha_is_clipped():
    import torch

    from mcbench.nn.progressive_mixing import f_act, mixing_alpha

    rng = np.random.default_rng(3)
    x1, x2, x3 = rng.normal(0, 1, (3, 4, 5))
    x3[0, 0] = 0.0
    x3[1, 1] = -2.0
    got = f_act(*(torch.from_numpy(a) for a in (x1, x2, x3))).numpy()
    np.testing.assert_allclose(got, sure.f_act(x1, x2, x3), rtol=1e-12)
    outputs = torch.from_numpy(np.concatenate([x1[None], x2[None], x3[None]]).repeat(3, axis=0)[None])
    alpha = mixing_alpha(outputs).numpy()
    np.testing.assert_allclose(alpha[0, 0], sure.mixing_alpha(x1, x2, x3), rtol=1e-12)
    direct = mixing_alpha(torch.from_numpy(rng.normal(0, 2, (1, 3, 4, 5))), use_f_act=False).numpy()
    assert direct.min() >= 0 and direct.max() <= 1


def test_initial_network_starts_near_alpha_one_half():
    import methods.progressive as progressive

    net = progressive.build_network(**progressive.METHOD.learned.network).eval()
    import torch
    with torch.no_grad():
        alpha = net.alpha(random_batch(np.random.default_rng(4)))
    assert 0.3 < float(alpha.mean()) < 0.7


# --- the combiner -------------------------------------------------------------------------------

def hard_cases(make_render_buffers):
    from tests.methods.test_contract import COMBINER_CASES, hard_case

    return {case: hard_case(case, make_render_buffers) for case in COMBINER_CASES}


@pytest.mark.parametrize("options", [dict(), dict(t_test=False), dict(divergence="jbf"),
                                     dict(divergence="oidn", iterations=2), dict(network=False),
                                     dict(sure_input=False, divergence="oidn"), dict(f_act=False)])
def test_combiner_is_finite_and_deterministic_on_hard_cases(make_render_buffers, options):
    import methods.progressive as progressive

    options = dict(options)
    variant = {k: options.pop(k) for k in ("sure_input", "f_act") if k in options}
    net = random_network(**variant) if options.pop("network", True) else None
    for case, (buffers, inputs) in hard_cases(make_render_buffers).items():
        first = progressive.combine_images(buffers, inputs[:1], net=net, **options)
        second = progressive.combine_images(buffers, inputs[:1], net=net, **options)
        for which in ("full", "a", "b"):
            image = first.image(which)
            assert image.shape == buffers.shape + (3,) and image.dtype == np.float32, (case, which)
            assert np.isfinite(image).all(), (case, which)
            np.testing.assert_array_equal(image, second.image(which), err_msg=f"{case} {which}")
            alpha = first.extras["alpha" + {"full": "", "a": "_a", "b": "_b"}[which]]
            assert np.all((alpha >= 0) & (alpha <= 1)), (case, which)


def test_each_half_uses_only_its_own_samples_and_base_result(make_render_buffers):
    """Changing B's samples and B's base result leaves A's output unchanged (and vice versa)."""
    import methods.progressive as progressive
    from mcbench.io.buffers import Denoised

    net = random_network()
    buffers = make_render_buffers(height=12, width=10, seed=1, bins=True)
    base = Denoised(buffers.color * 0.9, buffers.color_a * 0.9, buffers.color_b * 0.9)
    first = progressive.combine_images(buffers, [base], net=net, divergence="oidn")
    layers = dict(buffers.layers)
    layers["color_b"] = layers["color_b"] * 1.3
    layers["variance_b"] = layers["variance_b"] * 2.0
    changed = type(buffers)(layers=layers, spp=buffers.spp)
    second = progressive.combine_images(changed, [Denoised(base.full, base.a, base.b * 1.1)], net=net,
                                        divergence="oidn")
    np.testing.assert_array_equal(first.a, second.a)
    np.testing.assert_array_equal(first.full, second.full)
    assert not np.array_equal(first.b, second.b)


def test_t_test_only_mode_converges_to_the_noisy_image_when_the_base_is_biased(make_render_buffers):
    """network=False: α = 1 then Eq. 18; a strongly biased base is rejected where the noise is
    small, kept where it is large."""
    import methods.progressive as progressive
    from mcbench.io.buffers import Denoised

    low = make_render_buffers(height=24, width=24, seed=5, half_std=1e-3)
    high = make_render_buffers(height=24, width=24, seed=5, half_std=0.5)
    for buffers, expected in ((low, "x"), (high, "y")):
        biased = Denoised(*(img * 1.2 + 0.05 for img in (buffers.color, buffers.color_a, buffers.color_b)))
        z = progressive.combine_images(buffers, [biased], net=None).full
        target = buffers.color if expected == "x" else biased.full
        assert np.abs(z - target).mean() < 0.05 * np.abs(buffers.color - biased.full).mean(), expected


def test_divergence_bases_and_their_refusals():
    import methods.progressive as progressive
    from methods import check_params, single_image_function, single_image_methods
    from mcbench import BenchError
    from mcbench.io.weights import COMMITTED_WEIGHTS

    assert single_image_methods() == ("jbf", "kpcn", "mcgan", "oidn", "optix_ae", "wskpn")
    assert callable(single_image_function("oidn", weights_dir=COMMITTED_WEIGHTS))
    assert callable(single_image_function("jbf", weights_dir=COMMITTED_WEIGHTS))
    assert callable(single_image_function("kpcn", weights_dir=COMMITTED_WEIGHTS))
    with pytest.raises(BenchError, match="no single-image function.*one of jbf, kpcn"):
        single_image_function("nfor", weights_dir=COMMITTED_WEIGHTS)
    with pytest.raises(BenchError):
        progressive.combine(None, [], iterations=0, weights_file=COMMITTED_WEIGHTS / "progressive.pt")
    check_params(progressive, {"divergence": "kpcn"}, config_key="combiners[0].params")
    with pytest.raises(BenchError, match=r"combiners\[0\]\.params\.divergence: 'nfor' is not allowed for "
                                         r"progressive; expected one of 'none' or a single-image denoiser \(jbf, kpcn"):
        check_params(progressive, {"divergence": "nfor"}, config_key="combiners[0].params")


def test_importing_the_method_does_not_import_torch():
    import subprocess
    import sys

    code = "import sys, methods.progressive, mcbench.filters.sure; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_ablation_variants_are_other_networks_with_their_own_weights():
    import methods.progressive as progressive
    from mcbench import BenchError

    module = progressive.variant_module("no_sure")
    assert module.__name__ == "methods.progressive_no_sure" and module.METHOD.learned.network["sure_input"] is False
    assert module.METHOD.learned.build_network(**module.METHOD.learned.network).sure_input is False
    no_fact = progressive.variant_module("no_fact").METHOD
    assert no_fact.learned.build_network(**no_fact.learned.network).conv_out.out_channels == 3
    assert no_fact.label == f"{progressive.METHOD.label}, ablation no_fact" and no_fact.run is progressive.combine
    full = Path("w/progressive.pt")
    assert progressive.ablation_weights_path(full, sure_input=True, f_act=True) == full
    assert progressive.ablation_weights_path(full, sure_input=False, f_act=True) == Path("w/progressive_no_sure.pt")
    assert progressive.ablation_weights_path(full, sure_input=True, f_act=False) == Path("w/progressive_no_fact.pt")
    with pytest.raises(BenchError):
        progressive.variant_module("no_t_test")


def test_stacks_over_an_ensemble(make_render_buffers):
    """Progressive with an ensemble's result as its denoised input (OIDN's divergence as the
    proxy, the documented choice): finite, each image from its own samples."""
    import methods.ensemble as ensemble
    import methods.progressive as progressive
    from tests.methods.test_contract import synthetic_inputs

    buffers = make_render_buffers(height=16, width=14, seed=6, bins=True)
    ens = ensemble.combine(buffers, synthetic_inputs(buffers))
    result = progressive.combine_images(buffers, [ens], net=random_network(), divergence="oidn")
    for which in ("full", "a", "b"):
        assert np.isfinite(result.image(which)).all()
        alpha = result.extras["alpha" + {"full": "", "a": "_a", "b": "_b"}[which]]
        np.testing.assert_allclose(result.image(which), sure.mix(buffers.image(which).color, ens.image(which), alpha),
                                   rtol=1e-5, atol=1e-6)
