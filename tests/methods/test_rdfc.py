"""RDFC (methods/rdfc.py): denoising gain, identity on noise-free input, SURE unbiasedness,
analytic derivative vs finite differences, consistency with spp on a render, robustness."""

from __future__ import annotations

import numpy as np
import pytest

from mcbench.io.buffers import Denoised, RenderBuffers
from methods import load_method, rdfc

SMALL_RADIUS = 4   # window radius for the kernel-level tests (fast; the math is radius-independent)


def piecewise_smooth(h=64, w=64):
    """Two smooth colour regions split by a slanted edge; albedo marks the regions."""
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    region = xx + 0.3 * yy > 0.6
    truth = np.where(region[..., None],
                     np.stack([0.8 * xx + 0.1, 0.3 + 0.4 * yy, 0.5 + 0 * xx], -1),
                     np.stack([0.2 + 0.1 * yy, 0.6 + 0 * xx, 0.1 + 0.5 * xx], -1))
    albedo = np.where(region[..., None], [0.8, 0.3, 0.5], [0.2, 0.6, 0.1])
    return truth, albedo


def flat_features(h, w):
    """The features the RDFC tests use: no normal or depth edges (+z normals, depth 1)."""
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    return dict(normal=normal, depth=np.ones((h, w)))


def test_registered_and_interface():
    module = load_method("rdfc", "denoiser")
    assert module.METHOD.label == "#8 RDFC"


def test_denoises_synthetic_image_5x(make_render_buffers):
    truth, albedo = piecewise_smooth()
    buffers = make_render_buffers(truth, albedo=albedo, **flat_features(*truth.shape[:2]),
                                  half_std=np.sqrt(0.02), seed=1, spp=4)
    out = rdfc.denoise(buffers)
    assert isinstance(out, Denoised)
    for image in (out.full, out.a, out.b):
        assert image.shape == truth.shape and image.dtype == np.float32
        assert np.all(np.isfinite(image))
    mse_noisy = np.mean((buffers.color - truth) ** 2)
    mse_out = np.mean((out.full - truth) ** 2)
    assert mse_out * 5 < mse_noisy, (mse_out, mse_noisy)
    for which in ("a", "b"):
        assert np.mean((getattr(out, which) - truth) ** 2) * 5 < np.mean((getattr(buffers, "color_" + which) - truth) ** 2)
    np.testing.assert_allclose(out.full, (out.a.astype(np.float64) + out.b) / 2, rtol=1e-6, atol=1e-7)


