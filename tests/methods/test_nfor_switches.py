"""The Tungsten switches of methods/nfor.py on small synthetic inputs: the rank rule and the
errors of missing layers (the golden comparison is tests/methods/test_nfor_golden.py; the
regression's Tungsten weights are tested in tests/filters/test_nlmeans_tungsten.py)."""

import numpy as np
import pytest

from mcbench.io.buffers import RenderBuffers
from methods import nfor


def test_rank_threshold_drops_a_rounding_noise_column():
    """A feature column of 1e-12 noise next to position columns is a free regressor for the
    scaled Cholesky (pivot ~1) but falls under Eigen's rank rule (norm <= eps_32 x largest)."""
    rng = np.random.default_rng(5)
    n = 40
    x = np.stack([np.ones(n), rng.uniform(-9, 9, n), rng.uniform(-9, 9, n), 1e-12 * rng.standard_normal(n)], 1)
    y = rng.standard_normal((n, 1))
    a, b = x.T @ x, x.T @ y
    beta = np.zeros((4, 1))
    nfor._solve_normal_equations(a, b, 4, 1, 1e-9, beta, 0.0)
    assert beta[3, 0] != 0.0
    nfor._solve_normal_equations(a, b, 4, 1, 1e-9, beta, float(np.finfo(np.float32).eps) ** 2)
    assert beta[3, 0] == 0.0
    np.testing.assert_allclose(beta[:3], np.linalg.lstsq(x[:, :3], y, rcond=None)[0], rtol=1e-8)


def small_buffers(h=12, w=13, feature_variance=True):
    rng = np.random.default_rng(6)
    layers = {}
    for s in ("_a", "_b"):
        layers["color" + s] = rng.random((h, w, 3)).astype(np.float32)
        layers["variance" + s] = (0.01 * rng.random((h, w, 3))).astype(np.float32)
        layers["normal" + s] = rng.random((h, w, 3)).astype(np.float32)
        layers["albedo" + s] = rng.random((h, w, 3)).astype(np.float32)
        layers["depth" + s] = rng.random((h, w)).astype(np.float32)
    for q in ("color", "normal", "albedo", "depth"):
        layers[q] = (layers[q + "_a"] + layers[q + "_b"]) / np.float32(2)
    layers["variance"] = (layers["variance_a"] + layers["variance_b"]) / 4
    if feature_variance:
        for q in ("normal", "albedo", "depth"):
            layers[q + "_variance"] = ((layers[q + "_a"] - layers[q + "_b"]) ** 2 / 4).astype(np.float32)
    return RenderBuffers(layers, spp=8)


def test_the_paper_reading_settings_run_and_differ_from_the_defaults():
    buffers = small_buffers()
    ours = nfor.denoise(buffers, **nfor.PAPER_READING).full
    tungsten = nfor.denoise(buffers).full
    assert np.isfinite(tungsten).all() and tungsten.shape == ours.shape
    assert np.abs(tungsten - ours).max() > 1e-4


def test_buffer_feature_variance_needs_the_layers():
    with pytest.raises(ValueError, match=r"normal_variance.*feature_variance='halves'"):
        nfor.denoise(small_buffers(feature_variance=False))
    out = nfor.denoise(small_buffers(feature_variance=False), feature_variance="halves")
    assert np.isfinite(out.full).all()
    with pytest.raises(ValueError, match="feature_variance"):
        nfor.denoise(small_buffers(), feature_variance="pooled")
