"""Tests of the ensemble combiner (Zheng et al. 2021) and the cross-bilateral filter,
against independent truth: a general-purpose QP (qpsolvers/quadprog), the paper's
two-denoiser closed form (Eq. 29, re-derived here), Monte Carlo of Eq. 16 and a
brute-force bilateral filter."""

from __future__ import annotations

import itertools

import numba
import numpy as np
import pytest
import qpsolvers

from mcbench.bilateral import cross_bilateral_filter
from mcbench.buffers import Denoised, RenderBuffers
from methods import ensemble as E


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def as_problems(points, bs):
    """Pack K problems with N points each into solver inputs.

    points: (K, N, 2) with a_i = (y_i^A, y_i^B); bs: (K, 2) with b = (x^B, x^A).
    Returns color_a, color_b (1, K, 1) and denoised_a, denoised_b (N, 1, K, 1).
    """
    points = np.asarray(points, np.float64)
    bs = np.asarray(bs, np.float64)
    ya = points[:, :, 0].T[:, None, :, None]
    yb = points[:, :, 1].T[:, None, :, None]
    xb = bs[:, 0][None, :, None]
    xa = bs[:, 1][None, :, None]
    return xa, xb, ya, yb


def half_sq_dist(w, pts, b):
    """0.5 |A w - b|^2 for one problem (Eq. 25 up to a constant)."""
    r = w @ pts - b
    return 0.5 * float(r @ r)


def qp_objective(pts, b):
    """Minimum of 0.5 |A w - b|^2 over the simplex with quadprog, on data divided by the
    problem's scale (s = max |coordinate|) and rescaled back; ridge 1e-12 for definiteness."""
    s = max(np.abs(pts).max(), np.abs(b).max(), 1e-30)
    A = (pts / s).T  # 2 x N
    bb = b / s
    n = pts.shape[0]
    P = A.T @ A + 1e-12 * np.eye(n)
    q = -A.T @ bb
    w = qpsolvers.solve_qp(P, q, G=-np.eye(n), h=np.zeros(n), A=np.ones((1, n)),
                           b=np.array([1.0]), solver="quadprog")
    assert w is not None
    w = np.clip(w, 0, None)
    w /= w.sum()
    return half_sq_dist(w, pts, b), w


