"""The problem every simplex solver solves, and what the solver families share.

Objective (Eq. 11-14). For one pixel-channel with base outputs ``y_i^A, y_i^B`` and noisy
halves ``x^A, x^B``, the estimated MSE matrix is <M> = (<M>^A + <M>^B) / 2 with
<M>^A_ij = x^A x^B - x^B (y_i^A + y_j^A) + y_i^A y_j^A (and A <-> B). Since
<M>^A_ij = (y_i^A - x^B)(y_j^A - x^B) + x^A x^B - (x^B)^2, on the simplex (sum w = 1)

    L(w) = w^T <M> w = 1/2 |A w - b|^2 - 1/2 (x^A - x^B)^2,                     (Eq. 25)

with A the 2 x N matrix whose columns are the points a_i = (y_i^A, y_i^B) and
b = (x^B, x^A) (:func:`objective`). So the minimiser of Eq. 13 is given by the Euclidean
projection p* of b onto the convex hull of the N points a_i, and any simplex weights w with
A w = p*. With D channels sharing one weight vector the points live in R^2D and the objective
is the sum over the channels.
"""

from __future__ import annotations

import numpy as np

from mcbench.jit import cached_njit

__all__ = ["SOLVERS", "CHUNK", "GEOM_TOL", "objective", "clip_normalise"]

SOLVERS = ("iterative", "exact", "qp")   # the ensemble's solver choices (see mcbench.combine.simplex_solvers)
CHUNK = 256  # pixel-channels per parallel work item (scratch arrays are per item)
GEOM_TOL = 1e-10    # distances in units of the pixel's scale (the exact solvers' geometry)


def objective(weights, color_a, color_b, denoised_a, denoised_b) -> np.ndarray:
    """Eq. 13 value L(w) = w^T <M> w per pixel-channel, via Eq. 25.

    weights, denoised_a, denoised_b: (N, H, W, C); color_a, color_b: (H, W, C).
    Returns (H, W, C) float64 (squared radiance units).
    """
    w = np.asarray(weights, np.float64)
    za = np.einsum("nhwc,nhwc->hwc", w, np.asarray(denoised_a, np.float64))
    zb = np.einsum("nhwc,nhwc->hwc", w, np.asarray(denoised_b, np.float64))
    xa = np.asarray(color_a, np.float64)
    xb = np.asarray(color_b, np.float64)
    return 0.5 * ((za - xb) ** 2 + (zb - xa) ** 2) - 0.5 * (xa - xb) ** 2


@cached_njit()
def clip_normalise(w):
    """Weights ``w`` (N,) in place: negatives set to 0, then divided by their sum (1/N each
    when all are 0), against rounding after an update."""
    n = w.shape[0]
    total = 0.0
    for j in range(n):
        if w[j] < 0.0:
            w[j] = 0.0
        total += w[j]
    if total > 0.0:
        for j in range(n):
            w[j] /= total
    else:
        for j in range(n):
            w[j] = 1.0 / n

