"""Tests of the ensemble's ablation options (Zheng et al. 2021 Sec. 5.2.1-5.2.4) against
independent truth: unconstrained weights against the paper's Eq. 19 built element-wise from
Eq. 11-12 and against np.linalg on the equality-constrained least squares (exact, minimum
norm, or with a vanishing ridge); weights shared by the channels against a brute-force search
of a fine simplex grid and against quadprog on the channel-summed <M>; the general QP solver
against the exact one; robustness on fireflies, black pixels and 1 x 1 images; and the
defaults leaving ``combine`` unchanged."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import qpsolvers

from mcbench.combine.blending import blend, combine_with
from mcbench.combine.ensemble_weights import CHANNELS, WEIGHTS, solve_weights
from mcbench.combine.simplex_solvers.problem import SOLVERS, objective
from mcbench.combine.weight_filter import PAPER_FILTER, PUBLIC_CODE_FILTER, filter_weights
from mcbench.io.buffers import Denoised
from methods import ensemble as E


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def as_problems(points, bs):
    """K one-channel problems: points (K, N, 2) a_i = (y_i^A, y_i^B), bs (K, 2) b = (x^B, x^A).
    Returns color_a, color_b (1, K, 1) and denoised_a, denoised_b (N, 1, K, 1)."""
    points = np.asarray(points, np.float64)
    bs = np.asarray(bs, np.float64)
    ya = points[:, :, 0].T[:, None, :, None]
    yb = points[:, :, 1].T[:, None, :, None]
    return bs[:, 1][None, :, None], bs[:, 0][None, :, None], ya, yb


def mse_matrix(xa, xb, ya, yb):
    """<M> of one pixel-channel written out from Eq. 11-12. xa, xb scalars; ya, yb (N,)."""
    ma = xa * xb - xb * (ya[:, None] + ya[None, :]) + np.outer(ya, ya)
    mb = xa * xb - xa * (yb[:, None] + yb[None, :]) + np.outer(yb, yb)
    return 0.5 * (ma + mb)


def pixel_problems(rng, n, count, kind):
    """RGB pixels: color_a, color_b (1, K, 3), denoised_a, denoised_b (n, 1, K, 3).
    ``random``: standard normals; ``realistic``: biased, slightly noisy denoisers of a
    radiance around 0.5 whose halves have std 0.2."""
    if kind == "random":
        xa, xb = rng.normal(size=(2, 1, count, 3))
        ya, yb = rng.normal(size=(2, n, 1, count, 3))
        return xa, xb, ya, yb
    truth = rng.uniform(0.2, 1.0, (1, count, 3))
    xa = truth + rng.normal(0, 0.2, truth.shape)
    xb = truth + rng.normal(0, 0.2, truth.shape)
    bias = rng.normal(0, 0.05, (n, 1, 1, 3))
    ya = truth + bias + rng.normal(0, 0.03, (n,) + truth.shape)
    yb = truth + bias + rng.normal(0, 0.03, (n,) + truth.shape)
    return xa, xb, ya, yb


def summed_objective(weights, xa, xb, ya, yb):
    """Channel-summed Eq. 13 per pixel: weights (N, H, W) or (N, H, W, C). Returns (H, W)."""
    w = np.asarray(weights, np.float64)
    if w.ndim == 3:
        w = np.broadcast_to(w[..., None], ya.shape)
    return objective(w, xa, xb, ya, yb).sum(axis=-1)


def pixel_scale2(xa, xb, ya, yb, axis=None):
    """max(|x|, |y|)^2 over the pixel's channels (axis=-1) or its pixel-channel (None)."""
    s = np.maximum(np.maximum(np.abs(xa), np.abs(xb)),
                   np.maximum(np.abs(ya).max(axis=0), np.abs(yb).max(axis=0)))
    if axis is not None:
        s = s.max(axis=axis)
    return np.maximum(s, 1e-30) ** 2


