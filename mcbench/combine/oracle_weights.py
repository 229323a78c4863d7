"""Weights from ground-truth statistics: the oracle study of Zheng et al. 2021 Sec. 5.2.7 (Fig. 11).

A scene rendered R times at one spp with independent seeds gives, per pixel and channel, R
samples of every base denoiser's output y_i. Against the ground truth mu (the reference) the
true MSE matrix of the full-buffer outputs (Eq. 6-7)

    M_ij = E[(y_i - mu)(y_j - mu)],          so that E[(w.y - mu)^2] = w^T M w  (sum w = 1)

is estimated by its sample mean over the repetitions, and the half-buffer matrix M^half (Eq. 15,
whose estimate the dual-buffer <M> of Eq. 11-12 is) by the same mean over the half-buffer
outputs y_i^A and y_i^B of every repetition (2R i.i.d. samples: A and B are rendered alike).
:class:`MseMatrixAccumulator` keeps float64 running sums, one outer product per sample.

From a matrix (any PSD N x N per pixel-channel, not the 2-D geometry of the ensemble's
dual-buffer problems) three weight maps are solved:

* :func:`one_hot_weights` -- 1 for the output of least MSE (the diagonal), ties to the lowest
  index (:func:`mcbench.combine.selection.one_hot_selection`);
* :func:`unconstrained_weights` -- min w^T M w subject to sum w = 1 (Eq. 5-6 without w >= 0;
  Eq. 19's M^-1 1 / 1^T M^-1 1 when M is non-singular): with Q an orthonormal basis of the
  plane sum w = 0 and w = 1/N + Q v, the minimisers are v = -(Q^T M Q)^+ Q^T M 1/N; we return
  the minimum-norm one (no null-space part). The pseudo-inverse drops eigenvalues below
  max(1e-10 lambda_max, 1e-13) in units of the problem's scale s = max_i M_ii, so
  |w - 1/N| <= sqrt(N) / 1e-13: finite, never NaN/Inf; M = 0 gives 1/N;
* :func:`simplex_weights` -- min w^T M w on the simplex (Eq. 13 with the true M): exact by
  enumeration of supports. The minimiser of least support S has no other minimiser on the
  affine hull of its face (else moving along them would reach a smaller face), so it is the
  unconstrained solution on S; every support's solution is computed, the feasible ones
  (w >= -1e-9, then clipped) compared by objective, ties (within 1e-12 s + 1e-10 of the
  optimum) to the least Euclidean norm (identical outputs share their weight equally).
  2^N - 1 supports: N <= :data:`MAX_SIMPLEX_N`.

Layouts: outputs and weights (N, H, W, C) like the ensemble's; matrices (H, W, C, N, N), one
problem per pixel-channel; the per-problem solvers take (P, N, N). The study's tables and
figure are in :mod:`mcbench.analysis.oracle_tables`.
"""

from __future__ import annotations

import numpy as np

from mcbench.combine.selection import check_finite_arrays, one_hot_selection

__all__ = ["MAX_SIMPLEX_N", "MseMatrixAccumulator", "quadratic_objective", "unconstrained_problem_weights",
           "simplex_problem_weights", "one_hot_weights", "unconstrained_weights", "simplex_weights",
           "block_average", "UNCONSTRAINED_RANGE"]

MAX_SIMPLEX_N = 10
EIGEN_REL_TOL = 1e-10     # pseudo-inverse: eigenvalues relative to the largest ...
EIGEN_ABS_TOL = 1e-13     # ... and absolute, in units of the problem's scale max_i M_ii
FEASIBLE_TOL = 1e-9       # a support's solution counts as on the simplex above -this
TIE_ABS_TOL = 1e-12       # objectives this close (units of the scale, plus TIE_REL_TOL relative) tie
TIE_REL_TOL = 1e-10
UNCONSTRAINED_RANGE = (-1.0, 2.0)   # colour scale of unconstrained weight maps (centred at 0.5)


