"""Unconstrained ensemble weights (Zheng et al. 2021 Sec. 5.2.1 ablation): sum to one, any sign (the
problem: :mod:`mcbench.combine.simplex_solvers.problem`).

Unconstrained weights (Sec. 5.2.1): sum w = 1 without w >= 0. The paper's closed form
w = M^-1 1 / (1^T M^-1 1) (Eq. 19) needs a non-singular matrix, but on sum w = 1 the objective
is 1/2 |A w - b|^2 + const, i.e. <M> may be replaced by 1/2 C^T C (C = A - b 1^T, rank <= 2):
singular for N > 2, and for N > 3 the minimisers form an affine set (Eq. 19 with a
pseudo-inverse is then not even a minimiser in general). **Departure:** we return the
minimum-norm minimiser, w = 1/N + D^+ (b - a_bar) (D the centred points: the KKT conditions of
the equality-constrained least squares; D's rows are orthogonal to 1). For N = 2 with
non-singular <M> this is Eq. 19, for N = 3 points in general position the unique A w = b. The
pseudo-inverse drops directions with singular values below max(1e-6 sigma_max,
1e-11 sqrt(N)) in units of the scale, so |w - 1/N| < 5e11 / sqrt(N): finite, never NaN/Inf;
the sum is restored to one against rounding. :func:`unconstrained_weights` is the per
pixel-channel form (through the exact solver's 2 x 2 scatter pseudo-inverse, the same
thresholds up to sqrt(trace) for sigma_max), :func:`unconstrained_least_squares` the general
one (an SVD, any D).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.combine.simplex_solvers.exact import min_norm_on_support
from mcbench.combine.simplex_solvers.problem import CHUNK
from mcbench.jit import cached_njit

__all__ = ["unconstrained_weights", "unconstrained_least_squares"]

_SV_REL_TOL = 1e-6    # singular values of the centred points, relative to the largest
_SV_ABS_TOL = 1e-11   # ... and absolute, in units of the scale (per sqrt(N))


@cached_njit(parallel=True)
def unconstrained_weights(ya, yb, xa, xb):
    """Per pixel-channel: ya, yb (P, N); xa, xb (P,). The minimum-norm minimiser of
    1/2 |A w - b|^2 subject to sum w = 1 (no sign constraint): w = 1/N + D^+ (b - a_bar)
    with D the centred 2 x N points, via the 2 x 2 scatter's pseudo-inverse of the exact
    solver (its thresholds bound |w|). Returns weights (P, N)."""
    P, n = ya.shape
    out = np.empty((P, n))
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        u = np.empty(n)
        v = np.empty(n)
        idx = np.arange(n)
        wtmp = np.empty(n)
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            s = max(1e-30, abs(xa[p]), abs(xb[p]))
            for j in range(n):
                s = max(s, abs(ya[p, j]), abs(yb[p, j]))
            for j in range(n):
                u[j] = ya[p, j] / s
                v[j] = yb[p, j] / s
            # feasibility flag ignored: b need not lie in the points' affine hull
            min_norm_on_support(u, v, idx, n, xb[p] / s, xa[p] / s, wtmp)
            total = 0.0
            for j in range(n):
                total += wtmp[j]
            for j in range(n):  # the sum against rounding amplified by large weights
                out[p, j] = wtmp[j] + (1.0 - total) / n
    return out


def unconstrained_least_squares(points, targets) -> np.ndarray:
    """Minimum-norm minimiser of 1/2 |A w - b|^2 subject to sum_i w_i = 1, w of any sign.

    points : (P, N, D) float64, row i of problem p is the point a_i (a column of A);
    targets : (P, D) float64, b. Each problem is divided by its scale
    s = max(|a|, |b|) (floor 1e-30). With D the centred points a_i - a_bar (D x N) the
    solutions are w = 1/N + D^+ (b - a_bar) + null(D) (the KKT conditions of the
    equality-constrained least squares; D's rows are orthogonal to 1), the minimum-norm one
    has no null-space part. D^+ keeps singular values above max(1e-6 sigma_max,
    1e-11 sqrt(N)) (units of s), so |w - 1/N| <= |b - a_bar| / (1e-11 sqrt(N)) < 5e11 /
    sqrt(N): finite, never NaN/Inf. Returns (P, N) float64 weights (sum 1, restored
    against rounding by adding (1 - sum) / N).
    """
    a = np.asarray(points, np.float64)
    b = np.asarray(targets, np.float64)
    n = a.shape[1]
    scale = np.maximum(np.maximum(np.abs(a).max(axis=(1, 2)), np.abs(b).max(axis=1)), 1e-30)
    a = a / scale[:, None, None]
    b = b / scale[:, None]
    a_bar = a.mean(axis=1)
    centred = np.swapaxes(a - a_bar[:, None, :], 1, 2)              # (P, D, N)
    u, sv, vt = np.linalg.svd(centred, full_matrices=False)        # (P,D,K) (P,K) (P,K,N)
    keep = sv > np.maximum(_SV_REL_TOL * sv[:, :1], _SV_ABS_TOL * np.sqrt(n))
    inverse = np.divide(1.0, sv, out=np.zeros_like(sv), where=keep)
    coef = np.einsum("pdk,pd->pk", u, b - a_bar) * inverse
    w = 1.0 / n + np.einsum("pkn,pk->pn", vt, coef)
    return w + (1.0 - w.sum(axis=1, keepdims=True)) / n   # the sum against rounding