def assert_sum_one(w, atol=1e-9):
    assert np.all(np.isfinite(w))
    np.testing.assert_allclose(w.sum(axis=0), 1.0, atol=atol)


def assert_shared_by_channels(w):
    for c in range(1, w.shape[-1]):
        assert np.array_equal(w[..., c], w[..., 0])


# ---------------------------------------------------------------------------------------
# unconstrained weights (Sec. 5.2.1)
# ---------------------------------------------------------------------------------------
def test_unconstrained_two_denoisers_equal_eq19():
    """N = 2: <M> (Eq. 11-12) is non-singular; the weights are Eq. 19,
    w = M^-1 1 / (1^T M^-1 1), and take negative values on some pixel-channels."""
    rng = np.random.default_rng(1)
    m = 300
    pts = rng.normal(size=(m, 2, 2))
    bs = rng.normal(size=(m, 2)) * 1.5
    xa, xb, ya, yb = as_problems(pts, bs)
    got = solve_weights(xa, xb, ya, yb, weights="unconstrained")[:, 0, :, 0]
    expected = np.empty((2, m))
    for k in range(m):
        M = mse_matrix(xa[0, k, 0], xb[0, k, 0], ya[:, 0, k, 0], yb[:, 0, k, 0])
        v = np.linalg.solve(M, np.ones(2))
        expected[:, k] = v / v.sum()
    np.testing.assert_allclose(got, expected, rtol=1e-8, atol=1e-8)
    assert (got < -0.05).any(), "no negative weight: the constraint would not matter"


def test_unconstrained_equals_equality_constrained_least_squares():
    """N = 3..8, points in general position: b is reachable (A w = b), the weights are the
    minimum-norm solution of [A; 1^T] w = [b; 1] (np.linalg.lstsq; the exact solve for N = 3)
    and the objective reaches its lower bound -1/2 (x^A - x^B)^2 (Eq. 25)."""
    rng = np.random.default_rng(2)
    for n in range(3, 9):
        m = 40
        pts = rng.normal(size=(m, n, 2))
        bs = rng.normal(size=(m, 2)) * 2.0
        xa, xb, ya, yb = as_problems(pts, bs)
        w = solve_weights(xa, xb, ya, yb, weights="unconstrained")
        for k in range(m):
            system = np.vstack([pts[k].T, np.ones((1, n))])
            rhs = np.concatenate([bs[k], [1.0]])
            ref = (np.linalg.solve(system, rhs) if n == 3
                   else np.linalg.lstsq(system, rhs, rcond=None)[0])
            np.testing.assert_allclose(w[:, 0, k, 0], ref, atol=1e-9, err_msg=f"n={n}")
        bound = -0.5 * (xa - xb) ** 2
        np.testing.assert_allclose(objective(w, xa, xb, ya, yb), bound, atol=1e-9)


def ridge_kkt(points, target, ridge):
    """argmin 1/2 |A w - b|^2 + ridge/2 |w|^2 s.t. sum w = 1 (KKT solve); points (N, D)."""
    n = points.shape[0]
    kkt = np.block([[points @ points.T + ridge * np.eye(n), np.ones((n, 1))],
                    [np.ones((1, n)), np.zeros((1, 1))]])
    return np.linalg.solve(kkt, np.concatenate([points @ target, [1.0]]))[:n]


def min_norm_on_sum_one(points, target):
    """Minimum-norm minimiser of 1/2 |A w - b|^2 s.t. sum w = 1 by another route: w = 1/N +
    Z c with Z an orthonormal basis of 1^perp (QR), c the minimum-norm least-squares solution
    of A Z c = b - A 1/N (np.linalg.lstsq); |w|^2 = 1/N + |c|^2, so min |c| is min |w|."""
    n = points.shape[0]
    q, _ = np.linalg.qr(np.column_stack([np.ones(n), np.eye(n)[:, :n - 1]]))
    Z = q[:, 1:]
    A = points.T
    c = np.linalg.lstsq(A @ Z, target - A @ np.full(n, 1.0 / n), rcond=1e-9)[0]
    return 1.0 / n + Z @ c