class MseMatrixAccumulator:
    """Running float64 sums of (y_i - mu)(y_j - mu) over samples of N outputs, per pixel-channel.

    ``reference``: mu, (H, W, C); ``count``: N outputs per sample. :meth:`add` takes one sample
    (N, H, W, C) (e.g. the base denoisers' results on one repetition); :meth:`matrix` is the
    sample mean, an unbiased estimate of M (Eq. 7) since mu is given, not estimated.
    """

    def __init__(self, reference, *, count: int):
        self.reference = np.asarray(reference, np.float64)
        if self.reference.ndim != 3 or int(count) < 1:
            raise ValueError(f"reference must be (H, W, C) and count >= 1, got {self.reference.shape}, {count}")
        check_finite_arrays({"reference": self.reference}, what="the MSE-matrix accumulator")
        self.count = int(count)
        self.samples = 0
        self.sums = np.zeros(self.reference.shape + (self.count, self.count))

    def add(self, outputs) -> None:
        """Add one sample: ``outputs`` (N, H, W, C), finite."""
        y = np.asarray(outputs, np.float64)
        if y.shape != (self.count,) + self.reference.shape:
            raise ValueError(f"outputs {y.shape} must be (N, H, W, C) = {(self.count,) + self.reference.shape}")
        check_finite_arrays({"outputs": y}, what="the MSE-matrix accumulator")
        error = y - self.reference[None]
        self.sums += np.einsum("ihwc,jhwc->hwcij", error, error)
        self.samples += 1

    def matrix(self) -> np.ndarray:
        """(H, W, C, N, N) float64: the mean of the outer products added so far."""
        if not self.samples:
            raise ValueError("no samples added to the MSE-matrix accumulator")
        return self.sums / self.samples


def quadratic_objective(weights, matrix) -> np.ndarray:
    """w^T M w per pixel-channel: weights (N, H, W, C), matrix (H, W, C, N, N) -> (H, W, C)."""
    w = np.asarray(weights, np.float64)
    return np.einsum("ihwc,hwcij,jhwc->hwc", w, np.asarray(matrix, np.float64), w)


def _problems(matrices) -> np.ndarray:
    m = np.asarray(matrices, np.float64)
    if m.ndim != 3 or m.shape[1] != m.shape[2] or m.shape[1] < 1:
        raise ValueError(f"matrices must be (P, N, N) with N >= 1, got shape {m.shape}")
    check_finite_arrays({"MSE matrices": m}, what="the oracle weight solver")
    return 0.5 * (m + np.swapaxes(m, 1, 2))


def _scales(m: np.ndarray) -> np.ndarray:
    return np.maximum(np.abs(np.diagonal(m, axis1=1, axis2=2)).max(axis=1), 1e-300)


def _zero_sum_basis(n: int) -> np.ndarray:
    """(N, N-1) orthonormal basis of {v : sum v = 0} (Helmert's contrasts)."""
    basis = np.zeros((n, n - 1))
    for k in range(1, n):
        basis[:k, k - 1] = 1.0
        basis[k, k - 1] = -k
        basis[:, k - 1] /= np.sqrt(k * (k + 1.0))
    return basis


def _min_norm_sum_to_one(m: np.ndarray) -> np.ndarray:
    """(P, N, N) scaled symmetric PSD -> (P, N) minimum-norm minimisers on sum w = 1."""
    count, n, _ = m.shape
    if n == 1:
        return np.ones((count, 1))
    q = _zero_sum_basis(n)
    centre = np.full(n, 1.0 / n)
    reduced = np.einsum("ai,pab,bj->pij", q, m, q)
    gradient = np.einsum("ai,pab,b->pi", q, m, centre)
    lam, vec = np.linalg.eigh(reduced)
    keep = lam > np.maximum(EIGEN_REL_TOL * lam[:, -1:], EIGEN_ABS_TOL)
    inverse = np.divide(1.0, lam, out=np.zeros_like(lam), where=keep)
    v = -np.einsum("pik,pk->pi", vec, inverse * np.einsum("pik,pi->pk", vec, gradient))
    w = centre + v @ q.T
    return w + (1.0 - w.sum(axis=1, keepdims=True)) / n


def unconstrained_problem_weights(matrices) -> np.ndarray:
    """Minimum-norm minimiser of w^T M w subject to sum w = 1 (any sign), per problem.

    matrices : (P, N, N) PSD (symmetrised; finite). Each problem is divided by its scale
    max_i M_ii (floor 1e-300). Returns (P, N) float64, sum 1, finite (module docstring)."""
    m = _problems(matrices)
    return _min_norm_sum_to_one(m / _scales(m)[:, None, None])