def random_problem(rng, n, kind, scale):
    pts = rng.normal(size=(n, 2))
    if kind == "inside":
        lam = rng.dirichlet(np.ones(n))
        b = lam @ pts
    elif kind == "duplicates":
        pts[n // 2:] = pts[0]
        b = rng.normal(size=2) * 2
    elif kind == "collinear":
        pts[:, 0] = 0.0
        pts[: max(1, n // 3), 0] = -rng.uniform(0.1, 1, size=max(1, n // 3))
        b = np.array([rng.uniform(0.5, 3), rng.normal()])
    else:
        b = rng.normal(size=2) * 2
    return pts * scale, b * scale


KINDS = ("outside", "inside", "duplicates", "collinear")


def random_simplex_problems(seed=1, count=300):
    rng = np.random.default_rng(seed)
    probs = []
    for t in range(count):
        n = int(rng.integers(2, 9))
        kind = KINDS[t % len(KINDS)]
        scale = 10.0 ** rng.uniform(-3, 3)
        probs.append((n, kind, scale) + random_problem(rng, n, kind, scale))
    return probs


def solve_one(pts, b, solver="exact", **kw):
    xa, xb, ya, yb = as_problems(pts[None], b[None])
    return E.solve_weights(xa, xb, ya, yb, solver=solver, **kw)[:, 0, 0, 0]


def assert_simplex(w, axis=0, atol=1e-9):
    assert np.all(np.isfinite(w))
    assert w.min() >= 0.0
    np.testing.assert_allclose(w.sum(axis=axis), 1.0, atol=atol)


# ---------------------------------------------------------------------------------------
# exact solver vs a general-purpose QP
# ---------------------------------------------------------------------------------------
def test_exact_matches_qp_objective():
    """Exact objective <= QP objective + 1e-9 s^2 (s = max |input| of the problem) and
    within 1e-9 s^2 of it from below too (both reach the same optimum)."""
    paths = set()
    for n, kind, scale, pts, b in random_simplex_problems():
        xa, xb, ya, yb = as_problems(pts[None], b[None])
        w, code = E.solve_weights(xa, xb, ya, yb, solver="exact", return_info=True)
        w = w[:, 0, 0, 0]
        paths.add(int(code.ravel()[0]))
        assert_simplex(w)
        f_exact = half_sq_dist(w, pts, b)
        f_qp, _ = qp_objective(pts, b)
        s2 = max(np.abs(pts).max(), np.abs(b).max()) ** 2
        assert f_exact <= f_qp + 1e-9 * s2, (n, kind, scale, f_exact, f_qp)
        assert f_exact >= f_qp - 1e-9 * s2, (n, kind, scale, f_exact, f_qp)
    # the unique fast path, the min-norm-over-candidates path and the support enumeration
    # are all exercised; the geometric fallback (3, a numerical safety net) never is
    assert paths == {0, 1, 2}, paths


def test_objective_is_eq13_quadratic_form():
    """E.objective (Eq. 25 form used by the exact solver) equals w^T <M> w with <M> built
    element-wise from Eq. 11-12."""
    rng = np.random.default_rng(5)
    n = 5
    xa, xb = rng.normal(size=2)
    ya, yb = rng.normal(size=(2, n))
    MA = xa * xb - xb * (ya[:, None] + ya[None, :]) + np.outer(ya, ya)
    MB = xa * xb - xa * (yb[:, None] + yb[None, :]) + np.outer(yb, yb)
    M = 0.5 * (MA + MB)
    for _ in range(10):
        w = rng.dirichlet(np.ones(n))
        got = E.objective(w[:, None, None, None], np.full((1, 1, 1), xa), np.full((1, 1, 1), xb),
                          ya[:, None, None, None], yb[:, None, None, None])[0, 0, 0]
        assert got == pytest.approx(w @ M @ w, rel=1e-12, abs=1e-12)


def test_exact_min_norm_tie_break_matches_qp():
    """Non-unique optima: the exact weights equal the minimum-norm optimal weights found by
    a QP  min |w|^2  s.t.  A w = p*, sum w = 1, w >= 0  (p* known by construction)."""
    rng = np.random.default_rng(7)
    checked = 0
    for t in range(60):
        n = int(rng.integers(4, 9))
        if t % 2 == 0:  # b strictly inside the hull of points in general position
            pts = rng.normal(size=(n, 2))
            p_star = rng.dirichlet(np.ones(n)) @ pts
            b = p_star
        else:  # several collinear points on the optimal face x = 0
            k = int(rng.integers(3, n))
            pts = np.column_stack([np.zeros(n), rng.uniform(-1, 1, n)])
            pts[k:, 0] = -rng.uniform(0.2, 1, n - k)
            ys = pts[:k, 1]
            p_star = np.array([0.0, rng.uniform(ys.min(), ys.max())])
            b = p_star + np.array([rng.uniform(0.5, 2.0), 0.0])
        w = solve_one(pts, b)
        A_eq = np.vstack([pts.T, np.ones((1, n))])
        b_eq = np.concatenate([p_star, [1.0]])
        ref = qpsolvers.solve_qp(np.eye(n), np.zeros(n), G=-np.eye(n), h=np.zeros(n),
                                 A=A_eq, b=b_eq, solver="quadprog")
        if ref is None:  # quadprog refuses dependent equality rows; use the 1-D form
            A_eq = np.vstack([pts[:, 1], np.ones(n)])
            G = np.vstack([-np.eye(n), np.eye(n)[k:]])
            h = np.zeros(n + n - k)
            ref = qpsolvers.solve_qp(np.eye(n), np.zeros(n), G=G, h=h, A=A_eq,
                                     b=np.array([p_star[1], 1.0]), solver="quadprog")
        assert ref is not None
        np.testing.assert_allclose(w, ref, atol=1e-6)
        checked += 1
    assert checked == 60


def test_exact_identical_outputs_gives_uniform_weights():
    pts = np.tile([[0.3, 0.7]], (5, 1))
    for b in ([0.3, 0.7], [2.0, -1.0]):
        np.testing.assert_allclose(solve_one(pts, np.array(b)), 0.2, atol=1e-12)


def test_exact_permutation_equivariant():
    rng = np.random.default_rng(11)
    for n, kind, scale, pts, b in random_simplex_problems(seed=3, count=80):
        w = solve_one(pts, b)
        perm = rng.permutation(n)
        wp = solve_one(pts[perm], b)
        np.testing.assert_allclose(wp, w[perm], atol=1e-8, err_msg=f"{kind} n={n}")


# ---------------------------------------------------------------------------------------
# iterative solver
# ---------------------------------------------------------------------------------------
def test_iterative_never_below_exact_and_close():
    rng = np.random.default_rng(2)
    n, m = 5, 2000
    pts = rng.normal(size=(m, n, 2))
    bs = rng.normal(size=(m, 2)) * 1.5
    xa, xb, ya, yb = as_problems(pts, bs)
    wi = E.solve_weights(xa, xb, ya, yb, solver="iterative")
    we = E.solve_weights(xa, xb, ya, yb, solver="exact")
    assert_simplex(wi)
    oi = E.objective(wi, xa, xb, ya, yb)
    oe = E.objective(we, xa, xb, ya, yb)
    assert (oi - oe).min() >= -1e-12
    assert np.median(oi - oe) < 1e-6  # converges on most pixel-channels


def test_iterative_two_denoisers_equals_closed_form():
    """N = 2: the iterative solver reaches the paper's closed form (Eq. 29), computed here
    independently: alpha = clip(c2 / c1, 0, 1), w = (1 - alpha, alpha)."""
    rng = np.random.default_rng(4)
    m = 500
    y1a, y1b, y2a, y2b, xa_, xb_ = rng.normal(size=(6, m))
    c1 = (y1a - y2a) ** 2 + (y1b - y2b) ** 2
    c2 = (y1a - xb_) * (y1a - y2a) + (y1b - xa_) * (y1b - y2b)
    alpha = np.clip(c2 / c1, 0, 1)
    pts = np.stack([np.stack([y1a, y1b], -1), np.stack([y2a, y2b], -1)], axis=1)
    bs = np.stack([xb_, xa_], -1)
    xa, xb, ya, yb = as_problems(pts, bs)
    for solver in ("iterative", "exact"):
        w = E.solve_weights(xa, xb, ya, yb, solver=solver)[:, 0, :, 0]
        np.testing.assert_allclose(w[1], alpha, atol=1e-9, err_msg=solver)
        np.testing.assert_allclose(w[0], 1 - alpha, atol=1e-9, err_msg=solver)


def test_iterative_deterministic_and_seeded():
    rng = np.random.default_rng(8)
    xa = rng.normal(size=(16, 16, 3))
    xb = rng.normal(size=(16, 16, 3))
    ya = rng.normal(size=(4, 16, 16, 3))
    yb = rng.normal(size=(4, 16, 16, 3))
    kw = dict(solver="iterative", max_iterations=64)
    w0 = E.solve_weights(xa, xb, ya, yb, seed=3, **kw)
    w1 = E.solve_weights(xa, xb, ya, yb, seed=3, **kw)
    assert np.array_equal(w0, w1)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        w_single = E.solve_weights(xa, xb, ya, yb, seed=3, **kw)
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(w0, w_single)
    w2 = E.solve_weights(xa, xb, ya, yb, seed=4, **kw)
    assert not np.array_equal(w0, w2)


# ---------------------------------------------------------------------------------------
# Eq. 16: <M> is an unbiased estimator of M^half
# ---------------------------------------------------------------------------------------
def test_dual_buffer_estimate_unbiased_eq16():
    """x^A, x^B ~ N(mu, sigma^2) iid; y_i^h = a_i x^h + c_i + s_i eps_i^h + r eta^h (eta shared
    by the denoisers of one half, so y_i^A and y_j^A are correlated but independent of half
    B). M^half_ij = (m_i - mu)(m_j - mu) + Cov[y_i^A, y_j^A] with m_i = a_i mu + c_i
    (Eq. 15); the Monte Carlo mean of <M> (Eq. 11-12) must match within 5 standard errors."""
    rng = np.random.default_rng(12)
    mu, sigma, r = 0.7, 0.4, 0.1
    a = np.array([0.9, 0.5, 0.2])
    c = np.array([0.05, 0.3, 0.5])
    s = np.array([0.05, 0.1, 0.02])
    T = 400_000
    xA = rng.normal(mu, sigma, T)
    xB = rng.normal(mu, sigma, T)

    def denoise(x):
        eta = rng.normal(size=T)
        return a[:, None] * x + c[:, None] + s[:, None] * rng.normal(size=(3, T)) + r * eta

    yA, yB = denoise(xA), denoise(xB)
    MA = xA * xB - xB * (yA[:, None] + yA[None, :]) + yA[:, None] * yA[None, :]
    MB = xA * xB - xA * (yB[:, None] + yB[None, :]) + yB[:, None] * yB[None, :]
    M = 0.5 * (MA + MB)  # (3, 3, T)
    mean = M.mean(axis=2)
    se = M.std(axis=2, ddof=1) / np.sqrt(T)
    m = a * mu + c
    cov = np.outer(a, a) * sigma ** 2 + np.diag(s ** 2) + r ** 2
    M_half = np.outer(m - mu, m - mu) + cov
    z = np.abs(mean - M_half) / se
    assert z.max() < 5, (mean, M_half, z)
    # and the estimate is not trivially close: a biased variant (using x^A for both) fails
    biased = (xA * xA - xA * (yA[:, None] + yA[None, :]) + yA[:, None] * yA[None, :]).mean(2)
    assert np.abs(biased - M_half).max() / se.max() > 20


# ---------------------------------------------------------------------------------------
# robustness
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("solver", E.SOLVERS)
def test_robust_degenerate_inputs(solver):
    rng = np.random.default_rng(9)
    H, W, n = 6, 7, 4
    xa = rng.uniform(0, 1, (H, W, 3))
    xb = rng.uniform(0, 1, (H, W, 3))
    ya = rng.uniform(0, 1, (n, H, W, 3))
    yb = rng.uniform(0, 1, (n, H, W, 3))
    ya[:, 0, 0] = ya[0, 0, 0]  # identical base outputs
    yb[:, 0, 0] = yb[0, 0, 0]
    xa[1, 1] = xb[1, 1] = ya[:, 1, 1] = yb[:, 1, 1] = 0.0  # all-zero pixel
    xa[2, 2] = 1e6  # fireflies
    yb[1, 3, 3] = 1e6
    w = E.solve_weights(xa, xb, ya, yb, solver=solver)
    assert w.shape == (n, H, W, 3)
    assert_simplex(w)
    if solver == "exact":
        np.testing.assert_allclose(w[:, 0, 0], 0.25, atol=1e-12)
        np.testing.assert_allclose(w[:, 1, 1], 0.25, atol=1e-12)
    w1 = E.solve_weights(xa, xb, ya[:1], yb[:1], solver=solver)
    assert np.array_equal(w1, np.ones((1, H, W, 3)))


def test_nonfinite_inputs_raise_with_count():
    rng = np.random.default_rng(10)
    xa, xb = rng.normal(size=(2, 5, 5, 3))
    ya, yb = rng.normal(size=(2, 3, 5, 5, 3))
    xa[0, 0, 0] = np.nan
    xa[1, 2, 1] = np.inf
    xa[1, 2, 2] = np.nan  # same pixel: counted once
    yb[2, 4, 4, 0] = -np.inf
    with pytest.raises(ValueError, match=r"3 pixel"):
        E.solve_weights(xa, xb, ya, yb)
    with pytest.raises(ValueError, match="shape|must"):
        E.solve_weights(xa, xb, ya[:, :4], yb)
    with pytest.raises(ValueError):
        E.solve_weights(xa, xb[:4], ya, yb)


# ---------------------------------------------------------------------------------------
# weight filter and combine
# ---------------------------------------------------------------------------------------
def synthetic_scene(rng, H=20, W=24, n=3, spp=8):
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    truth = np.stack([0.5 + 0.4 * np.sin(3 * xx), 0.3 + 0.2 * yy, 0.2 + xx * yy], -1)
    noise = 0.2
    xa = truth + rng.normal(0, noise, truth.shape)
    xb = truth + rng.normal(0, noise, truth.shape)
    bias = rng.normal(0, 0.05, (n, 1, 1, 3))
    ya = truth + bias + rng.normal(0, 0.03, (n, H, W, 3))
    yb = truth + bias + rng.normal(0, 0.03, (n, H, W, 3))
    yf = truth + bias + rng.normal(0, 0.02, (n, H, W, 3))
    albedo = np.clip(truth, 0, 1)
    normal = np.dstack([np.zeros((H, W)), np.zeros((H, W)), np.ones((H, W))])
    normal[:, W // 2:] = [1.0, 0.0, 0.0]
    layers = {"color": ((xa + xb) / 2).astype(np.float32), "color_a": xa.astype(np.float32),
              "color_b": xb.astype(np.float32), "albedo": albedo.astype(np.float32),
              "normal": normal.astype(np.float32)}
    buffers = RenderBuffers(layers=layers, spp=spp)
    inputs = [Denoised(full=yf[i].astype(np.float32), a=ya[i].astype(np.float32),
                       b=yb[i].astype(np.float32)) for i in range(n)]
    return buffers, inputs, (xa, xb, ya, yb, yf, albedo, normal)


def test_filter_weights_simplex_and_constant_fixed_point():
    rng = np.random.default_rng(13)
    buffers, inputs, (xa, xb, ya, yb, yf, albedo, normal) = synthetic_scene(rng)
    w = E.solve_weights(xa, xb, ya, yb, solver="exact")
    wf = E.filter_weights(w, yf, ya, yb, albedo, normal)
    assert wf.shape == w.shape
    assert_simplex(wf)
    assert np.abs(wf - w).max() > 1e-3  # it does filter
    const = np.broadcast_to(rng.dirichlet(np.ones(3), size=3).T[:, None, None, :], w.shape)
    wc = E.filter_weights(const, yf, ya, yb, albedo, normal)
    np.testing.assert_allclose(wc, const, atol=1e-12)


@pytest.mark.parametrize("filter_", [True, False])
def test_combine_end_to_end(filter_):
    rng = np.random.default_rng(14)
    buffers, inputs, (xa, xb, ya, yb, yf, albedo, normal) = synthetic_scene(rng)
    out = E.combine(buffers, inputs, filter=filter_, solver="exact")
    assert isinstance(out, Denoised)
    for img in (out.full, out.a, out.b):
        assert img.dtype == np.float32 and img.shape == xa.shape and np.isfinite(img).all()
    names = sorted(out.extras)
    assert names == sorted([f"weights_raw_{i}" for i in range(3)]
                           + [f"weights_filtered_{i}" for i in range(3)])
    wf = np.stack([out.extras[f"weights_filtered_{i}"] for i in range(3)]).astype(np.float64)
    assert_simplex(wf, atol=1e-6)
    np.testing.assert_allclose(out.full, np.einsum("nhwc,nhwc->hwc", wf, yf), atol=1e-5)
    if not filter_:
        for i in range(3):
            assert np.array_equal(out.extras[f"weights_raw_{i}"],
                                  out.extras[f"weights_filtered_{i}"])
    single = E.combine(buffers, inputs[:1], filter=filter_)
    np.testing.assert_allclose(single.full, inputs[0].full, atol=1e-6)


# ---------------------------------------------------------------------------------------
# cross-bilateral filter vs brute force
# ---------------------------------------------------------------------------------------
def brute_force_cbf(values, guide, gvar, features, sigmas, ss, sg, radius):
    K, H, W = values.shape
    out = np.zeros_like(values)
    for y in range(H):
        for x in range(W):
            acc = np.zeros(K)
            wsum = 0.0
            for qy in range(max(0, y - radius), min(H, y + radius + 1)):
                for qx in range(max(0, x - radius), min(W, x + radius + 1)):
                    k = np.exp(-((qy - y) ** 2 + (qx - x) ** 2) / (2 * ss ** 2))
                    for f, sf in zip(features, sigmas):
                        f = f if f.ndim == 3 else f[:, :, None]
                        k *= np.exp(-np.sum((f[y, x] - f[qy, qx]) ** 2) / (2 * sf ** 2))
                    if guide is not None:
                        terms = []
                        for c in range(guide.shape[2]):
                            num = (guide[y, x, c] - guide[qy, qx, c]) ** 2
                            den = gvar[y, x, c] + gvar[qy, qx, c]
                            if den <= 1e-20:
                                terms.append(0.0 if num == 0 else np.inf)
                            else:
                                terms.append(num / den)
                        k *= np.exp(-np.mean(terms) / (2 * sg ** 2))
                    acc += k * values[:, qy, qx]
                    wsum += k
            out[:, y, x] = acc / wsum
    return out


def test_cross_bilateral_matches_brute_force():
    rng = np.random.default_rng(15)
    H, W, K = 9, 11, 2
    values = rng.normal(size=(K, H, W))
    guide = rng.uniform(0, 1, (H, W, 3))
    gvar = rng.uniform(0, 0.05, (H, W, 3))
    gvar[2:4, 3:6] = 0.0  # exercise the zero-variance guard
    guide[2:4, 3:5] = 0.5
    feats = [rng.uniform(0, 1, (H, W, 3)), rng.uniform(0, 1, (H, W))]
    sig = [0.4, 0.3]
    got = cross_bilateral_filter(values, guide, gvar, feats, sig, 2.0, 1.5, 3)
    ref = brute_force_cbf(values, guide, gvar, feats, sig, 2.0, 1.5, 3)
    assert got.shape == (K, H, W) and got.dtype == np.float64
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12)
    got2 = cross_bilateral_filter(values, None, None, [], [], 1.0, 1.0, 2)
    ref2 = brute_force_cbf(values, None, None, [], [], 1.0, 1.0, 2)
    np.testing.assert_allclose(got2, ref2, rtol=1e-10, atol=1e-12)
