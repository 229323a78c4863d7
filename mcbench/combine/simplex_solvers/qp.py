"""The general-purpose QP solver of the simplex problem, the slow baseline of Zheng et al. 2021
Fig. 6 (Sec. 5.2.2; the problem: :mod:`mcbench.combine.simplex_solvers.problem`).

:func:`qp_simplex_weights` (Sec. 5.2.2, the slow baseline of Fig. 6): one call per problem to
the general QP solver quadprog (:data:`QP_BACKEND`: dense, active-set; Goldfarb-Idnani), on data
divided by the problem's scale with a ridge of 1e-12 (quadprog needs a definite matrix; A^T A has
rank <= 2 per pixel-channel). quadprog's ``solve_qp`` is called directly with the matrices that
``qpsolvers.solve_qp(..., solver="quadprog")`` hands it (cost P, -q, the constraints
-[A_eq; G]^T and -[b_eq; h] with one equality): the same weights bit for bit
(``tests/combine/test_qp_simplex.py``), without qpsolvers' problem building per call, which was
two thirds of this baseline's time at 128x128 (49 152 problems of a few unknowns each). The
authors' baseline is FBstab in C++ (docs/fidelity_ensemble.md); a per-pixel Python wrapper would
inflate the slow baseline beyond what a general QP solver costs.
"""

from __future__ import annotations

import numpy as np

__all__ = ["QP_BACKEND", "qp_simplex_weights", "qp_simplex_weights_through_qpsolvers"]

QP_BACKEND = "quadprog"
_QP_RIDGE = 1e-12    # added to A^T A (units of the scale^2): quadprog needs it definite


def qp_simplex_weights(points, targets) -> np.ndarray:
    """Minimiser of 1/2 |A w - b|^2 on the simplex for each problem, by the general QP solver
    quadprog (``QP_BACKEND``), one call per problem.

    points : (P, N, D) float64 (point a_i = column i of A); targets : (P, D) float64 (b).
    Each problem is divided by its scale s = max(|a|, |b|) (floor 1e-30) and regularised
    with 1e-12 I (the objective moves by at most 5e-13 s^2); the answer is clipped to
    w >= 0 and renormalised. Returns (P, N) float64. Raises ValueError if the backend
    fails on a problem even with a ridge of 1e-8.
    """
    from quadprog import solve_qp  # only this slow path needs it

    n = np.shape(points)[1]
    # w >= 0 (G w <= h) and sum(w) = 1 (A_eq w = b_eq) in quadprog's form C^T w >= c, the
    # equality first (meq = 1), built as qpsolvers builds them
    G, h, A_eq, b_eq = -np.eye(n), np.zeros(n), np.ones((1, n)), np.ones(1)
    constraints, bounds = -np.vstack([A_eq, G]).T, -np.hstack([b_eq, h])

    def solve(cost, linear, p):
        try:
            return solve_qp(cost, -linear, constraints, bounds, 1)[0]
        except ValueError as error:          # qpsolvers: None where quadprog finds no solution
            if "positive definite" in str(error):
                raise ValueError(f"QP solver {QP_BACKEND}: ensemble problem {p}: {error}") from error
            return None

    return _simplex_weights(points, targets, solve)


def qp_simplex_weights_through_qpsolvers(points, targets) -> np.ndarray:
    """:func:`qp_simplex_weights` through ``qpsolvers.solve_qp(..., solver="quadprog")`` per
    problem (qpsolvers returns None where quadprog finds no solution): the library path that the
    direct call must equal bit for bit (``tests/combine/test_qp_simplex.py``) and the baseline of
    ``benchmarks/qp_baseline.py``."""
    import qpsolvers

    def solve(cost, linear, p):
        n = cost.shape[0]
        return qpsolvers.solve_qp(cost, linear, G=-np.eye(n), h=np.zeros(n), A=np.ones((1, n)), b=np.ones(1),
                                  solver=QP_BACKEND)

    return _simplex_weights(points, targets, solve)


def _simplex_weights(points, targets, solve) -> np.ndarray:
    """The problems of :func:`qp_simplex_weights`, each scaled, regularised (ridge 1e-12, then
    1e-8 where ``solve(cost, linear, p)`` gives None or non-finite weights), clipped to w >= 0
    and renormalised."""
    a = np.asarray(points, np.float64)
    b = np.asarray(targets, np.float64)
    count, n, _ = a.shape
    out = np.ones((count, n))
    if n == 1:
        return out
    ridges = [ridge * np.eye(n) for ridge in (_QP_RIDGE, 1e-8)]
    for p in range(count):
        s = max(float(np.abs(a[p]).max()), float(np.abs(b[p]).max()), 1e-30)
        at = a[p] / s                                  # (N, D) = A^T
        gram = at @ at.T
        linear = -(at @ (b[p] / s))
        w = None
        for ridge in ridges:
            w = solve(gram + ridge, linear, p)
            if w is not None and np.all(np.isfinite(w)):
                break
            w = None
        if w is None:
            raise ValueError(f"QP solver {QP_BACKEND} failed on ensemble problem {p}")
        w = np.maximum(w, 0.0)
        out[p] = w / w.sum()
    return out