@pytest.mark.parametrize("kind", ["collinear", "duplicates"])
def test_unconstrained_singular_is_the_minimum_norm_limit(kind):
    """b outside the points' affine hull (collinear points, coincident ones): M is singular
    and the minimisers form a line; the weights are its minimum-norm point (computed by an
    orthonormal parametrisation of sum w = 1 and np.linalg.lstsq)."""
    rng = np.random.default_rng(3)
    for t in range(40):
        n = int(rng.integers(3, 8))
        if kind == "collinear":
            direction = rng.normal(size=2)
            pts = rng.normal(size=(n, 1)) * direction + rng.normal(size=2)
        else:
            pts = rng.normal(size=(n, 2))
            pts[1:] = pts[0] + 1e-3 * (np.arange(1, n) % 2)[:, None] * [1.0, -1.0]
            pts[2:] = pts[1]
        b = rng.normal(size=2) * 2
        xa, xb, ya, yb = as_problems(pts[None], b[None])
        got = solve_weights(xa, xb, ya, yb, weights="unconstrained")[:, 0, 0, 0]
        s = max(np.abs(pts).max(), np.abs(b).max())
        ref = min_norm_on_sum_one(pts / s, b / s)
        np.testing.assert_allclose(got, ref, atol=1e-8 * max(1.0, np.abs(ref).max()),
                                   err_msg=f"{kind} {t}")
        assert got.sum() == pytest.approx(1.0, abs=1e-12 * max(1.0, np.abs(ref).max()))


def test_unconstrained_single_channel_equals_kkt():
    """Weights shared by RGB, no sign constraint: the channel-summed problem is the least
    squares in 6-D; with N <= 7 points in general position the KKT system of
    min 1/2 |A w - b|^2 s.t. sum w = 1 is non-singular, solved by np.linalg."""
    rng = np.random.default_rng(4)
    for n in range(2, 8):
        xa, xb, ya, yb = pixel_problems(rng, n, 30, "random")
        w = solve_weights(xa, xb, ya, yb, weights="unconstrained", channels="single")
        assert_shared_by_channels(w)
        for k in range(30):
            points = np.concatenate([ya[:, 0, k], yb[:, 0, k]], axis=1)   # (N, 6)
            target = np.concatenate([xb[0, k], xa[0, k]])
            ref = ridge_kkt(points, target, 0.0)
            np.testing.assert_allclose(w[:, 0, k, 0], ref, atol=1e-8, err_msg=f"n={n}")


@pytest.mark.parametrize("channels", CHANNELS)
def test_unconstrained_never_above_simplex_optimum(channels):
    """Dropping w >= 0 can only lower the objective (a larger feasible set); the exact
    simplex solution is the reference; on these realistic problems some weights are negative
    and some pixels strictly gain."""
    rng = np.random.default_rng(5)
    xa, xb, ya, yb = pixel_problems(rng, 4, 400, "realistic")
    wu = solve_weights(xa, xb, ya, yb, weights="unconstrained", channels=channels)
    ws = solve_weights(xa, xb, ya, yb, solver="exact", channels=channels)
    assert_sum_one(wu)
    fu = summed_objective(wu, xa, xb, ya, yb)
    fs = summed_objective(ws, xa, xb, ya, yb)
    s2 = pixel_scale2(xa, xb, ya, yb, axis=-1)
    assert np.all(fu <= fs + 1e-10 * s2)
    assert np.mean(fu < fs - 1e-6 * s2) > 0.2
    assert (wu < 0).any()


# ---------------------------------------------------------------------------------------
# weights shared by the channels (Sec. 5.2.3)
# ---------------------------------------------------------------------------------------
def simplex_grid(steps):
    """All (w1, w2, w3) = (i, j, steps - i - j) / steps on the 2-simplex: (G, 3)."""
    i, j = np.meshgrid(np.arange(steps + 1), np.arange(steps + 1), indexing="ij")
    keep = i + j <= steps
    return np.stack([i[keep], j[keep], steps - i[keep] - j[keep]], -1) / steps


