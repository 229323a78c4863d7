"""Tests of the ensemble combiner (Zheng et al. 2021) and the cross-bilateral filter,
against independent truth: a general-purpose QP (qpsolvers/quadprog), the paper's
two-denoiser closed form (Eq. 29, re-derived here), Monte Carlo of Eq. 16 through the
project's objective, the iterative solver's stopping rule checked on its own trajectory, and
brute-force loops of the bilateral filter and of the weight filter (Eq. 32-34)."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest
import qpsolvers

from mcbench.combine import weight_filter
from mcbench.combine.ensemble_weights import CHANNELS, solve_weights
from mcbench.combine.simplex_solvers.problem import SOLVERS, objective
from mcbench.combine.weight_filter import PAPER_FILTER, filter_weights
from mcbench.io.buffers import Denoised
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
    return solve_weights(xa, xb, ya, yb, solver=solver, **kw)[:, 0, 0, 0]


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
        w, code = solve_weights(xa, xb, ya, yb, solver="exact", return_info=True)
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
    """objective (Eq. 25 form used by the exact solver) equals w^T <M> w with <M> built
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
        got = objective(w[:, None, None, None], np.full((1, 1, 1), xa), np.full((1, 1, 1), xb),
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
def random_plane_problems(seed=2, n=5, m=2000):
    """m random problems with n points in general position, b mostly outside their hull."""
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(m, n, 2))
    bs = rng.normal(size=(m, 2)) * 1.5
    return as_problems(pts, bs)


def biased_denoiser_problems(seed=13, n=4, h=64, w=64):
    """Realistic problems: n biased, slightly noisy denoisers of a smooth image whose noisy
    halves have std 0.2. Returns color_a, color_b (H, W, 3), denoised_a, denoised_b
    (n, H, W, 3)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    truth = np.stack([0.5 + 0.4 * np.sin(3 * xx), 0.3 + 0.2 * yy, 0.2 + xx * yy], -1)
    xa = truth + rng.normal(0, 0.2, truth.shape)
    xb = truth + rng.normal(0, 0.2, truth.shape)
    bias = rng.normal(0, 0.05, (n, 1, 1, 3))
    ya = truth + bias + rng.normal(0, 0.03, (n, h, w, 3))
    yb = truth + bias + rng.normal(0, 0.03, (n, h, w, 3))
    return xa, xb, ya, yb


def gap_above_optimum(weights, xa, xb, ya, yb):
    """Objective of ``weights`` minus the exact solver's optimum (itself checked against
    quadprog above), in units of the pixel-channel's scale s^2 = max(|x|, |y|)^2."""
    optimum = objective(solve_weights(xa, xb, ya, yb, solver="exact"), xa, xb, ya, yb)
    scale = np.maximum(np.maximum(np.abs(xa), np.abs(xb)),
                       np.maximum(np.abs(ya).max(axis=0), np.abs(yb).max(axis=0)))
    return (objective(weights, xa, xb, ya, yb) - optimum) / np.maximum(scale, 1e-30) ** 2


def test_iterative_never_below_exact():
    xa, xb, ya, yb = random_plane_problems()
    wi = solve_weights(xa, xb, ya, yb, solver="iterative")
    assert_simplex(wi)
    assert gap_above_optimum(wi, xa, xb, ya, yb).min() >= -1e-12


@pytest.mark.parametrize("problems", [random_plane_problems, biased_denoiser_problems])
def test_iterative_reaches_the_optimum_on_99_percent(problems):
    """With ``away_steps=True`` at least 99 % of pixel-channels end within 1e-6 s^2 of the exact
    optimum of Eq. 13. The paper's alpha in [0, 1] (the default) moves weight off a denoiser only
    as the others gain, so within the 1024 iterations far fewer get that close (measured: 67 %
    and 86 %), but all within 1e-2 s^2 (measured max 1.7e-3) and none below the optimum."""
    xa, xb, ya, yb = problems()
    gap = gap_above_optimum(solve_weights(xa, xb, ya, yb, solver="iterative", away_steps=True),
                            xa, xb, ya, yb)
    share = float(np.mean(gap <= 1e-6))
    assert share >= 0.99, share
    paper = gap_above_optimum(solve_weights(xa, xb, ya, yb, solver="iterative"), xa, xb, ya, yb)
    assert paper.min() >= -1e-12 and paper.max() <= 1e-2
    assert float(np.mean(paper <= 1e-6)) < 0.95


def two_denoiser_line_problems(t_star, seed=31, m=4000):
    """m problems of N = 2 points a_1, a_2 and a target b whose projection onto the line through
    the points is a_1 + t* (a_2 - a_1) (plus a perpendicular offset). Returns the solver inputs."""
    rng = np.random.default_rng(seed)
    a1, a2 = rng.normal(size=(2, m, 2))
    d = a2 - a1
    normal = np.stack([-d[:, 1], d[:, 0]], -1)
    b = a1 + np.asarray(t_star)[..., None] * d + rng.normal(size=(m, 1)) * normal
    return as_problems(np.stack([a1, a2], axis=1), b)


