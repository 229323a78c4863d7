"""The oracle study (Zheng et al. 2021 Sec. 5.2.7): the MSE-matrix accumulator against the analytic
matrix of synthetic Gaussian outputs, the three solvers against closed forms, brute force and a QP
solver, finite answers on singular matrices, and one tiny end-to-end run of the step."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest

from mcbench.combine.oracle_weights import (MseMatrixAccumulator, block_average, one_hot_weights, quadratic_objective,
                                            simplex_problem_weights, simplex_weights, unconstrained_problem_weights,
                                            unconstrained_weights)

# --------------------------------------------------------------------------- accumulator


def gaussian_problem(rng, shape=(6, 5, 3), n=3):
    """mu, biases b (N, H, W, C), noise factors L (H, W, C, N, N) and the analytic M = b b^T + L L^T."""
    mu = rng.uniform(0.1, 2.0, shape)
    bias = rng.normal(0.0, 0.3, (n,) + shape)
    factor = rng.normal(0.0, 0.4, shape + (n, n))
    sigma = factor @ np.swapaxes(factor, -1, -2)
    b = np.moveaxis(bias, 0, -1)
    return mu, bias, factor, b[..., :, None] * b[..., None, :] + sigma, sigma


def draw(rng, mu, bias, factor):
    noise = np.einsum("hwcij,hwcj->ihwc", factor, rng.standard_normal(mu.shape + (factor.shape[-1],)))
    return mu[None] + bias + noise


def accumulate(rng, mu, bias, factor, samples):
    acc = MseMatrixAccumulator(mu, count=bias.shape[0])
    for _ in range(samples):
        acc.add(draw(rng, mu, bias, factor))
    assert acc.samples == samples
    return acc.matrix()


def test_accumulator_converges_to_the_analytic_matrix():
    """y_i = mu + b_i + noise, noise ~ N(0, Sigma): M = b b^T + Sigma. Each estimated entry is a
    mean of R products u v of Gaussians (means m_u, m_v), whose variance is
    m_u^2 S_vv + m_v^2 S_uu + 2 m_u m_v S_uv + S_uu S_vv + S_uv^2: the z-scores are about standard
    normal, and the error shrinks like 1 / sqrt(R)."""
    rng = np.random.default_rng(7)
    mu, bias, factor, analytic, sigma = gaussian_problem(rng)
    b = np.moveaxis(bias, 0, -1)
    mi, mj = b[..., :, None], b[..., None, :]
    sii = np.diagonal(sigma, axis1=-2, axis2=-1)
    s_ii, s_jj = sii[..., :, None], sii[..., None, :]
    variance = mi ** 2 * s_jj + mj ** 2 * s_ii + 2 * mi * mj * sigma + s_ii * s_jj + sigma ** 2
    errors = {}
    for samples in (100, 1600):
        estimate = accumulate(rng, mu, bias, factor, samples)
        assert estimate.shape == analytic.shape
        np.testing.assert_allclose(estimate, np.swapaxes(estimate, -1, -2))  # symmetric
        z = (estimate - analytic) / np.sqrt(variance / samples)
        assert 0.8 < np.mean(z ** 2) < 1.2, np.mean(z ** 2)
        assert np.abs(z).max() < 5.0
        errors[samples] = np.sqrt(np.mean((estimate - analytic) ** 2))
    assert 3.0 < errors[100] / errors[1600] < 5.3, errors   # sqrt(16) = 4


def test_accumulator_is_exact_on_known_samples():
    """Two samples of two outputs: the mean of outer products, by hand."""
    mu = np.full((1, 1, 1), 1.0)
    acc = MseMatrixAccumulator(mu, count=2)
    acc.add(np.array([2.0, 0.0]).reshape(2, 1, 1, 1))   # errors (1, -1)
    acc.add(np.array([1.0, 4.0]).reshape(2, 1, 1, 1))   # errors (0, 3)
    np.testing.assert_allclose(acc.matrix()[0, 0, 0], [[0.5, -0.5], [-0.5, 5.0]])


def test_accumulator_refuses_bad_input():
    acc = MseMatrixAccumulator(np.zeros((2, 2, 3)), count=2)
    with pytest.raises(ValueError, match="no samples"):
        acc.matrix()
    with pytest.raises(ValueError, match="must be"):
        acc.add(np.zeros((3, 2, 2, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        acc.add(np.full((2, 2, 2, 3), np.nan))


# --------------------------------------------------------------------------- solvers


def random_psd(rng, count, n, rank=None):
    factor = rng.normal(size=(count, n, rank or n)) * rng.uniform(0.01, 3.0, (count, 1, 1))
    shift = rng.normal(size=(count, n, 1))                       # a bias outer product
    return factor @ np.swapaxes(factor, 1, 2) + shift @ np.swapaxes(shift, 1, 2)


def objective(w, m):
    return np.einsum("pi,pij,pj->p", w, m, w)


def test_unconstrained_equals_eq19_when_nonsingular():
    rng = np.random.default_rng(1)
    m = random_psd(rng, 200, 4)
    inverse_ones = np.linalg.solve(m, np.ones((200, 4, 1)))[..., 0]
    expected = inverse_ones / inverse_ones.sum(axis=1, keepdims=True)       # Eq. 19
    np.testing.assert_allclose(unconstrained_problem_weights(m), expected, rtol=1e-7, atol=1e-9)


def test_unconstrained_singular_is_the_minimum_norm_kkt_solution():
    """Rank-deficient M: the minimum-norm solution of the KKT system [[2M, 1], [1^T, 0]] restricted
    to the minimisers, compared with np.linalg.lstsq on the reduced problem."""
    rng = np.random.default_rng(2)
    for n, rank in ((3, 1), (4, 2)):
        factor = rng.normal(size=(50, n, rank))
        m = factor @ np.swapaxes(factor, 1, 2)
        w = unconstrained_problem_weights(m)
        np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
        # any other sum-to-one point: objective never lower (m is PSD, so check random ones)
        for _ in range(20):
            v = rng.normal(size=(50, n))
            v -= v.mean(axis=1, keepdims=True)
            assert np.all(objective(w + v, m) >= objective(w, m) - 1e-9 * np.trace(m, axis1=1, axis2=2))
        # minimum norm: w - 1/N is orthogonal to the null space of M within the plane sum = 0
        for p in range(50):
            basis = np.linalg.svd(np.vstack([factor[p].T, np.ones(n)]))[2][rank + 1:]
            np.testing.assert_allclose(basis @ (w[p] - 1.0 / n), 0.0, atol=1e-7)


def simplex_grid(n, steps):
    points = [c for c in itertools.product(range(steps + 1), repeat=n - 1) if sum(c) <= steps]
    grid = np.array([list(c) + [steps - sum(c)] for c in points], dtype=np.float64)
    return grid / steps


@pytest.mark.parametrize("n, steps", [(2, 2000), (3, 120), (4, 40)])
def test_simplex_matches_brute_force_and_qp(n, steps):
    """The exact support enumeration beats (or ties) every point of a dense simplex grid and is
    within the grid's resolution of its best; and equals quadprog's answer to 1e-8 (scaled)."""
    import qpsolvers

    rng = np.random.default_rng(3 + n)
    m = np.concatenate([random_psd(rng, 30, n), random_psd(rng, 10, n, rank=1)])
    w = simplex_problem_weights(m)
    assert np.all(w >= 0.0) and np.allclose(w.sum(axis=1), 1.0)
    grid = simplex_grid(n, steps)
    scale = np.diagonal(m, axis1=1, axis2=2).max(axis=1)
    for p in range(m.shape[0]):
        brute = np.einsum("gi,ij,gj->g", grid, m[p], grid).min()
        exact = objective(w[p:p + 1], m[p:p + 1])[0]
        assert exact <= brute + 1e-12 * scale[p]
        assert brute - exact <= 4.0 * n * scale[p] / steps    # a grid point within 1/steps per weight
        qp = qpsolvers.solve_qp(2 * m[p] / scale[p] + 1e-12 * np.eye(n), np.zeros(n), G=-np.eye(n),
                                h=np.zeros(n), A=np.ones((1, n)), b=np.ones(1), solver="quadprog")
        assert abs(exact - objective(qp[None], m[p:p + 1])[0]) / scale[p] < 1e-8


def test_simplex_equals_unconstrained_when_that_is_nonnegative_and_clips_otherwise():
    m = np.array([[[2.0, 0.0], [0.0, 1.0]],        # inverse-variance: w = (1/3, 2/3)
                  [[1.0, 2.0], [2.0, 5.0]]])       # unconstrained w = (1.5, -0.5) -> simplex (1, 0)
    np.testing.assert_allclose(unconstrained_problem_weights(m), [[1 / 3, 2 / 3], [1.5, -0.5]], atol=1e-12)
    np.testing.assert_allclose(simplex_problem_weights(m), [[1 / 3, 2 / 3], [1.0, 0.0]], atol=1e-12)


@pytest.mark.parametrize("matrix", [np.zeros((3, 3)), np.full((3, 3), 2.5), np.full((3, 3), 1e-310)],
                         ids=["zero noise, exact", "identical denoisers", "denormal"])
def test_singular_matrices_give_finite_equal_weights(matrix):
    """Identical denoisers (M = c 1 1^T) or perfect ones (M = 0): every weighting is optimal; the
    minimum-norm answer shares equally, finite, for all three solvers."""
    m = np.broadcast_to(matrix, (2, 2, 3, 3, 3))
    for solve in (unconstrained_weights, simplex_weights):
        w = solve(m)
        assert np.all(np.isfinite(w))
        np.testing.assert_allclose(w, 1.0 / 3.0, atol=1e-12)
    one_hot = one_hot_weights(m)
    assert np.all(one_hot[0] == 1.0) and np.all(one_hot[1:] == 0.0)   # ties: the first output


def test_one_hot_is_the_argmin_of_the_diagonal():
    rng = np.random.default_rng(4)
    m = random_psd(rng, 4 * 5 * 3, 3).reshape(4, 5, 3, 3, 3)
    w = one_hot_weights(m)
    diagonal = np.diagonal(m, axis1=3, axis2=4)
    for h, x, c in itertools.product(range(4), range(5), range(3)):
        expected = np.zeros(3)
        expected[np.argmin(diagonal[h, x, c])] = 1.0
        np.testing.assert_array_equal(w[:, h, x, c], expected)


def test_ordering_of_the_three_objectives():
    """On the same M: unconstrained <= simplex <= one-hot (each a subset of the previous feasible
    set), per pixel-channel; quadratic_objective agrees with a direct loop."""
    rng = np.random.default_rng(5)
    m = random_psd(rng, 3 * 4 * 3, 3).reshape(3, 4, 3, 3, 3)
    values = {name: quadratic_objective(solve(m), m) for name, solve in
              (("free", unconstrained_weights), ("simplex", simplex_weights), ("one_hot", one_hot_weights))}
    tolerance = 1e-10 * np.diagonal(m, axis1=3, axis2=4).max(axis=-1)
    assert np.all(values["free"] <= values["simplex"] + tolerance)
    assert np.all(values["simplex"] <= values["one_hot"] + tolerance)
    w = simplex_weights(m)
    direct = np.array([[[w[:, h, x, c] @ m[h, x, c] @ w[:, h, x, c] for c in range(3)] for x in range(4)]
                       for h in range(3)])
    np.testing.assert_allclose(values["simplex"], direct)


def test_block_average():
    image = np.arange(4 * 6 * 1, dtype=np.float64).reshape(4, 6, 1)
    out = block_average(image, 2)
    assert out.shape == (2, 3, 1)
    assert out[0, 0, 0] == np.mean([0, 1, 6, 7]) and out[1, 2, 0] == np.mean([16, 17, 22, 23])
    with pytest.raises(ValueError):
        block_average(image, 4)


# --------------------------------------------------------------------------- the step, end to end


def test_oracle_step_end_to_end(tmp_path):
    """16x16 (32x32 reference averaged 2x2), 4 spp, R = 4 + 1 held out, oidn and jbf: the nine
    panels and the context rows are finite, the ground-truth simplex weights beat one-hot on the
    matrix they were solved from, the files exist."""
    from mcbench.io.exr import write_layers
    from mcbench.render.renderer import merge_reference_chunks, render_reference_chunk
    from mcbench.pipeline.oracle import run_oracle_study
    from scenes import load_scene

    chunk = render_reference_chunk(load_scene("cornell_box"), 256, 0, resolution=(32, 32))
    layers, metadata = merge_reference_chunks([chunk])
    reference = tmp_path / "reference.exr"
    write_layers(str(reference), layers, metadata=metadata)
    paths = {key: str(tmp_path / name) for key, name in
             (("table_csv", "t.csv"), ("table_md", "t.md"), ("weights_png", "w.png"))}
    table = run_oracle_study("cornell_box", str(reference), denoisers=["oidn", "jbf"], repetitions=4, spp=4,
                             downscale=2, resolution=(32, 32), threads=1, **paths)
    assert list(table["panel"]) == list("abcdefghi") + ["-"] * 3
    assert np.all(np.isfinite(table[["relmse", "dssim"]].to_numpy()))
    assert pd.read_csv(paths["table_csv"]).shape == table.shape
    assert "Fig. 11" in open(paths["table_md"]).read()
    with open(paths["weights_png"], "rb") as handle:
        assert handle.read(8) == b"\x89PNG\r\n\x1a\n"


def test_oracle_size_divides_the_harness_resolution_and_names_the_key():
    from mcbench import BenchError
    from mcbench.pipeline.oracle import oracle_size

    assert oracle_size(None, (128, 96), 2) == (64, 48)
    assert oracle_size([32, 32], (128, 128), 1) == (32, 32)
    with pytest.raises(BenchError, match="oracle.downscale"):
        oracle_size(None, (128, 128), 3)
    with pytest.raises(BenchError, match="oracle.downscale.*11 pixels"):
        oracle_size([32, 32], (128, 128), 4)