@pytest.mark.parametrize("solver", SOLVERS)
def test_single_channel_equals_brute_force_simplex_grid(solver):
    """N = 3: the shared weights minimise the channel-summed Eq. 13 (with <M> from Eq. 11-12
    per channel) over a fine grid of the simplex (step 1/600): never above the grid's best
    point, and below it by no more than the grid's resolution allows. The iterative solver with
    away steps (with the paper's alpha in [0, 1] it approaches the optimum only geometrically,
    tests/combine/test_ensemble.py::test_iterative_reaches_the_optimum_on_99_percent)."""
    rng = np.random.default_rng(6)
    count = 12
    xa, xb, ya, yb = pixel_problems(rng, 3, count, "random")
    w = solve_weights(xa, xb, ya, yb, solver=solver, channels="single", away_steps=True)
    assert_shared_by_channels(w)
    assert w.min() >= 0.0
    assert_sum_one(w)
    grid = simplex_grid(600)
    for k in range(count):
        Ms = [mse_matrix(xa[0, k, c], xb[0, k, c], ya[:, 0, k, c], yb[:, 0, k, c])
              for c in range(3)]
        M = sum(Ms)
        values = np.einsum("gi,ij,gj->g", grid, M, grid)
        got = float(w[:, 0, k, 0] @ M @ w[:, 0, k, 0])
        s2 = pixel_scale2(xa[:, k], xb[:, k], ya[:, :, k], yb[:, :, k]).max()
        tol = 1e-6 if solver == "iterative" else 1e-9
        assert got <= values.min() + tol * s2, (k, got, values.min())
        # the grid's best point is within the grid's resolution of the optimum: the
        # objective's curvature times (1/600)^2
        assert values.min() - got <= np.abs(M).sum() * (1 / 600) ** 2, (k, got, values.min())


def summed_qp_optimum(xa, xb, ya, yb):
    """quadprog on Eq. 14 summed over the channels: P = sum_c (y^A y^A^T + y^B y^B^T),
    q = -sum_c (x^A y^B + x^B y^A) (ridge 1e-10 max|P|); xa, xb (C,), ya, yb (N, C)."""
    n = ya.shape[0]
    P = ya @ ya.T + yb @ yb.T
    q = -(yb @ xa + ya @ xb)
    s = max(np.abs(P).max(), 1e-30)
    w = qpsolvers.solve_qp(P / s + 1e-10 * np.eye(n), q / s, G=-np.eye(n), h=np.zeros(n),
                           A=np.ones((1, n)), b=np.ones(1), solver="quadprog")
    w = np.clip(w, 0, None)
    return w / w.sum()


@pytest.mark.parametrize("kind", ["random", "realistic"])
def test_single_channel_exact_matches_quadprog_on_summed_mse(kind):
    """N = 2..8: the exact shared weights' objective equals (within 1e-8 s^2) that of
    quadprog on the paper's Eq. 14 summed over the channels, both evaluated with <M> of
    Eq. 11-12 written out."""
    rng = np.random.default_rng(7)
    for n in range(2, 9):
        xa, xb, ya, yb = pixel_problems(rng, n, 25, kind)
        w = solve_weights(xa, xb, ya, yb, solver="exact", channels="single")
        for k in range(25):
            M = sum(mse_matrix(xa[0, k, c], xb[0, k, c], ya[:, 0, k, c], yb[:, 0, k, c])
                    for c in range(3))
            ref = summed_qp_optimum(xa[0, k], xb[0, k], ya[:, 0, k], yb[:, 0, k])
            got = w[:, 0, k, 0]
            s2 = pixel_scale2(xa[:, k], xb[:, k], ya[:, :, k], yb[:, :, k]).max()
            assert got @ M @ got <= ref @ M @ ref + 1e-8 * s2, (n, k)
            assert got @ M @ got >= ref @ M @ ref - 1e-8 * s2, (n, k)


