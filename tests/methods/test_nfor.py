"""NFOR (methods/nfor.py) against independent truths: brute-force kernels, synthetic images
with known noise, noise-free input, spp consistency on renders, degenerate inputs."""

import numpy as np
import pytest

from mcbench.io.buffers import RenderBuffers
from mcbench.analysis.metrics import relmse
from mcbench.filters.nlmeans import nl_means_window_weights
from methods import load_method, nfor


def synthetic_scene(h=64, w=64):
    """Noise-free piecewise-smooth colour and the features explaining its edges.

    Two albedo regions (vertical edge at x = w/2) and a disk with a different normal; shading is
    a smooth gradient in position, colour = albedo * shading.
    """
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    albedo = np.where((x < w // 2)[..., None], [0.8, 0.3, 0.2], [0.2, 0.5, 0.9])
    disk = (x - 0.6 * w) ** 2 + (y - 0.4 * h) ** 2 < (0.22 * w) ** 2
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    normal[disk] = [0.6, 0.0, 0.8]
    shading = 0.3 + 0.7 * (x / w) * (1.0 - 0.5 * y / h)
    shading = np.where(disk, 1.5 * shading + 0.2, shading)
    depth = np.where(disk, 2.0, 5.0 + y / h)
    color = albedo * shading[..., None]
    return color, albedo, normal, depth


def mse(x, y):
    return float(np.mean((np.asarray(x, np.float64) - y) ** 2))


def test_registry_interface():
    module = load_method("nfor", kind="denoiser")
    assert module.METHOD.kind == "denoiser" and module.METHOD.label == "#4 NFOR"


def planes(array):
    return np.ascontiguousarray(np.moveaxis(array, 2, 0))


def test_regression_matches_brute_force_lstsq():
    rng = np.random.default_rng(2)
    h, w, r = 9, 11, 2
    guide, variance = rng.random((h, w, 3)), rng.random((h, w, 3)) * 0.05
    color, feat = rng.random((h, w, 3)), rng.random((h, w, 2))
    feat[..., 1] = 0.25  # a constant feature: rank-deficient normal equations
    got = nfor.collaborative_regression(color, guide, variance, feat, radius=r, patch_radius=1, k=0.7)
    weights = nl_means_window_weights(planes(guide), planes(variance), 0, h, r, 1, 0.7, 1.0, 1e-10, 1e4)
    num, den = np.zeros((h, w, 3)), np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            qs = [(qy, qx) for qy in range(max(0, y - r), min(h, y + r + 1))
                  for qx in range(max(0, x - r), min(w, x + r + 1))]
            wq = np.array([weights[y, x, (qy - y + r) * (2 * r + 1) + qx - x + r] for qy, qx in qs])
            design = np.array([[1.0, qx - x, qy - y, *(feat[qy, qx] - feat[y, x])] for qy, qx in qs])
            target = np.array([color[qy, qx] for qy, qx in qs])
            sw = np.sqrt(wq)[:, None]
            beta = np.linalg.lstsq(design * sw, target * sw, rcond=None)[0]
            for (qy, qx), wt, pred in zip(qs, wq, design @ beta):
                num[qy, qx] += wt * pred
                den[qy, qx] += wt
    np.testing.assert_allclose(got, num / den[..., None], atol=1e-10)


def test_synthetic_mse_five_times_below_noisy(make_render_buffers):
    truth, albedo, normal, depth = synthetic_scene()
    buffers = make_render_buffers(truth, albedo=albedo, normal=normal, depth=depth, half_std=0.1,
                                  spp=16)
    out = nfor.denoise(buffers)
    noisy = mse(buffers.color, truth)
    for name, image, reference_noisy in (("full", out.full, noisy),
                                         ("a", out.a, mse(buffers.color_a, truth)),
                                         ("b", out.b, mse(buffers.color_b, truth))):
        assert image.shape == truth.shape and image.dtype == np.float32
        assert np.isfinite(image).all()
        assert mse(image, truth) * 5 < reference_noisy, (name, mse(image, truth), reference_noisy)
    assert mse(out.full, truth) * 10 < noisy
    sel = out.extras["selection"]
    assert sel.shape == truth.shape and (sel >= 0).all() and (sel <= 1).all()


def test_noise_free_input_is_returned_unchanged(make_render_buffers):
    truth, albedo, normal, depth = synthetic_scene(32, 40)
    buffers = make_render_buffers(truth, albedo=albedo, normal=normal, depth=depth, half_std=0.0,
                                  spp=16)
    out = nfor.denoise(buffers)
    for image in (out.full, out.a, out.b):
        np.testing.assert_allclose(image, truth, rtol=1e-4, atol=1e-7)


def test_flat_black_and_fireflies_stay_finite(make_render_buffers):
    truth, albedo, normal, depth = synthetic_scene(40, 40)
    truth[:, :12] = 0.0
    buffers = make_render_buffers(truth, albedo=albedo, normal=normal, depth=depth, half_std=0.05,
                                  seed=3, spp=16)
    layers = dict(buffers.layers)
    for name in ("color", "color_a", "color_b", "variance", "variance_a", "variance_b"):
        layers[name] = layers[name].copy()
        layers[name][:, :12] = 0.0                      # flat black, zero variance
    layers["color_a"][20, 30] = 1e4                     # isolated fireflies
    layers["color_b"][5, 25] = 1e4
    layers["variance_a"][20, 30] = 1e7
    layers["color"] = (layers["color_a"] + layers["color_b"]) / 2
    layers["normal"][:, :12] = layers["normal_a"][:, :12] = layers["normal_b"][:, :12] = 0.0
    out = nfor.denoise(RenderBuffers(layers=layers, spp=16))
    for image in (out.full, out.a, out.b):
        assert np.isfinite(image).all()
        assert np.abs(image[:, :8]).max() < 1e-6      # black stays black away from the edge


def test_consistency_on_renders():
    """relMSE against a high-spp reference falls as spp grows."""
    from mcbench.render.renderer import merge_reference_chunks, render_buffers, render_reference_chunk
    from scenes import load_scene

    resolution = (40, 40)
    reference, _ = merge_reference_chunks(
        [render_reference_chunk(load_scene("cornell_box"), 4096, c, resolution=resolution) for c in range(2)])
    errors = []
    for spp in (16, 64, 256, 1024):
        layers, _ = render_buffers(load_scene("cornell_box"), spp, resolution=resolution)
        out = nfor.denoise(RenderBuffers(layers=layers, spp=spp))
        assert np.isfinite(out.full).all()
        errors.append(relmse(out.full, reference["color"]))
    assert all(e1 < e0 for e0, e1 in zip(errors, errors[1:])), errors


def test_stage_lines_on_large_images_only_and_outputs_unchanged(make_render_buffers, monkeypatch, capsys):
    """NFOR prints one line per stage with the elapsed time when the image has more than
    mcbench.progress.LARGE_IMAGE_PIXELS pixels (threshold lowered here to reach a small image),
    and stays quiet below it; the output is bit-identical either way."""
    import re

    import mcbench.progress as progress

    truth, albedo, normal, depth = synthetic_scene(16, 20)
    buffers = make_render_buffers(truth, albedo=albedo, normal=normal, depth=depth, half_std=0.05, spp=8)
    capsys.readouterr()
    quiet = nfor.denoise(buffers)
    assert capsys.readouterr().out == ""
    monkeypatch.setattr(progress, "LARGE_IMAGE_PIXELS", 16 * 20 - 1)
    loud = nfor.denoise(buffers)
    lines = capsys.readouterr().out.splitlines()
    stages = ["feature prefiltering (Sec. 5.1)", "regression of A and B at k = 0.5 (Sec. 5.2)",
              "regression of A and B at k = 1.0 (Sec. 5.2)", "MSE filtering and bandwidth selection (Sec. 5.3)",
              "second-pass features (Sec. 5.4)", "second-pass regression (Sec. 5.4)"]
    assert len(lines) == len(stages)
    for line, stage in zip(lines, stages):
        assert re.fullmatch(rf"nfor \(20x16\): {re.escape(stage)} done, elapsed \d+\.\d s", line), line
    for name in ("full", "a", "b"):
        np.testing.assert_array_equal(getattr(loud, name), getattr(quiet, name))


def test_regression_ignores_rounding_noise_in_constant_features():
    """A feature constant up to float64 rounding (1e-15 relative, as an NL-means prefilter of a
    constant region leaves it) regresses like the exactly constant feature: differences within
    nfor.FEATURE_RESOLUTION of zero count as 0 (before, the noise was a fitted regressor)."""
    rng = np.random.default_rng(4)
    h, w = 16, 15
    color = rng.random((h, w, 3))
    guide, variance = color + 0.05 * rng.random((h, w, 3)), np.full((h, w, 3), 0.01)
    feat = np.stack([rng.random((h, w)), np.full((h, w), 0.8)], axis=2)
    noisy = feat.copy()
    noisy[..., 1] *= 1 + 1e-15 * rng.standard_normal((h, w))
    exact = nfor.collaborative_regression(color, guide, variance, feat, radius=3, patch_radius=1, k=0.7)
    rounded = nfor.collaborative_regression(color, guide, variance, noisy, radius=3, patch_radius=1, k=0.7)
    np.testing.assert_allclose(rounded, exact, rtol=1e-12, atol=1e-12)