def test_noise_free_input_is_returned(make_render_buffers):
    truth, albedo = piecewise_smooth(40, 40)
    buffers = make_render_buffers(truth, albedo=albedo, **flat_features(40, 40), half_std=0.0,
                                  spp=4)
    out = rdfc.denoise(buffers)
    for image in (out.full, out.a, out.b):
        np.testing.assert_allclose(image, truth, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("guided", [False, True])
def test_sure_matches_true_mse(guided):
    """Mean SURE over pixels and realisations equals the mean true squared error of each
    candidate, self-guided (pass 1, weights depend on y) and guided by an independent image."""
    truth, albedo = piecewise_smooth(32, 32)
    sigma2 = 0.01
    rng = np.random.default_rng(7)
    variance = np.full(truth.shape, sigma2)
    estimates, trues = [], []
    for _ in range(80):
        y = truth + rng.normal(size=truth.shape) * np.sqrt(sigma2)
        kwargs = {}
        if guided:
            kwargs = dict(guide=truth + rng.normal(size=truth.shape) * 0.05,
                          guide_variance=np.full(truth.shape, 0.0025))
        filtered, deriv, _ = rdfc.candidate_filters(y, variance, [albedo], [np.zeros(truth.shape[:2])],
                                                    radius=SMALL_RADIUS, **kwargs)
        estimates.append(rdfc.sure(filtered, deriv, y, variance).mean(axis=(1, 2, 3)))
        trues.append(((filtered - truth) ** 2).mean(axis=(1, 2, 3)))
    diffs = np.array(estimates) - np.array(trues)      # (realisations, candidates)
    true = np.mean(trues, axis=0)
    assert np.all(true < sigma2 / 5)                    # every candidate denoises
    mean, se = diffs.mean(axis=0), diffs.std(axis=0, ddof=1) / np.sqrt(len(diffs))
    assert np.all(se < 0.1 * true)                      # the test has power
    assert np.all(np.abs(mean) < 4 * se), (mean, se, true)


def test_derivative_matches_finite_difference():
    rng = np.random.default_rng(3)
    truth, albedo = piecewise_smooth(20, 20)
    y = truth + rng.normal(size=truth.shape) * 0.1
    variance = np.full(truth.shape, 0.01)
    feats, fvars = [albedo, np.ones((20, 20))], [np.zeros((20, 20)), np.zeros((20, 20))]
    _, deriv, _ = rdfc.candidate_filters(y, variance, feats, fvars, radius=3)
    step = 1e-6
    for py, px, c in [(0, 0, 0), (5, 7, 1), (10, 10, 2), (19, 3, 0), (12, 19, 1)]:
        up, down = y.copy(), y.copy()
        up[py, px, c] += step
        down[py, px, c] -= step
        f_up = rdfc.candidate_filters(up, variance, feats, fvars, radius=3)[0]
        f_down = rdfc.candidate_filters(down, variance, feats, fvars, radius=3)[0]
        numeric = (f_up - f_down)[:, py, px, c] / (2 * step)
        np.testing.assert_allclose(deriv[:, py, px, c], numeric, rtol=1e-4, atol=1e-7)


def test_flat_black_and_fireflies_stay_finite(make_render_buffers):
    h = w = 32
    black = np.zeros((h, w, 3))
    layers = dict(make_render_buffers(black, albedo=black, normal=black, depth=black[..., 0],
                                      half_std=0.0, spp=2).layers)
    layers["color_a"][5, 5] = 1e4
    layers["variance_a"][5, 5] = 1e8
    layers["color_b"][20, 9, 1] = 1e4            # firefly with (wrongly) zero variance
    layers["color"] = (layers["color_a"] + layers["color_b"]) / 2
    out = rdfc.denoise(RenderBuffers(layers=layers, spp=2))
    for image in (out.full, out.a, out.b):
        assert image.shape == (h, w, 3) and image.dtype == np.float32
        assert np.all(np.isfinite(image))
        assert np.abs(image).max() <= 1e4
    # beyond the filter window (r = 10) plus the selection filter (r = 3), black stays black;
    # nearer, the second pass (guided by the other, firefly-free buffer) may spread a firefly
    assert np.abs(out.full[:, 25:]).max() == 0.0


@pytest.fixture(scope="module")
def cornell_series():
    from mcbench.render.renderer import merge_reference_chunks, render_buffers, render_reference_chunk
    from scenes import load_scene
    resolution = (48, 48)
    reference, _ = merge_reference_chunks([render_reference_chunk(load_scene("cornell_box"), 4096, chunk, resolution=resolution)
                                           for chunk in range(2)])
    renders = {spp: RenderBuffers(layers=render_buffers(load_scene("cornell_box"), spp, resolution=resolution)[0], spp=spp)
               for spp in (16, 64, 256, 1024)}
    return reference["color"], renders


def test_consistency_relmse_decreases_with_spp(cornell_series):
    from mcbench.analysis.metrics import relmse
    reference, renders = cornell_series
    errors = {spp: relmse(rdfc.denoise(b).full, reference) for spp, b in renders.items()}
    noisy = {spp: relmse(b.color, reference) for spp, b in renders.items()}
    spps = sorted(errors)
    assert all(errors[a] > errors[b] for a, b in zip(spps, spps[1:])), errors
    assert errors[16] < noisy[16], (errors, noisy)


def test_tiling_is_exact():
    rng = np.random.default_rng(5)
    truth, albedo = piecewise_smooth(45, 38)
    y = truth + rng.normal(size=truth.shape) * 0.1
    variance = np.full(truth.shape, 0.01)
    args = (y, variance, [albedo], [np.zeros(truth.shape[:2])])
    whole = rdfc.candidate_filters(*args, radius=3, tile=None)
    tiled = rdfc.candidate_filters(*args, radius=3, tile=16)
    for a, b in zip(whole, tiled):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)


def test_stage_lines_on_large_images_only_and_outputs_unchanged(make_render_buffers, monkeypatch, capsys):
    """RDFC prints one line per stage (prefilter, two passes per half buffer) with elapsed time
    above mcbench.progress.LARGE_IMAGE_PIXELS pixels (lowered here), nothing below; output
    bit-identical either way."""
    import re

    import mcbench.progress as progress

    truth, albedo = piecewise_smooth(12, 14)
    buffers = make_render_buffers(truth, albedo=albedo, **flat_features(12, 14), half_std=0.05, spp=4)
    outputs, printed = [], []
    for threshold in (progress.LARGE_IMAGE_PIXELS, 12 * 14 - 1):
        monkeypatch.setattr(progress, "LARGE_IMAGE_PIXELS", threshold)
        capsys.readouterr()
        outputs.append(rdfc.denoise(buffers, radius=SMALL_RADIUS))
        printed.append(capsys.readouterr().out.splitlines())
    assert printed[0] == []
    stages = ["feature prefiltering", "first pass of half buffer A", "first pass of half buffer B",
              "second pass"]
    assert len(printed[1]) == len(stages)
    for line, stage in zip(printed[1], stages):
        assert re.fullmatch(rf"rdfc \(14x12\): {stage} done, elapsed \d+\.\d s", line), line
    for name in ("full", "a", "b"):
        np.testing.assert_array_equal(getattr(outputs[1], name), getattr(outputs[0], name))