def test_single_channel_exact_identical_outputs_share_equally():
    """Identical base outputs are one point of the hull: the exact shared weights split its
    weight equally (all identical: 1/N, like the per-channel exact solver) and stay optimal
    (quadprog on Eq. 14)."""
    rng = np.random.default_rng(13)
    xa, xb, ya, yb = pixel_problems(rng, 5, 40, "realistic")
    ya[3], yb[3] = ya[1], yb[1]
    ya[4], yb[4] = ya[1], yb[1]
    w = solve_weights(xa, xb, ya, yb, solver="exact", channels="single")
    np.testing.assert_array_equal(w[3], w[1])
    np.testing.assert_array_equal(w[4], w[1])
    assert (w[1] > 0.05).any()
    f = summed_objective(w, xa, xb, ya, yb)[0]
    s2 = pixel_scale2(xa, xb, ya, yb, axis=-1)[0]
    for k in range(40):
        ref = summed_qp_optimum(xa[0, k], xb[0, k], ya[:, 0, k], yb[:, 0, k])
        f_ref = summed_objective(ref[:, None, None], xa[:, k:k + 1], xb[:, k:k + 1],
                                 ya[:, :, k:k + 1], yb[:, :, k:k + 1])[0, 0]
        assert f[k] <= f_ref + 1e-8 * s2[k]
    same = solve_weights(xa, xb, np.repeat(ya[:1], 4, 0), np.repeat(yb[:1], 4, 0),
                           solver="exact", channels="single")
    np.testing.assert_allclose(same, 0.25, atol=1e-15)


def test_single_channel_costs_objective_against_channel_wise():
    """Shared weights are a restriction of channel-wise ones: the summed optimum can only
    rise, and it does where the denoisers' colour biases differ per channel."""
    rng = np.random.default_rng(8)
    xa, xb, ya, yb = pixel_problems(rng, 3, 300, "realistic")
    f_single = summed_objective(solve_weights(xa, xb, ya, yb, solver="exact",
                                                channels="single"), xa, xb, ya, yb)
    f_rgb = summed_objective(solve_weights(xa, xb, ya, yb, solver="exact"), xa, xb, ya, yb)
    s2 = pixel_scale2(xa, xb, ya, yb, axis=-1)
    assert np.all(f_rgb <= f_single + 1e-10 * s2)
    assert np.mean(f_single > f_rgb + 1e-6 * s2) > 0.5


# ---------------------------------------------------------------------------------------
# the general QP solver (Sec. 5.2.2, Fig. 6)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("channels", CHANNELS)
@pytest.mark.parametrize("kind", ["random", "realistic"])
def test_qp_solver_objective_matches_exact(channels, kind):
    """Objective of solver="qp" within 1e-8 of the exact solver's, in units of the pixel's
    (or pixel-channel's) scale^2, for N = 2..8; weights on the simplex."""
    rng = np.random.default_rng(9)
    axis = -1 if channels == "single" else None
    for n in range(2, 9):
        xa, xb, ya, yb = pixel_problems(rng, n, 20, kind)
        wq = solve_weights(xa, xb, ya, yb, solver="qp", channels=channels)
        we = solve_weights(xa, xb, ya, yb, solver="exact", channels=channels)
        assert wq.min() >= 0.0
        assert_sum_one(wq)
        if channels == "single":
            fq, fe = summed_objective(wq, xa, xb, ya, yb), summed_objective(we, xa, xb, ya, yb)
        else:
            fq, fe = objective(wq, xa, xb, ya, yb), objective(we, xa, xb, ya, yb)
        gap = (fq - fe) / pixel_scale2(xa, xb, ya, yb, axis=axis)
        assert np.abs(gap).max() <= 1e-8, (n, np.abs(gap).max())


# ---------------------------------------------------------------------------------------
# robustness and the unchanged defaults
# ---------------------------------------------------------------------------------------
OPTIONS = list(itertools.product(SOLVERS, WEIGHTS, CHANNELS))