def simplex_problem_weights(matrices) -> np.ndarray:
    """Minimiser of w^T M w on the simplex (w >= 0, sum 1), per problem, exact by support
    enumeration (module docstring); ties to the least norm.

    matrices : (P, N, N) PSD, N <= :data:`MAX_SIMPLEX_N`. Returns (P, N) float64 >= 0, sum 1."""
    m = _problems(matrices)
    count, n, _ = m.shape
    if n > MAX_SIMPLEX_N:
        raise ValueError(f"exact simplex weights support N <= {MAX_SIMPLEX_N} outputs, got {n}")
    m = m / _scales(m)[:, None, None]
    best = np.zeros((count, n))
    best_objective = np.full(count, 1e300)      # every singleton is feasible and beats it
    best_norm = np.full(count, 1e300)
    for mask in range(1, 1 << n):
        support = [i for i in range(n) if mask >> i & 1]
        local = _min_norm_sum_to_one(m[:, support][:, :, support])
        feasible = (local >= -FEASIBLE_TOL).all(axis=1)
        local = np.maximum(local, 0.0)
        local /= local.sum(axis=1, keepdims=True)
        w = np.zeros((count, n))
        w[:, support] = local
        objective = np.einsum("pi,pij,pj->p", w, m, w)
        norm = np.einsum("pi,pi->p", w, w)
        tolerance = TIE_ABS_TOL + TIE_REL_TOL * np.abs(best_objective)
        better = feasible & ((objective < best_objective - tolerance) |
                             ((objective <= best_objective + tolerance) & (norm < best_norm - 1e-12)))
        best[better], best_objective[better], best_norm[better] = w[better], objective[better], norm[better]
    return best


def _per_pixel(solve, matrix) -> np.ndarray:
    m = np.asarray(matrix, np.float64)
    if m.ndim != 5 or m.shape[3] != m.shape[4]:
        raise ValueError(f"matrix must be (H, W, C, N, N), got shape {m.shape}")
    h, wd, c, n, _ = m.shape
    w = solve(m.reshape(-1, n, n))
    return np.ascontiguousarray(np.moveaxis(w.reshape(h, wd, c, n), 3, 0))


def one_hot_weights(matrix) -> np.ndarray:
    """(H, W, C, N, N) -> (N, H, W, C): 1 for the output of least M_ii, ties to the lowest index."""
    m = np.asarray(matrix, np.float64)
    if m.ndim != 5 or m.shape[3] != m.shape[4]:
        raise ValueError(f"matrix must be (H, W, C, N, N), got shape {m.shape}")
    return one_hot_selection(np.moveaxis(np.diagonal(m, axis1=3, axis2=4), 3, 0))


def unconstrained_weights(matrix) -> np.ndarray:
    """(H, W, C, N, N) -> (N, H, W, C): :func:`unconstrained_problem_weights` per pixel-channel."""
    return _per_pixel(unconstrained_problem_weights, matrix)


def simplex_weights(matrix) -> np.ndarray:
    """(H, W, C, N, N) -> (N, H, W, C): :func:`simplex_problem_weights` per pixel-channel."""
    return _per_pixel(simplex_problem_weights, matrix)


def block_average(image, factor: int) -> np.ndarray:
    """Mean over ``factor`` x ``factor`` pixel blocks: (H, W, C) -> (H/f, W/f, C), float64.

    With the harness's box pixel filter a pixel's expected value is the mean radiance over its
    footprint, so the block mean of a reference is the reference of the same camera at 1/f the
    resolution (exactly, in expectation). H and W must be multiples of ``factor``."""
    x = np.asarray(image, np.float64)
    f = int(factor)
    if f < 1 or x.ndim != 3 or x.shape[0] % f or x.shape[1] % f:
        raise ValueError(f"cannot average {x.shape[:2]} pixels in {factor} x {factor} blocks")
    h, w, c = x.shape
    return x.reshape(h // f, f, w // f, f, c).mean(axis=(1, 3))