def test_iterative_alpha_range_in_one_step():
    """Eq. 29's clip decides where one step can go. N = 2, w = (1 - t, t) on the segment, t* the
    unclipped minimiser on the line. A step towards e_2 with alpha in [0, 1] reaches t in
    [t0, 1], one towards e_1 t in [0, t0] (t0 the random start); with away steps alpha in
    [-w_i / (1 - w_i), 1] both reach any t in [0, 1]. So after one iteration:

    * t* < 0 (optimum at e_1): with away steps every problem is at t = 0 exactly; with the paper's
      clip the half that stepped towards e_2 cannot move weight off it and stays at its start
      t0 > 0, the other half is at 0; after one whole cycle (2 iterations) all are at 0.
    * 0 < t* < 1: with away steps every problem is at t*; with the paper's clip half are (those
      whose start lay on the chosen vertex's far side of t*), half stay at t0; after one cycle
      all are at t*."""
    m = 4000
    xa, xb, ya, yb = two_denoiser_line_problems(np.full(m, -0.5))
    away = solve_weights(xa, xb, ya, yb, max_iterations=1, away_steps=True)[1].ravel()
    np.testing.assert_array_equal(away, 0.0)
    paper = solve_weights(xa, xb, ya, yb, max_iterations=1)[1].ravel()
    stayed = paper > 0
    assert 0.45 < stayed.mean() < 0.55, stayed.mean()
    np.testing.assert_array_equal(paper[~stayed], 0.0)
    assert len(np.unique(paper[stayed])) == stayed.sum()          # the random starts
    np.testing.assert_array_equal(solve_weights(xa, xb, ya, yb, max_iterations=2)[1].ravel(), 0.0)

    t_star = np.random.default_rng(32).uniform(0.2, 0.8, m)
    xa, xb, ya, yb = two_denoiser_line_problems(t_star, seed=33)
    away = solve_weights(xa, xb, ya, yb, max_iterations=1, away_steps=True)[1].ravel()
    np.testing.assert_allclose(away, t_star, rtol=0, atol=1e-12)
    paper = solve_weights(xa, xb, ya, yb, max_iterations=1)[1].ravel()
    reached = np.abs(paper - t_star) <= 1e-12
    assert 0.45 < reached.mean() < 0.55, reached.mean()
    np.testing.assert_allclose(solve_weights(xa, xb, ya, yb, max_iterations=2)[1].ravel(), t_star,
                               rtol=0, atol=1e-12)
    for bad in (1, 0, "yes", None):
        with pytest.raises(ValueError, match="away_steps must be true or false"):
            solve_weights(xa, xb, ya, yb, away_steps=bad)


@pytest.mark.parametrize("start", ["vertex", "pair"])
def test_iterative_deterministic_starts(start):
    """start="vertex" begins at the best single denoiser, "pair" at the best two-denoiser
    ensemble (Eq. 29 over all pairs). With away steps both reach the optimum like the random start;
    "pair" *is* the optimum where the exact solution has two non-zero weights (b outside the
    hull, nearest point inside an edge), so one cycle of N steps moves nothing and it stops,
    with the exact weights."""
    xa, xb, ya, yb = random_plane_problems(seed=5, n=5, m=3000)
    w, iterations = solve_weights(xa, xb, ya, yb, start=start, return_info=True, away_steps=True)
    assert_simplex(w)
    gap = gap_above_optimum(w, xa, xb, ya, yb)
    assert gap.min() >= -1e-12 and np.mean(gap <= 1e-6) >= 0.99
    exact = solve_weights(xa, xb, ya, yb, solver="exact")
    two = (exact > 1e-9).sum(axis=0) == 2
    assert two.mean() > 0.2
    if start == "pair":
        assert np.mean(iterations[two] == 5) > 0.99
        np.testing.assert_allclose(w[:, two], exact[:, two], atol=1e-7)
    else:   # the best vertex is the optimum only where one weight is 1
        assert np.mean(iterations[two] == 5) < 0.5
    random = solve_weights(xa, xb, ya, yb)
    assert not np.array_equal(random, w)
    with pytest.raises(ValueError, match="start 'best'"):
        solve_weights(xa, xb, ya, yb, start="best")