@pytest.mark.parametrize("solver,weights,channels", OPTIONS)
def test_finite_on_fireflies_black_and_1x1(solver, weights, channels, make_render_buffers):
    """Every option: finite weights summing to one (non-negative for the simplex) and finite
    combined images, with fireflies (1e6), black pixels, identical outputs and a 1 x 1 image."""
    rng = np.random.default_rng(10)
    H, W, n = 6, 7, 4
    truth = rng.uniform(0.1, 1.0, (H, W, 3))
    truth[1, 1] = 0.0
    buffers = make_render_buffers(truth, half_std=0.1, seed=rng)
    buffers.color_a[1, 1] = buffers.color_b[1, 1] = 0.0           # black pixel
    buffers.color_a[2, 2] = 1e6                                    # firefly
    ys = {k: np.clip(truth + rng.normal(0, 0.05, (n, H, W, 3)), 0, None) for k in "fab"}
    for y in ys.values():
        y[:, 1, 1] = 0.0
        y[:, 0, 0] = y[0, 0, 0]                                    # identical outputs
    ys["b"][1, 3, 3] = 1e6
    inputs = [Denoised(full=ys["f"][i].astype(np.float32), a=ys["a"][i].astype(np.float32),
                       b=ys["b"][i].astype(np.float32)) for i in range(n)]
    options = dict(solver=solver, weights=weights, channels=channels)
    w = solve_weights(buffers.color_a, buffers.color_b, ys["a"], ys["b"], **options)
    # rounding of the sum is relative to the weights' size (unconstrained: up to ~1e9 here)
    assert_sum_one(w, atol=1e-12 * max(1.0, np.abs(w).max()))
    if weights == "simplex":
        assert w.min() >= 0.0
    out = E.combine(buffers, inputs, **options)
    for image in (out.full, out.a, out.b):
        assert image.shape == (H, W, 3) and np.isfinite(image).all()
    tiny = make_render_buffers(np.full((1, 1, 3), 0.5), half_std=0.1, seed=1)
    tiny_inputs = [Denoised(full=d.full[:1, :1], a=d.a[:1, :1], b=d.b[:1, :1]) for d in inputs]
    small = E.combine(tiny, tiny_inputs, **options)
    assert small.full.shape == (1, 1, 3) and np.isfinite(small.full).all()
    one = solve_weights(buffers.color_a, buffers.color_b, ys["a"][:1], ys["b"][:1], **options)
    assert np.array_equal(one, np.ones((1, H, W, 3)))


def test_unconstrained_filter_keeps_negative_weights(make_render_buffers):
    """With weights="unconstrained" the weight filter averages without clipping: filtered
    weights sum to one and stay negative where the raw ones are all negative nearby."""
    rng = np.random.default_rng(11)
    H, W, n = 12, 12, 3
    truth = np.full((H, W, 3), 0.5)
    buffers = make_render_buffers(truth, half_std=0.01, seed=rng)
    bias = np.array([0.2, 0.1, -0.05])[:, None, None, None]        # denoiser 0 worst
    ys = [truth + bias + rng.normal(0, 0.002, (n, H, W, 3)) for _ in range(3)]
    inputs = [Denoised(full=ys[0][i].astype(np.float32), a=ys[1][i].astype(np.float32),
                       b=ys[2][i].astype(np.float32)) for i in range(n)]
    y_full, y_a, y_b = (np.stack([np.asarray(getattr(d, k), np.float64) for d in inputs])
                        for k in ("full", "a", "b"))
    raw = solve_weights(buffers.color_a, buffers.color_b, y_a, y_b, weights="unconstrained")
    filt = filter_weights(raw, y_full, y_a, y_b, buffers.albedo, buffers.normal,
                            nonnegative=False)
    np.testing.assert_allclose(filt.sum(axis=0), 1.0, atol=1e-12 * np.abs(raw).max())
    out = E.combine(buffers, inputs, weights="unconstrained", **PAPER_FILTER)
    filt32 = filter_weights(raw, y_full, y_a, y_b, buffers.albedo, buffers.normal,
                              nonnegative=False, dtype=np.float32)   # combine's precision
    for i in range(n):
        assert np.array_equal(out.extras[f"weights_filtered_{i}"], filt32[i])
    np.testing.assert_allclose(filt32, filt, rtol=0, atol=1e-5 * np.abs(raw).max())
    assert (raw.min(axis=0) < -0.1).mean() > 0.5
    assert (filt.min(axis=0) < -0.1).mean() > 0.5


