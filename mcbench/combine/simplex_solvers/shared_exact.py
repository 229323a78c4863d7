"""The exact simplex solver for one weight vector shared by the channels (Zheng et al. 2021
Sec. 5.2.3; the problem: :mod:`mcbench.combine.simplex_solvers.problem`).

:func:`shared_exact_weights` (one weight vector shared by D channels, Sec. 5.2.3): projects b
onto the hull of the points in R^2D by Wolfe's minimum-norm-point algorithm (finite, exact up
to a Frank-Wolfe gap of 1e-13 scale^2; coincident points -- identical outputs -- share their
weight equally; the weights are unique when the distinct points are affinely independent,
otherwise Wolfe's deterministic answer, not necessarily the minimum-norm one).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.combine.simplex_solvers.problem import CHUNK, GEOM_TOL, clip_normalise
from mcbench.jit import cached_njit

__all__ = ["shared_exact_weights"]

_WOLFE_GAP_TOL = 1e-13   # Frank-Wolfe gap x.(x - q_j), in units of the scale^2
_WOLFE_PIVOT_TOL = 1e-14  # singular affine system (relative to its largest entry)


@cached_njit()
def _affine_min_norm(q, support, k, kkt, alpha):
    """alpha minimising |sum_t alpha_t q[support[t]]|^2 subject to sum_t alpha_t = 1, from
    the (k + 1) x (k + 1) KKT system [G 1; 1^T 0] by Gaussian elimination with partial
    pivoting (G the Gram matrix of the support). Returns False if the system is singular
    (affinely dependent support)."""
    dim = q.shape[1]
    m = k + 1
    for r in range(k):
        for c in range(k):
            g = 0.0
            for e in range(dim):
                g += q[support[r], e] * q[support[c], e]
            kkt[r, c] = g
        kkt[r, k] = 1.0
        kkt[k, r] = 1.0
        kkt[r, m] = 0.0
    kkt[k, k] = 0.0
    kkt[k, m] = 1.0
    big = 1e-300
    for r in range(m):
        for c in range(m):
            big = max(big, abs(kkt[r, c]))
    for col in range(m):
        piv = col
        for r in range(col + 1, m):
            if abs(kkt[r, col]) > abs(kkt[piv, col]):
                piv = r
        if abs(kkt[piv, col]) <= _WOLFE_PIVOT_TOL * big:
            return False
        if piv != col:
            for c in range(m + 1):
                t = kkt[col, c]
                kkt[col, c] = kkt[piv, c]
                kkt[piv, c] = t
        for r in range(col + 1, m):
            f = kkt[r, col] / kkt[col, col]
            for c in range(col, m + 1):
                kkt[r, c] -= f * kkt[col, c]
    for r in range(m - 1, -1, -1):
        acc = kkt[r, m]
        for c in range(r + 1, m):
            acc -= kkt[r, c] * kkt[c, m]
        kkt[r, m] = acc / kkt[r, r]
    for t in range(k):
        alpha[t] = kkt[t, m]
    return True


@cached_njit()
def _wolfe_one(q, w, x, support, lam, alpha, kkt):
    """Minimum-norm point of the convex hull of the rows of q (N, D): Wolfe (1976). Writes
    its simplex weights w (N,); returns the number of major and minor steps."""
    n, dim = q.shape
    q2max = 1e-300
    j0 = 0
    best = np.inf
    for j in range(n):
        nj = 0.0
        for e in range(dim):
            nj += q[j, e] * q[j, e]
        q2max = max(q2max, nj)
        if nj < best:
            best = nj
            j0 = j
    support[0] = j0
    lam[0] = 1.0
    k = 1
    steps = 0
    max_steps = 50 * n + 50
    while steps < max_steps:
        for e in range(dim):
            x[e] = 0.0
            for t in range(k):
                x[e] += lam[t] * q[support[t], e]
        xx = 0.0
        for e in range(dim):
            xx += x[e] * x[e]
        # major cycle: the point most in the direction of -x (Frank-Wolfe vertex)
        jbest = 0
        low = np.inf
        for j in range(n):
            xq = 0.0
            for e in range(dim):
                xq += x[e] * q[j, e]
            if xq < low:
                low = xq
                jbest = j
        if xx - low <= _WOLFE_GAP_TOL * q2max:
            break  # optimal: no point improves on x
        present = False
        for t in range(k):
            if support[t] == jbest:
                present = True
        if present:
            break  # rounding: x is as good as this support allows
        support[k] = jbest
        lam[k] = 0.0
        k += 1
        # minor cycles: affine minimiser of the support, stepping back into the simplex
        while steps < max_steps:
            steps += 1
            if not _affine_min_norm(q, support, k, kkt, alpha):
                steps = max_steps  # dependent support (rounding): keep the last feasible lam
                break
            positive = True
            for t in range(k):
                if alpha[t] <= 0.0:
                    positive = False
            if positive:
                for t in range(k):
                    lam[t] = alpha[t]
                break
            theta = 1.0
            for t in range(k):
                if alpha[t] <= 0.0 and lam[t] - alpha[t] > 0.0:
                    theta = min(theta, lam[t] / (lam[t] - alpha[t]))
            kept = 0
            total = 0.0
            for t in range(k):
                val = (1.0 - theta) * lam[t] + theta * alpha[t]
                if val > 1e-15:
                    support[kept] = support[t]
                    lam[kept] = val
                    total += val
                    kept += 1
            if kept == 0:  # cannot happen in exact arithmetic; restart from the best vertex
                support[0] = jbest
                lam[0] = 1.0
                kept = 1
                total = 1.0
            k = kept
            for t in range(k):
                lam[t] /= total
    for j in range(n):
        w[j] = 0.0
    for t in range(k):
        w[support[t]] += lam[t]
    clip_normalise(w)
    return steps


@cached_njit(parallel=True)
def shared_exact_weights(ya, yb, xa, xb):
    """Exact weights shared by D channels (Wolfe): ya, yb (P, N, D); xa, xb (P, D). Minimises
    sum_d 1/2 |A_d w - b_d|^2 on the simplex: the projection of b = (x^B, x^A) in R^2D onto
    the hull of the points a_i = (y_i^A, y_i^B), divided by the problem's scale. Returns
    weights (P, N) and step counts (P,)."""
    P, n, dim = ya.shape
    out = np.empty((P, n))
    steps = np.empty(P, np.int64)
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        q = np.empty((n, 2 * dim))
        group = np.empty(n, np.int64)
        size = np.empty(n, np.int64)
        w = np.empty(n)
        x = np.empty(2 * dim)
        support = np.empty(n + 1, np.int64)
        lam = np.empty(n + 1)
        alpha = np.empty(n + 1)
        kkt = np.empty((n + 2, n + 3))
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            s = 1e-30
            for e in range(dim):
                s = max(s, abs(xa[p, e]), abs(xb[p, e]))
                for j in range(n):
                    s = max(s, abs(ya[p, j, e]), abs(yb[p, j, e]))
            # coincident points (identical outputs) are one point of the hull: solve on the
            # distinct ones, then split each one's weight equally (the minimum-norm split)
            m = 0
            for j in range(n):
                group[j] = -1
                for g in range(m):
                    same = True
                    for e in range(dim):
                        if (abs((ya[p, j, e] - xb[p, e]) / s - q[g, e]) > GEOM_TOL
                                or abs((yb[p, j, e] - xa[p, e]) / s - q[g, dim + e]) > GEOM_TOL):
                            same = False
                    if same:
                        group[j] = g
                        size[g] += 1
                        break
                if group[j] < 0:
                    for e in range(dim):
                        q[m, e] = (ya[p, j, e] - xb[p, e]) / s
                        q[m, dim + e] = (yb[p, j, e] - xa[p, e]) / s
                    group[j] = m
                    size[m] = 1
                    m += 1
            if m == 1:
                w[0] = 1.0
                steps[p] = 0
            else:
                steps[p] = _wolfe_one(q[:m], w[:m], x, support, lam, alpha, kkt)
            for j in range(n):
                out[p, j] = w[group[j]] / size[group[j]]
    return out, steps
