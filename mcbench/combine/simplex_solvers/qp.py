"""The general-purpose QP solver of the simplex problem, the slow baseline of Zheng et al. 2021
Fig. 6 (Sec. 5.2.2; the problem: :mod:`mcbench.combine.simplex_solvers.problem`).

:func:`qp_simplex_weights` (Sec. 5.2.2, the slow baseline of Fig. 6): one call per problem to
the general QP solver ``qpsolvers.solve_qp`` (backend :data:`QP_BACKEND`, quadprog: dense,
active-set), on data divided by the problem's scale with a ridge of 1e-12 (quadprog needs a
definite matrix; A^T A has rank <= 2 per pixel-channel).
"""

from __future__ import annotations

import numpy as np

__all__ = ["QP_BACKEND", "qp_simplex_weights"]

QP_BACKEND = "quadprog"
_QP_RIDGE = 1e-12    # added to A^T A (units of the scale^2): quadprog needs it definite


def qp_simplex_weights(points, targets) -> np.ndarray:
    """Minimiser of 1/2 |A w - b|^2 on the simplex for each problem, by the general QP solver
    ``qpsolvers.solve_qp`` (backend ``QP_BACKEND``), one call per problem.

    points : (P, N, D) float64 (point a_i = column i of A); targets : (P, D) float64 (b).
    Each problem is divided by its scale s = max(|a|, |b|) (floor 1e-30) and regularised
    with 1e-12 I (the objective moves by at most 5e-13 s^2); the answer is clipped to
    w >= 0 and renormalised. Returns (P, N) float64. Raises ValueError if the backend
    fails on a problem even with a ridge of 1e-8.
    """
    import qpsolvers  # only this slow path needs it

    a = np.asarray(points, np.float64)
    b = np.asarray(targets, np.float64)
    count, n, _ = a.shape
    out = np.ones((count, n))
    if n == 1:
        return out
    G, h = -np.eye(n), np.zeros(n)
    A_eq, b_eq = np.ones((1, n)), np.ones(1)
    for p in range(count):
        s = max(float(np.abs(a[p]).max()), float(np.abs(b[p]).max()), 1e-30)
        at = a[p] / s                                  # (N, D) = A^T
        gram = at @ at.T
        linear = -(at @ (b[p] / s))
        w = None
        for ridge in (_QP_RIDGE, 1e-8):
            w = qpsolvers.solve_qp(gram + ridge * np.eye(n), linear, G=G, h=h, A=A_eq,
                                   b=b_eq, solver=QP_BACKEND)
            if w is not None and np.all(np.isfinite(w)):
                break
            w = None
        if w is None:
            raise ValueError(f"QP solver {QP_BACKEND} failed on ensemble problem {p}")
        w = np.maximum(w, 0.0)
        out[p] = w / w.sum()
    return out