def test_defaults_are_the_measured_filter(make_render_buffers):
    """The defaults (iterative solver, simplex, per-channel weights, filter with the public
    code's details where the text is silent: the standardised normal, guide-variance blur, its
    outlier pass, reflected borders, the 1e-6 floor; the paper's alpha in [0, 1];
    methods/ensemble.py docstring) give exactly the output of the
    explicit defaults and of the solve -> filter (float32, as combine) -> blend path, bit for
    bit; the paper's filter alone (PAPER_FILTER) is the same path without them."""
    rng = np.random.default_rng(12)
    H, W, n = 14, 15, 3
    truth = rng.uniform(0.2, 1.0, (H, W, 3))
    buffers = make_render_buffers(truth, half_std=0.2, seed=rng)
    bias = rng.normal(0, 0.05, (n, 1, 1, 3))
    ys = [truth + bias + rng.normal(0, sd, (n, H, W, 3)) for sd in (0.02, 0.03, 0.03)]
    inputs = [Denoised(full=ys[0][i].astype(np.float32), a=ys[1][i].astype(np.float32),
                       b=ys[2][i].astype(np.float32)) for i in range(n)]
    default = E.combine(buffers, inputs)
    explicit = E.combine(buffers, inputs, solver="iterative", seed=0, max_iterations=1024,
                         tolerance=1e-9, filter=True, weights="simplex", channels="rgb",
                         radius=7, sigma_spatial=3.0, sigma_color=2.0, sigma_albedo=0.25,
                         sigma_normal=0.15, guide_variance_blur="gaussian9",
                         outlier_removal="public_code", colour_distance="sum", filter_border="reflect101",
                         normal_features="standardised", variance_sum_floor=1e-6, start="random",
                         away_steps=False)
    paper = E.combine(buffers, inputs, **PAPER_FILTER)
    y_full, y_a, y_b = (np.stack([np.asarray(getattr(d, k), np.float64) for d in inputs])
                        for k in ("full", "a", "b"))
    raw = solve_weights(buffers.color_a, buffers.color_b, y_a, y_b, solver="iterative")
    code_details = dict(guide_variance_blur="gaussian9", outlier_removal="public_code", filter_border="reflect101",
                        variance_sum_floor=1e-6, normal_features="standardised")
    for got, passes in ((default, code_details), (explicit, code_details), (paper, PAPER_FILTER)):
        filt = filter_weights(raw, y_full, y_a, y_b, buffers.albedo, buffers.normal,
                                dtype=np.float32, **passes)
        for which in ("full", "a", "b"):
            assert np.array_equal(got.image(which), blend(filt, inputs, which).astype(np.float32))
        for i in range(n):
            assert np.array_equal(got.extras[f"weights_raw_{i}"], raw[i].astype(np.float32))
            assert np.array_equal(got.extras[f"weights_filtered_{i}"], filt[i])
    np.testing.assert_allclose(paper.full, combine_with(
        filter_weights(raw, y_full, y_a, y_b, buffers.albedo, buffers.normal), y_full),
        rtol=1e-6, atol=1e-7)
    # the options do change the result (the comparison above has power)
    for change in (dict(weights="unconstrained"), dict(channels="single"), dict(filter=False),
                   dict(guide_variance_blur="none"), dict(outlier_removal="none"),
                   dict(outlier_removal="neighbour_mean"), dict(colour_distance="mean"),
                   dict(filter_border="clip"), dict(normal_features="raw"), dict(start="pair"),
                   dict(away_steps=True)):
        assert not np.array_equal(E.combine(buffers, inputs, **change).full, default.full), change


