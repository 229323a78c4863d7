"""The Tungsten switches of methods/nfor.py on small synthetic inputs: the regression's weights
with truncated patches and minimum per-channel weights against a brute-force loop, the rank rule,
and the errors of missing layers (the golden comparison is tests/methods/test_nfor_golden.py)."""

import numpy as np
import pytest

from mcbench.io.buffers import RenderBuffers
from methods import nfor


def planes(array):
    return np.ascontiguousarray(np.moveaxis(array, 2, 0))


def brute_weights(guide, variance, y, x, dy, dx, patch, k, eps, clamp):
    """min over channels of exp(-max(D_c, 0)), D_c the truncated patch mean of the clipped distance."""
    h, w, c = guide.shape
    total, count = np.zeros(c), 0
    for ny in range(-patch, patch + 1):
        for nx in range(-patch, patch + 1):
            py, px, qy, qx = y + ny, x + nx, y + ny + dy, x + nx + dx
            if not (0 <= py < h and 0 <= px < w and 0 <= qy < h and 0 <= qx < w):
                continue
            vp, vq = variance[py, px], variance[qy, qx]
            d = ((guide[py, px] - guide[qy, qx]) ** 2 - (vp + np.minimum(vp, vq))) / (eps + k * k * (vp + vq))
            total += np.minimum(d, clamp)
            count += 1
    return np.exp(-np.maximum(total / count, 0.0)).min()


def test_tungsten_regression_weights_match_brute_force():
    rng = np.random.default_rng(4)
    h, w, r, f = 8, 9, 2, 2
    guide, variance = rng.random((h, w, 3)), rng.random((h, w, 3)) * 0.03
    got = nfor.regression_weights(planes(guide), planes(variance), 0, h, r, f, 0.8, 1.0, 1e-7, 1e4, True, 1)
    side = 2 * r + 1
    for y in range(h):
        for x in range(w):
            for dy in range(-r, r + 1):
                for dx in range(-r, r + 1):
                    o = (dy + r) * side + dx + r
                    if 0 <= y + dy < h and 0 <= x + dx < w:
                        want = brute_weights(guide, variance, y, x, dy, dx, f, 0.8, 1e-7, 1e4)
                        assert got[y, x, o] == pytest.approx(want, rel=1e-10, abs=1e-300)
                    else:
                        assert got[y, x, o] == 0.0


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


def test_tungsten_switches_run_and_differ_from_defaults():
    buffers = small_buffers()
    ours = nfor.denoise(buffers).full
    tungsten = nfor.denoise(buffers, **nfor.TUNGSTEN).full
    assert np.isfinite(tungsten).all() and tungsten.shape == ours.shape
    assert np.abs(tungsten - ours).max() > 1e-4


def test_buffer_feature_variance_needs_the_layers():
    with pytest.raises(KeyError, match="normal_variance"):
        nfor.denoise(small_buffers(feature_variance=False), feature_variance="buffer")
    with pytest.raises(ValueError, match="feature_variance"):
        nfor.denoise(small_buffers(), feature_variance="pooled")