def brute_force_candidates(y, v, features, feature_variances, guide, guide_variance, radius, patch_radii,
                           k_colors, k_f=rdfc.K_FEATURE, tau=rdfc.TAU, alpha=rdfc.ALPHA, eps=rdfc.EPSILON):
    """Per-pixel loops over the module docstring's equations: F_k(p) = sum_q w y_q / sum_q w and
    sum w^2 V / (sum w)^2, w = min(w_c, w_f), patch distances over the in-image pairs."""
    h, w, _ = y.shape
    norms = [rdfc.feature_normaliser(f, fv, k_f, tau) for f, fv in zip(features, feature_variances)]

    def delta(n, m, kc):
        vp, vq = guide_variance[n], guide_variance[m]
        return np.mean(((guide[n] - guide[m]) ** 2 - alpha * (vp + np.minimum(vp, vq))) / (eps + kc * kc * (vp + vq)))

    filtered = np.zeros((len(patch_radii), h, w, 3))
    variance = np.zeros_like(filtered)
    for k, (f, kc) in enumerate(zip(patch_radii, k_colors)):
        for py in range(h):
            for px in range(w):
                num, num_var, den = np.zeros(3), np.zeros(3), 0.0
                for qy in range(max(0, py - radius), min(h, py + radius + 1)):
                    for qx in range(max(0, px - radius), min(w, px + radius + 1)):
                        dfeat = 0.0
                        for feat, fvar, norm in zip(features, feature_variances, norms):
                            dist = np.mean((feat[py, px] - feat[qy, qx]) ** 2)
                            vp = fvar[py, px]
                            dfeat = max(dfeat, (dist - (vp + min(vp, fvar[qy, qx]))) / norm[py, px])
                        weight = np.exp(-dfeat)
                        if np.isfinite(kc):
                            terms = [delta((ny, nx), (ny + qy - py, nx + qx - px), kc)
                                     for ny in range(max(0, py - f), min(h, py + f + 1))
                                     for nx in range(max(0, px - f), min(w, px + f + 1))
                                     if 0 <= ny + qy - py < h and 0 <= nx + qx - px < w]
                            weight = min(weight, np.exp(-max(0.0, np.mean(terms))))
                        num += weight * y[qy, qx]
                        num_var += weight ** 2 * v[qy, qx]
                        den += weight
                filtered[k, py, px] = num / den
                variance[k, py, px] = num_var / den ** 2
    return filtered, variance


@pytest.mark.parametrize("guided", [False, True])
def test_kernel_matches_brute_force_equations(guided):
    """The compiled candidate filters against per-pixel loops on small random inputs (noisy
    features with variance, a zero-variance corner), FIRST/SECOND/THIRD-like candidates;
    the self-guided derivative against central differences of the brute force at pixel p."""
    rng = np.random.default_rng(11)
    h, w, radius, patch_radii, k_colors = 9, 8, 2, (1, 2, 0), (0.45, 0.45, np.inf)
    y = rng.random((h, w, 3))
    v = rng.random((h, w, 3)) * 0.02
    v[:2, :3] = 0.0
    features = [rng.random((h, w, 3)) * 0.3, rng.random((h, w))]
    feature_variances = [rng.random((h, w)) * 0.01, np.zeros((h, w))]
    guide, guide_variance = (y + 0.05 * rng.random(y.shape), v * 0.5) if guided else (y, v)
    kwargs = dict(guide=guide, guide_variance=guide_variance) if guided else {}
    filtered, derivative, out_var = rdfc.candidate_filters(y, v, features, feature_variances, radius=radius,
                                                           patch_radii=patch_radii, k_colors=k_colors, **kwargs)
    expected, expected_var = brute_force_candidates(y, v, [f if f.ndim == 3 else f[..., None] for f in features],
                                                    feature_variances, guide, guide_variance, radius, patch_radii,
                                                    k_colors)
    np.testing.assert_allclose(filtered, expected, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(out_var, expected_var, rtol=1e-10, atol=1e-14)
    step = 1e-6
    for py, px, c in ((4, 4, 0), (0, 0, 1), (8, 7, 2), (1, 1, 2)):
        plus, minus = y.copy(), y.copy()
        plus[py, px, c] += step
        minus[py, px, c] -= step
        g_plus, g_minus = (guide, guide) if guided else (plus, minus)
        f_plus = brute_force_candidates(plus, v, [features[0], features[1][..., None]], feature_variances, g_plus,
                                        guide_variance, radius, patch_radii, k_colors)[0]
        f_minus = brute_force_candidates(minus, v, [features[0], features[1][..., None]], feature_variances,
                                         g_minus, guide_variance, radius, patch_radii, k_colors)[0]
        numeric = (f_plus[:, py, px, c] - f_minus[:, py, px, c]) / (2 * step)
        np.testing.assert_allclose(derivative[:, py, px, c], numeric, rtol=1e-5, atol=1e-7)