def test_iterative_stopping_rule_on_its_trajectory():
    """The solver stops after the first whole cycle of N iterations in which no single update
    changed any weight by more than ``tolerance``, or at ``max_iterations``.

    Independent check: with the counter-based generator, ``max_iterations=t`` returns the
    weights w(t) after t iterations of the same trajectory, so every update's change is
    observable (except the first, from the hidden random start). The iteration counts
    returned with ``return_info`` must be where the rule says to stop."""
    n, limit, tolerance = 3, 12, 1e-4
    xa, xb, ya, yb = random_plane_problems(seed=21, n=n, m=300)
    kw = dict(solver="iterative", seed=5, tolerance=tolerance)
    final, counts = solve_weights(xa, xb, ya, yb, max_iterations=limit, return_info=True, **kw)
    trajectory = np.stack([solve_weights(xa, xb, ya, yb, max_iterations=t, **kw)
                           for t in range(1, limit + 1)])          # (limit, n, 1, m, 1)
    step_change = np.abs(np.diff(trajectory, axis=0)).max(axis=1)  # change of update t+2
    counts = counts.ravel()
    step_change = step_change.reshape(limit - 1, -1)
    assert set(np.unique(counts)) <= set(range(n, limit + 1, n))
    assert 0.1 < np.mean(counts < limit) < 0.9, "the case needs converged and unconverged pixels"
    for p, k in enumerate(counts):
        np.testing.assert_array_equal(trajectory[k - 1][:, 0, p], final[:, 0, p])
        cycles = [step_change[max(0, c * n - 1):(c + 1) * n - 1, p].max()
                  for c in range(k // n)]                          # updates c*n+1 .. (c+1)*n
        # every cycle before the last moved a weight by more than the tolerance (the first
        # cycle's first update is hidden, so only later cycles are checked) ...
        assert all(change > tolerance for change in cycles[1:-1]), (p, k, cycles)
        # ... and the last one did not, unless the limit stopped it
        if k < limit:
            assert cycles[-1] <= tolerance, (p, k, cycles)


def test_iterative_stops_at_the_paper_limit_of_1024():
    """Pixel-channels that do not converge stop at exactly 1024 iterations by default (the
    paper's limit); a different limit, even mid-cycle, is respected exactly; converged pixels
    stop at the same weights whatever the limit, unconverged ones move on with more."""
    xa, xb, ya, yb = biased_denoiser_problems(n=4, h=24, w=24)
    # tolerance 0: only a cycle that changes no weight at all stops early, so that a third of
    # the pixel-channels run to the limit (with the default 1e-9, 99.9 % converge first)
    w_default, counts = solve_weights(xa, xb, ya, yb, tolerance=0.0, return_info=True)
    assert counts.max() == 1024
    unconverged = counts == 1024
    assert 0.02 < unconverged.mean() < 0.9
    assert np.all(counts[~unconverged] % 4 == 0)
    w_1001, counts_1001 = solve_weights(xa, xb, ya, yb, tolerance=0.0, max_iterations=1001, return_info=True)
    assert counts_1001.max() == 1001 and np.all(counts_1001[unconverged] == 1001)
    w_more, counts_more = solve_weights(xa, xb, ya, yb, tolerance=0.0, max_iterations=4096, return_info=True)
    np.testing.assert_array_equal(counts_more[~unconverged], counts[~unconverged])
    np.testing.assert_array_equal(w_more[:, ~unconverged], w_default[:, ~unconverged])
    assert np.all(counts_more[unconverged] > 1024)
    # more iterations never leave them further from the optimum (each step minimises on a line)
    gap_default = gap_above_optimum(w_default, xa, xb, ya, yb)[unconverged]
    gap_more = gap_above_optimum(w_more, xa, xb, ya, yb)[unconverged]
    assert np.all(gap_more <= gap_default + 1e-12)


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
        w = solve_weights(xa, xb, ya, yb, solver=solver)[:, 0, :, 0]
        np.testing.assert_allclose(w[1], alpha, atol=1e-9, err_msg=solver)
        np.testing.assert_allclose(w[0], 1 - alpha, atol=1e-9, err_msg=solver)


def test_iterative_deterministic_and_seeded():
    rng = np.random.default_rng(8)
    xa = rng.normal(size=(16, 16, 3))
    xb = rng.normal(size=(16, 16, 3))
    ya = rng.normal(size=(4, 16, 16, 3))
    yb = rng.normal(size=(4, 16, 16, 3))
    kw = dict(solver="iterative", max_iterations=64)
    w0 = solve_weights(xa, xb, ya, yb, seed=3, **kw)
    w1 = solve_weights(xa, xb, ya, yb, seed=3, **kw)
    assert np.array_equal(w0, w1)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        w_single = solve_weights(xa, xb, ya, yb, seed=3, **kw)
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(w0, w_single)
    w2 = solve_weights(xa, xb, ya, yb, seed=4, **kw)
    assert not np.array_equal(w0, w2)


# ---------------------------------------------------------------------------------------
# Eq. 16: <M> is an unbiased estimator of M^half
# ---------------------------------------------------------------------------------------
def estimated_mse_matrix(color_a, color_b, denoised_a, denoised_b):
    """<M> per pixel-channel recovered from the project's objective by polarisation: on the
    simplex L(w) = w^T <M> w, so <M>_ii = L(e_i) and <M>_ij = 2 L((e_i + e_j) / 2)
    - (<M>_ii + <M>_jj) / 2. denoised_*: (N, H, W, C). Returns (N, N, H, W, C)."""
    n = denoised_a.shape[0]

    def loss(w):
        weights = np.broadcast_to(np.asarray(w, np.float64)[:, None, None, None], denoised_a.shape)
        return objective(weights, color_a, color_b, denoised_a, denoised_b)

    eye = np.eye(n)
    diag = [loss(eye[i]) for i in range(n)]
    return np.stack([np.stack([diag[i] if i == j else
                               2 * loss((eye[i] + eye[j]) / 2) - (diag[i] + diag[j]) / 2
                               for j in range(n)]) for i in range(n)])


def simplex_minimiser(matrix):
    """argmin w^T M w over the simplex by quadprog (ridge 1e-12 for definiteness)."""
    n = matrix.shape[0]
    w = qpsolvers.solve_qp(matrix + 1e-12 * np.eye(n), np.zeros(n), G=-np.eye(n), h=np.zeros(n),
                           A=np.ones((1, n)), b=np.array([1.0]), solver="quadprog")
    assert w is not None
    return w


def test_dual_buffer_estimate_unbiased_eq16():
    """Eq. 16: the project's objective (objective, Eq. 11-13 via Eq. 25) is an unbiased
    estimate of w^T M^half w. Monte Carlo over T pixels of one scene: x^A, x^B ~ N(mu, sigma^2)
    iid; y_i^h = a_i x^h + c_i + s_i eps_i^h + r eta^h (eta shared by the denoisers of one half,
    so y_i^A and y_j^A are correlated but independent of half B). Truth (Eq. 15):
    M^half_ij = (m_i - mu)(m_j - mu) + Cov[y_i^A, y_j^A] with m_i = a_i mu + c_i. The mean of
    <M> must match within 5 standard errors, its simplex minimiser must match the true one, and
    two biased variants (x^A in place of x^B; half-A outputs that saw x^B, against Eq. 10)
    must be detected."""
    rng = np.random.default_rng(12)
    mu, sigma, r = 0.7, 0.4, 0.1
    a = np.array([0.3, 0.35, 0.25])
    c = np.array([0.39, 0.535, 0.545])   # biases m_i - mu = -0.1, 0.08, 0.02
    s = np.array([0.1, 0.12, 0.1])
    T = 200_000
    xA = rng.normal(mu, sigma, (1, T, 1))
    xB = rng.normal(mu, sigma, (1, T, 1))

    def denoise(x):
        eta = rng.normal(size=x.shape)
        return (a[:, None, None, None] * x + c[:, None, None, None]
                + s[:, None, None, None] * rng.normal(size=(3,) + x.shape) + r * eta)

    yA, yB = denoise(xA), denoise(xB)
    m = a * mu + c
    M_half = np.outer(m - mu, m - mu) + np.outer(a, a) * sigma ** 2 + np.diag(s ** 2) + r ** 2

    M = estimated_mse_matrix(xA, xB, yA, yB).reshape(3, 3, T)
    mean = M.mean(axis=2)
    se = M.std(axis=2, ddof=1) / np.sqrt(T)
    z = np.abs(mean - M_half) / se
    assert z.max() < 5, (mean, M_half, z)
    # the minimiser of the estimated objective is the minimiser of the true half-buffer MSE
    w_true = simplex_minimiser(M_half)
    assert 0.05 < w_true.min() < w_true.max() < 0.95  # an interior optimum: a real test
    np.testing.assert_allclose(simplex_minimiser(mean), w_true, atol=0.02)
    # the test has power: biased estimates of M^half are rejected
    same_half = estimated_mse_matrix(xA, xA, yA, yA).reshape(3, 3, T).mean(axis=2)
    assert (np.abs(same_half - M_half) / se).max() > 20
    yA_saw_B = denoise((xA + xB) / 2)
    leaked = estimated_mse_matrix(xA, xB, yA_saw_B, yB).reshape(3, 3, T).mean(axis=2)
    assert (np.abs(leaked - M_half) / se).max() > 20


# ---------------------------------------------------------------------------------------
# robustness
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("solver", SOLVERS)
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
    w = solve_weights(xa, xb, ya, yb, solver=solver)
    assert w.shape == (n, H, W, 3)
    assert_simplex(w)
    if solver == "exact":
        np.testing.assert_allclose(w[:, 0, 0], 0.25, atol=1e-12)
        np.testing.assert_allclose(w[:, 1, 1], 0.25, atol=1e-12)
    w1 = solve_weights(xa, xb, ya[:1], yb[:1], solver=solver)
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
        solve_weights(xa, xb, ya, yb)
    with pytest.raises(ValueError, match="shape|must"):
        solve_weights(xa, xb, ya[:, :4], yb)
    with pytest.raises(ValueError):
        solve_weights(xa, xb[:4], ya, yb)


# ---------------------------------------------------------------------------------------
# weight filter and combine
# ---------------------------------------------------------------------------------------
def synthetic_scene(build, rng, H=20, W=24, n=3, spp=8):
    """Noisy halves of std 0.2 around a smooth image (``build`` is the make_render_buffers
    fixture) and n base outputs with a per-denoiser colour bias and a little noise."""
    yy, xx = np.mgrid[0:H, 0:W] / max(H, W)
    truth = np.stack([0.5 + 0.4 * np.sin(3 * xx), 0.3 + 0.2 * yy, 0.2 + xx * yy], -1)
    albedo = np.clip(truth, 0, 1)
    normal = np.dstack([np.zeros((H, W)), np.zeros((H, W)), np.ones((H, W))])
    normal[:, W // 2:] = [1.0, 0.0, 0.0]
    buffers = build(truth, albedo=albedo, normal=normal, half_std=0.2, seed=rng, spp=spp)
    xa = buffers.color_a.astype(np.float64)
    xb = buffers.color_b.astype(np.float64)
    bias = rng.normal(0, 0.05, (n, 1, 1, 3))
    ya = truth + bias + rng.normal(0, 0.03, (n, H, W, 3))
    yb = truth + bias + rng.normal(0, 0.03, (n, H, W, 3))
    yf = truth + bias + rng.normal(0, 0.02, (n, H, W, 3))
    inputs = [Denoised(full=yf[i].astype(np.float32), a=ya[i].astype(np.float32),
                       b=yb[i].astype(np.float32)) for i in range(n)]
    return buffers, inputs, (xa, xb, ya, yb, yf, albedo, normal)


def test_filter_weights_simplex_and_constant_fixed_point(make_render_buffers):
    rng = np.random.default_rng(13)
    buffers, inputs, (xa, xb, ya, yb, yf, albedo, normal) = synthetic_scene(make_render_buffers, rng)
    w = solve_weights(xa, xb, ya, yb, solver="exact")
    wf = filter_weights(w, yf, ya, yb, albedo, normal)
    assert wf.shape == w.shape
    assert_simplex(wf)
    assert np.abs(wf - w).max() > 1e-3  # it does filter
    const = np.broadcast_to(rng.dirichlet(np.ones(3), size=3).T[:, None, None, :], w.shape)
    wc = filter_weights(const, yf, ya, yb, albedo, normal)
    np.testing.assert_allclose(wc, const, atol=1e-12)


def _reflect101(i, n):
    """cv::borderInterpolate(i, n, BORDER_REFLECT_101) for |overshoot| < n."""
    return -i if i < 0 else 2 * (n - 1) - i if i >= n else i


def brute_force_weight_filter(weights, y_full, y_a, y_b, albedo, normal, *, radius, sigma_s,
                              sigma_z, sigma_albedo, sigma_normal, colour="sum", border="clip",
                              den_floor=0.0):
    """Sec. 4.2 written out pixel by pixel. weights, y_*: (N, H, W, C). The guide is the raw
    combination z = sum_i w_i y_i of the full outputs, Var[z] = (z^A - z^B)^2 / 2 from the
    half outputs; kappa (Eq. 32) with D^2 of Eq. 33 = sum (``colour="sum"``, the text's
    ||.||^2) or mean over channels of (z_p - z_q)^2 / max(Var_p + Var_q, den_floor); Eq. 34 is
    the kappa-weighted mean of the weight vectors over the square window, clipped at the
    borders (``border="clip"``) or with out-of-image positions reflected (``"reflect101"``,
    OpenCV's BORDER_REFLECT_101: a pixel may count twice)."""
    n, h, w, c = weights.shape
    z = np.einsum("nhwc,nhwc->hwc", weights, y_full)
    var = 0.5 * (np.einsum("nhwc,nhwc->hwc", weights, y_a)
                 - np.einsum("nhwc,nhwc->hwc", weights, y_b)) ** 2
    reduce = np.sum if colour == "sum" else np.mean
    out = np.zeros_like(weights)
    for py in range(h):
        for px in range(w):
            total, norm = np.zeros((n, c)), 0.0
            for dy in range(-radius, radius + 1):
                for dx in range(-radius, radius + 1):
                    qy, qx = py + dy, px + dx
                    if border == "clip":
                        if not (0 <= qy < h and 0 <= qx < w):
                            continue
                    else:
                        qy, qx = _reflect101(qy, h), _reflect101(qx, w)
                    d2 = reduce((z[py, px] - z[qy, qx]) ** 2
                                / np.maximum(var[py, px] + var[qy, qx], den_floor))
                    kappa = (np.exp(-(dy ** 2 + dx ** 2) / (2 * sigma_s ** 2))
                             * np.exp(-d2 / (2 * sigma_z ** 2))
                             * np.exp(-np.sum((albedo[py, px] - albedo[qy, qx]) ** 2)
                                      / (2 * sigma_albedo ** 2))
                             * np.exp(-np.sum((normal[py, px] - normal[qy, qx]) ** 2)
                                      / (2 * sigma_normal ** 2)))
                    total += kappa * weights[:, qy, qx]
                    norm += kappa
            out[:, py, px] = total / norm
    return out


def filter_case(rng, truth, *, n, noise):
    """Random simplex weights (n, H, W, 3), base outputs full/A/B around ``truth`` (H, W, 3) with
    ``noise`` std, albedo in [0.4, 0.6] and normals near +z: the weight filter's inputs."""
    h, w, _ = truth.shape
    weights = rng.dirichlet(np.ones(n), size=(h, w, 3)).transpose(3, 0, 1, 2)
    y_full = truth + rng.normal(0, noise, (n, h, w, 3))
    y_a = y_full + rng.normal(0, noise, (n, h, w, 3))
    y_b = y_full + rng.normal(0, noise, (n, h, w, 3))
    albedo = rng.uniform(0.4, 0.6, (h, w, 3))
    normal = rng.normal(size=(h, w, 3)) * 0.05 + [0.0, 0.0, 1.0]
    return weights, y_full, y_a, y_b, albedo, normal


def test_reflected_borders_and_the_variance_floor_match_brute_force():
    """filter_border="reflect101" and variance_sum_floor (the public code's windows and Eq. 33
    floor) equal the brute-force loop with reflected windows and max(v_p + v_q, floor); clipped
    windows or no floor give another result (the test has power). Tiny variances put the floor in
    its range."""
    radius = 3
    rng = np.random.default_rng(32)
    truth = 0.5 + 0.001 * rng.uniform(size=(9, 10, 3))     # smooth: colour distances ~ noise
    weights, y_full, y_a, y_b, albedo, normal = filter_case(rng, truth, n=3, noise=0.0005)
    params = dict(sigma_s=3.0, sigma_z=2.0, sigma_albedo=0.25, sigma_normal=0.15)
    expected = brute_force_weight_filter(weights, y_full, y_a, y_b, albedo, normal, radius=radius,
                                         border="reflect101", den_floor=1e-6, **params)
    got = filter_weights(weights, y_full, y_a, y_b, albedo, normal, radius=radius, sigma_spatial=3.0,
                         sigma_color=2.0, sigma_albedo=0.25, sigma_normal=0.15,
                         filter_border="reflect101", variance_sum_floor=1e-6)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    for other in (dict(border="clip", den_floor=1e-6), dict(border="reflect101", den_floor=0.0)):
        wrong = brute_force_weight_filter(weights, y_full, y_a, y_b, albedo, normal, radius=radius,
                                          **other, **params)
        assert np.abs(wrong - expected).max() > 1e-3, other


@pytest.mark.parametrize("radius", [7, 2])
def test_filter_weights_matches_eq32_34_brute_force(radius):
    """filter_weights with the paper's parameters (Sec. 4.2: radius 7, sigma_s 3, sigma_z 2,
    sigma_albedo 0.25, sigma_normal 0.15) equals the brute-force loop; the data put every
    factor of kappa in its sensitive range, so a wrong guide, Var factor or sigma fails."""
    rng = np.random.default_rng(31)
    weights, y_full, y_a, y_b, albedo, normal = filter_case(rng, rng.uniform(0.2, 1.0, (9, 11, 3)), n=3, noise=0.05)
    paper = dict(sigma_s=3.0, sigma_z=2.0, sigma_albedo=0.25, sigma_normal=0.15)
    expected = brute_force_weight_filter(weights, y_full, y_a, y_b, albedo, normal,
                                         radius=radius, **paper)
    if radius == 7:
        got = filter_weights(weights, y_full, y_a, y_b, albedo, normal)  # the defaults
    else:
        got = filter_weights(weights, y_full, y_a, y_b, albedo, normal, radius=radius,
                               sigma_spatial=3.0, sigma_color=2.0, sigma_albedo=0.25,
                               sigma_normal=0.15)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
    # sensitivity: each of these deviations moves the result well beyond the tolerance
    for deviation in (dict(sigma_s=2.5), dict(sigma_z=2.5), dict(sigma_albedo=0.3),
                      dict(sigma_normal=0.18)):
        other = brute_force_weight_filter(weights, y_full, y_a, y_b, albedo, normal,
                                          radius=radius, **{**paper, **deviation})
        assert np.abs(other - expected).max() > 1e-4, deviation


@pytest.mark.parametrize("filter_", [True, False])
def test_combine_end_to_end(filter_, make_render_buffers):
    rng = np.random.default_rng(14)
    buffers, inputs, (xa, xb, ya, yb, yf, albedo, normal) = synthetic_scene(make_render_buffers, rng)
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
# a float64, whole-image reference of the blends
# ---------------------------------------------------------------------------------------
FLOAT64_REFERENCE = Path(__file__).resolve().parents[1] / "data" / "ensemble_blend_float64.npz"


@pytest.mark.parametrize("n", [3, 5])
@pytest.mark.parametrize("solver", ["iterative", "exact"])
def test_combine_matches_the_float64_whole_image_blends(n, solver, make_render_buffers,
                                                        monkeypatch):
    """tests/data/ensemble_blend_float64.npz holds the full, A and B blends of this deterministic
    case computed in float64 on the whole image at once (an implementation of the same equations
    without float32 storage, blocks or bands, kept in the repository's history), with the paper's
    filter alone and Eq. 33 averaged over the channels (``PAPER_FILTER``, ``colour_distance="mean"``).
    The float32 filter and the block-wise solve (blocks of 5 rows here, so blocks and filter
    bands both cut the 32 x 36 image) must stay within 1e-6 relMSE of it."""
    monkeypatch.setattr(E, "BLOCK_PIXELS", 5 * 36)
    before = np.load(FLOAT64_REFERENCE)
    buffers, inputs, _ = synthetic_scene(make_render_buffers, np.random.default_rng(100 + n),
                                         H=32, W=36, n=n)
    out = E.combine(buffers, inputs, solver=solver, **dict(PAPER_FILTER, colour_distance="mean"))
    for which in ("full", "a", "b"):
        expected = before[f"{solver}_n{n}_{which}"].astype(np.float64)
        got = out.image(which).astype(np.float64)
        relmse = np.mean((got - expected) ** 2 / (expected ** 2 + 1e-2))
        assert relmse < 1e-6, (which, relmse)
        # power: the unfiltered blend is far from it
    unfiltered = E.combine(buffers, inputs, solver=solver, filter=False).full.astype(np.float64)
    expected = before[f"{solver}_n{n}_full"].astype(np.float64)
    assert np.mean((unfiltered - expected) ** 2 / (expected ** 2 + 1e-2)) > 1e-4


def test_solve_in_blocks_equals_whole_image(monkeypatch, make_render_buffers):
    """combine solves blocks of rows; its raw weights equal solve_weights on the whole image
    bit for bit, for every solver and channel option (the iterative solver's generator is keyed
    by the problem's index in the image)."""
    buffers, inputs, (xa, xb, *_) = synthetic_scene(make_render_buffers,
                                                    np.random.default_rng(7), H=11, W=6, n=3)
    ya, yb = (np.stack([d.image(k) for d in inputs]).astype(np.float64) for k in ("a", "b"))
    monkeypatch.setattr(E, "BLOCK_PIXELS", 2 * 6)      # 2 rows per block, the last one short
    for solver in SOLVERS:
        for channels in CHANNELS:
            whole = solve_weights(xa, xb, ya, yb, solver=solver, channels=channels)
            out = E.combine(buffers, inputs, solver=solver, channels=channels, filter=False)
            got = np.stack([out.extras[f"weights_raw_{i}"] for i in range(3)])
            assert np.array_equal(got, whole.astype(np.float32)), (solver, channels)


# ---------------------------------------------------------------------------------------
# the band-wise pass (bounded memory): tiles with their halos equal the whole image
# ---------------------------------------------------------------------------------------
def test_gaussian_blur_kernel_and_tiles_equal_the_numpy_blur():
    """mcbench.filters.blur_and_outliers.gaussian_blur (numba) equals its NumPy formulation bit for bit, on
    whole images (axes of length 1, 2, 3: NumPy's repeated reflection) and on tiles holding
    only the rows within 4 of the rows asked for (or the image's border)."""
    from mcbench.filters import blur_and_outliers
    rng = np.random.default_rng(3)
    for shape in [(1, 1, 3), (1, 6, 3), (2, 3, 3), (3, 9, 1), (5, 4, 3), (17, 2), (40, 33, 3)]:
        image = rng.normal(size=shape) * 10
        assert np.array_equal(blur_and_outliers.gaussian_blur(image),
                              blur_and_outliers.gaussian_blur_reference(image)), shape
    image = rng.normal(size=(50, 21, 3))
    whole = blur_and_outliers.gaussian_blur_reference(image)
    for r0, r1 in [(0, 1), (0, 10), (3, 30), (20, 21), (40, 50), (46, 50)]:
        v0, v1 = max(0, r0 - 4), min(50, r1 + 4)
        tile = blur_and_outliers.gaussian_blur(image[v0:v1], rows=(r0, r1), first_row=v0, height=50)
        assert np.array_equal(tile, whole[r0:r1]), (r0, r1)
    with pytest.raises(ValueError, match="outside the tile"):
        blur_and_outliers.gaussian_blur(image[10:20], rows=(10, 20), first_row=10, height=50)


def test_filter_rows_of_a_tile_equal_the_whole_filter():
    """cross_bilateral_filter_vectors(rows=...) on a tile holding radius rows around them (or
    the border) gives exactly those rows of the whole image's filter, for bands of the kernel
    that do not line up with the tile (BAND_ROWS 64 against rows cut at 5 and 23)."""
    from mcbench.filters import bilateral
    rng = np.random.default_rng(4)
    h, w, r = 41, 19, 7
    values = rng.dirichlet(np.ones(3), size=(h, w, 3)).transpose(3, 0, 1, 2).astype(np.float32)
    guide = rng.uniform(0.2, 1.0, (h, w, 3))
    var = rng.uniform(0.0, 0.02, (h, w, 3))
    var[5:9, 3:7] = 0.0                          # the zero-variance guard in the tile
    feats = [rng.uniform(0, 1, (h, w, 3)), rng.normal(size=(h, w, 3))]
    args = (feats, [0.25, 0.15], 3.0, 2.0, r)
    whole = bilateral.cross_bilateral_filter_vectors(values, guide, var, *args, dtype=np.float32)
    for o0, o1 in [(0, 5), (5, 23), (23, 41), (12, 13), (0, 41)]:
        f0, f1 = max(0, o0 - r), min(h, o1 + r)
        tile = bilateral.cross_bilateral_filter_vectors(
            values[:, f0:f1], guide[f0:f1], var[f0:f1], [f[f0:f1] for f in feats], *args[1:],
            dtype=np.float32, rows=(o0 - f0, o1 - f0))
        assert np.array_equal(tile, whole[:, o0:o1]), (o0, o1)
    # the kernel's bands: a multiple of the thread count, of equal height (numba gives each
    # thread an equal run of bands), about BAND_ROWS rows (1024 rows on 2 threads: 16 of 64)
    threads = numba.get_num_threads()
    for rows in (1, 6, 70, 134, 1024, 1031):
        band = bilateral._band_rows(rows)
        bands = -(-rows // band)
        assert bands % threads == 0 or band == 1, (rows, band)
        assert bands * band - rows < bands, (rows, band)
    if threads == 2:
        assert bilateral._band_rows(1024) == 64 and bilateral._band_rows(134) == 67


@pytest.mark.parametrize("passes", ["default", "paper"])
@pytest.mark.parametrize("solver", ["iterative", "exact"])
def test_banded_combine_equals_the_whole_image_pass(passes, solver, monkeypatch,
                                                    make_render_buffers):
    """combine's one pass in bands (filter bands of 4 rows, solve blocks of 3, so both cut the
    37 x 23 image everywhere and a band's halo of 14 rows spans several of them) against one
    band and one block for the whole image (one tile, no halo): raw weights
    equal bit for bit; with the paper's filter alone the filtered weights and blends too; with
    the default passes the outlier pass's float64 running sums start at each tile, so within
    rounding (max |dw| 1e-6, blend relMSE 1e-12)."""
    buffers, inputs, _ = synthetic_scene(make_render_buffers, np.random.default_rng(21),
                                         H=37, W=23, n=4)
    # a firefly-like spike so that the outlier pass replaces values near band borders
    inputs[1].a[16:18, 5:8] += 3.0
    options = dict(solver=solver, **(PAPER_FILTER if passes == "paper" else {}))
    monkeypatch.setattr(weight_filter, "FILTER_BLOCK_PIXELS", 10 ** 9)
    monkeypatch.setattr(E, "BLOCK_PIXELS", 10 ** 9)
    whole = E.combine(buffers, inputs, **options)
    monkeypatch.setattr(weight_filter, "FILTER_BLOCK_PIXELS", 4 * 23)
    monkeypatch.setattr(E, "BLOCK_PIXELS", 3 * 23)
    banded = E.combine(buffers, inputs, **options)
    for i in range(4):
        assert np.array_equal(banded.extras[f"weights_raw_{i}"], whole.extras[f"weights_raw_{i}"])
        got, expected = (d.extras[f"weights_filtered_{i}"] for d in (banded, whole))
        if passes == "paper":
            assert np.array_equal(got, expected)
        else:
            assert np.abs(got - expected).max() <= 1e-6
    for which in ("full", "a", "b"):
        got, expected = (d.image(which).astype(np.float64) for d in (banded, whole))
        assert np.mean((got - expected) ** 2 / (expected ** 2 + 1e-2)) < 1e-12
        if passes == "paper":
            assert np.array_equal(got, expected)
    # the filter did act across band borders (the comparison has power)
    raw = np.stack([whole.extras[f"weights_raw_{i}"] for i in range(4)])
    filt = np.stack([whole.extras[f"weights_filtered_{i}"] for i in range(4)])
    assert np.abs(raw - filt).max() > 1e-2


def test_combine_reads_layers_by_rows(tmp_path, monkeypatch, make_render_buffers):
    """The render's layers and the inputs as mcbench.io.exr.LayerRows (read from their files by
    rows, as the declaration's reads_rows allows) give the same output, bit for bit, as the same
    files read whole; a NaN in a file is refused with the whole image's count, as for arrays."""
    from mcbench.io.buffers import RenderBuffers
    from mcbench.io.exr import layer_rows, write_layers

    buffers, inputs, _ = synthetic_scene(make_render_buffers, np.random.default_rng(22),
                                         H=30, W=17, n=3)
    monkeypatch.setattr(weight_filter, "FILTER_BLOCK_PIXELS", 5 * 17)
    monkeypatch.setattr(E, "BLOCK_PIXELS", 4 * 17)
    write_layers(tmp_path / "render.exr", buffers.layers, metadata={"spp": 8})
    paths = [tmp_path / f"in{i}.exr" for i in range(3)]
    for path, d in zip(paths, inputs):
        write_layers(path, {"color": d.full, "color_a": d.a, "color_b": d.b})

    def lazy():
        render = RenderBuffers(layers=layer_rows(tmp_path / "render.exr",
                                                 ["color", *E.METHOD.render_layers]), spp=8)
        return render, [Denoised(full=L["color"], a=L["color_a"], b=L["color_b"])
                        for L in (layer_rows(p) for p in paths)]

    eager = E.combine(RenderBuffers.load(tmp_path / "render.exr", layers=E.METHOD.render_layers),
                      [Denoised.load(p) for p in paths])
    by_rows = E.combine(*lazy())
    for name, layer in eager.layers().items():
        assert np.array_equal(by_rows.layers()[name], layer), name
    bad = inputs[2].b.copy()
    bad[29, 3, 1] = np.nan
    bad[0, 0] = np.inf
    write_layers(paths[2], {"color": inputs[2].full, "color_a": inputs[2].a, "color_b": bad})
    with pytest.raises(ValueError, match=r"non-finite \(NaN/Inf\) values in 2 pixel\(s\) .*"
                                         r"denoised_b: 2"):
        E.combine(*lazy())