def test_unknown_options_name_the_choices():
    xa = xb = np.zeros((2, 2, 3))
    ya = yb = np.zeros((2, 2, 2, 3))
    for key, bad in (("weights", "nonneg"), ("channels", "grey"), ("solver", "osqp")):
        with pytest.raises(ValueError, match=f"{key} '{bad}'"):
            solve_weights(xa, xb, ya, yb, **{key: bad})


@pytest.mark.parametrize("params", [dict(PAPER_FILTER, guide_variance_blur="gaussian9"),
                                    dict(PAPER_FILTER, outlier_removal="neighbour_mean"),
                                    dict(PAPER_FILTER, outlier_removal="public_code"),
                                    dict(PAPER_FILTER, colour_distance="mean"),
                                    dict(PAPER_FILTER, filter_border="reflect101"),
                                    dict(PUBLIC_CODE_FILTER)])
def test_postprocessing_keeps_the_constraint(params, make_render_buffers):
    """The public code's passes: finite weights on the simplex (and summing to one when
    unconstrained) on the firefly case, and the filter without them is what they change."""
    rng = np.random.default_rng(21)
    H, W, n = 12, 13, 3
    truth = rng.uniform(0.1, 1.0, (H, W, 3))
    buffers = make_render_buffers(truth, half_std=0.1, seed=rng)
    buffers.color_a[2, 2] = 1e6
    ys = [np.clip(truth + rng.normal(0, 0.05, (n, H, W, 3)), 0, None) for _ in range(3)]
    inputs = [Denoised(full=ys[0][i].astype(np.float32), a=ys[1][i].astype(np.float32),
                       b=ys[2][i].astype(np.float32)) for i in range(n)]
    for weights in WEIGHTS:
        out = E.combine(buffers, inputs, weights=weights, **params)
        filt = np.stack([out.extras[f"weights_filtered_{i}"] for i in range(n)]).astype(np.float64)
        assert np.isfinite(filt).all() and np.isfinite(out.full).all()
        assert_sum_one(filt, atol=1e-5 * max(1.0, np.abs(filt).max()))
        if weights == "simplex":
            assert filt.min() >= 0.0
        plain = E.combine(buffers, inputs, weights=weights, **PAPER_FILTER)
        assert not np.array_equal(plain.full, out.full)


def test_outlier_removal_that_empties_a_pixel_keeps_the_filtered_weights():
    """Raw weights the filter leaves as they are (sigma_s tiny): at the centre [1, 0, 0]; around
    it map 0 is 0 (std 0: the 1 is an outlier, replaced by 0) and maps 1, 2 alternate 0 / 1
    (std 0.5: their 0s stay). All three weights would be 0; the filtered ones are kept."""
    H = W = 9
    w = np.zeros((3, H, W, 3))
    checker = (np.add.outer(np.arange(H), np.arange(W)) % 2).astype(float)[..., None]
    w[1], w[2] = checker, 1.0 - checker
    w[:, 4, 4] = np.array([1.0, 0.0, 0.0])[:, None]
    y = np.ones((3, H, W, 3))
    flat = np.full((H, W, 3), 0.5)
    kwargs = dict(sigma_spatial=0.01, radius=1)
    plain = filter_weights(w, y, y, y, flat, flat, **kwargs)
    cleaned = filter_weights(w, y, y, y, flat, flat, outlier_removal="neighbour_mean", **kwargs)
    np.testing.assert_allclose(plain, w, atol=1e-12)
    np.testing.assert_array_equal(cleaned[:, 4, 4], plain[:, 4, 4])
    assert np.isfinite(cleaned).all()
    np.testing.assert_allclose(cleaned.sum(axis=0), 1.0, atol=1e-12)
