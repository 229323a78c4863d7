"""The paper's iterative solver of the simplex problem (Zheng et al. 2021 Sec. 4.1; the problem:
:mod:`mcbench.combine.simplex_solvers.problem`).

:func:`iterative_weights` (Sec. 4.1, the paper's): a start (:data:`STARTS`: the paper's random
one, or the best vertex, or the best two-denoiser ensemble by Eq. 29 over all pairs), then
repeatedly combine the current ensemble z = (w.y^A, w.y^B) with one base denoiser through the
two-denoiser closed form (Eq. 29, c1 and c2 summed over the D channels) and update
w <- (1 - alpha) w + alpha e_i (Eq. 31); the denoiser is chosen cycling through all N in a
freshly shuffled order per cycle; stop when no weight moved by more than ``tolerance`` over a
whole cycle or after ``max_iterations`` iterations.
**Alpha's range (``away_steps``).** The paper clips alpha to [0, 1] (Eq. 29, "clamps the value
into [0, 1]"; Sec. 4.1.2: "we always clamp alpha to [0, 1]"), and so does the authors' code
(``alpha = std::clamp(b / a, 0.0, 1.0)``, src/solve.h:112 at becc556): weight only ever moves
*towards* the chosen denoiser, and a denoiser that should get weight 0 loses it only as the
others gain (geometrically slowly). That is the default (``away_steps=False``). With
``away_steps=True`` (our option) alpha is clipped to the whole feasible segment of the line
through w and e_i, [-w_i / (1 - w_i), 1]: a negative alpha is the same closed form moving weight
*off* denoiser i, down to w_i = 0 (exactly 0 at the bound). Either way every step is the exact
minimiser of Eq. 13 on its (clipped) segment, so the objective never increases, and w is
renormalised after each update against rounding (as the code does, src/solve.h:116).
tests/combine/test_ensemble.py compares how many problems reach the optimum with either.
**c1 (Eq. 29's denominator):** the text divides by c1 with no floor; the code floors it,
``std::max(c1, 1e-6)`` (src/solve.h:92, :110), an absolute constant that shrinks every step of
dark pixels (radiance differences below ~1e-3) by the factor c1 / 1e-6. The text decides: no
floor; only c1 = 0 (then c2 = 0: the ensemble equals denoiser i) leaves w unchanged.
**Stop:** the paper stops when "w is not changing for several iterations" or at 1024; this solver stops
after a whole cycle of N updates none of which moved a weight by more than ``tolerance`` (the
code: 2N + 1 consecutive steps with alpha < 1e-10, src/solve.h:91, :104, :113).
**Departure (random numbers):** a counter-based splitmix64 generator seeded from
(seed, problem index in the image), not ``np.random``: inside numba ``prange`` loops
``np.random`` draws from per-thread states, so which pixel gets which numbers would depend on
thread scheduling and the thread count. With the counter-based generator the result is
identical for identical inputs and seed whatever the threading, and a block of rows solved
alone gets the numbers the whole image would.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.combine.simplex_solvers.problem import CHUNK, clip_normalise
from mcbench.jit import cached_njit

__all__ = ["STARTS", "MAX_ITERATIONS", "TOLERANCE", "seed_state", "iterative_weights"]

MAX_ITERATIONS = 1024    # the iterative solver's iteration limit (the paper's)
TOLERANCE = 1e-9         # ... and its stop: no weight moved by more over a whole cycle

# ---------------------------------------------------------------------------------------
# counter-based random numbers (splitmix64)
# ---------------------------------------------------------------------------------------
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0  # 2^-53


@cached_njit(inline="always")
def _mix64(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@cached_njit(inline="always")
def _next(state):
    """splitmix64 step: returns (new_state, 64 random bits)."""
    state = state + _GOLDEN
    return state, _mix64(state)


@cached_njit(inline="always")
def _uniform(bits):
    """Uniform double in [0, 1) from 64 random bits."""
    return float(bits >> _S11) * _INV53


def seed_state(seed) -> np.uint64:
    """The generator's 64-bit seed state of an integer ``seed`` (taken modulo 2^64)."""
    return np.uint64(int(seed) % (1 << 64))


# ---------------------------------------------------------------------------------------
# the iterative solver
# ---------------------------------------------------------------------------------------
START_RANDOM, START_VERTEX, START_PAIR = 0, 1, 2
STARTS = ("random", "vertex", "pair")


@cached_njit()
def _segment_point(ya, yb, xa, xb, i, j):
    """Eq. 29 between base denoisers i and j (D channels summed): the clipped blending factor
    alpha in [0, 1] of w = (1 - alpha) e_i + alpha e_j and its value sum_k (z^A - x^B)^2 +
    (z^B - x^A)^2 (twice Eq. 25 up to a constant)."""
    c1 = 0.0
    c2 = 0.0
    for k in range(ya.shape[1]):
        da = ya[i, k] - ya[j, k]
        db = yb[i, k] - yb[j, k]
        c1 += da * da + db * db
        c2 += (ya[i, k] - xb[k]) * da + (yb[i, k] - xa[k]) * db
    alpha = 0.0
    if c1 > 0.0:
        alpha = min(1.0, max(0.0, c2 / c1))
    value = 0.0
    for k in range(ya.shape[1]):
        ra = (1.0 - alpha) * ya[i, k] + alpha * ya[j, k] - xb[k]
        rb = (1.0 - alpha) * yb[i, k] + alpha * yb[j, k] - xa[k]
        value += ra * ra + rb * rb
    return alpha, value


@cached_njit()
def _deterministic_start(ya, yb, xa, xb, w, start):
    """Writes w: the best vertex e_j (``START_VERTEX``) or the best point of all vertices and
    segments, i.e. the best two-denoiser ensemble by Eq. 29 (``START_PAIR``, O(N^2))."""
    n = ya.shape[0]
    best = np.inf
    bi = 0
    bj = 0
    balpha = 0.0
    for i in range(n):
        _, value = _segment_point(ya, yb, xa, xb, i, i)
        if value < best:
            best = value
            bi = i
            bj = i
    if start == START_PAIR:
        for i in range(n):
            for j in range(i + 1, n):
                alpha, value = _segment_point(ya, yb, xa, xb, i, j)
                if value < best:
                    best = value
                    bi = i
                    bj = j
                    balpha = alpha
    for k in range(n):
        w[k] = 0.0
    w[bi] += 1.0 - balpha
    w[bj] += balpha


@cached_njit()
def _iterative_one(ya, yb, xa, xb, w, order, state, max_iterations, tolerance, start, away_steps):
    """One problem: ya, yb (N, D) with D channels sharing the weights (D = 1 per
    pixel-channel; D = C for one weight vector per pixel, whose Eq. 29 sums c1 and c2 over
    the channels); xa, xb (D,). alpha in [0, 1] (the paper's), or in [-w_i / (1 - w_i), 1] with
    ``away_steps``. Writes w (N,); returns the iteration count."""
    n = ya.shape[0]
    d = ya.shape[1]
    if start == START_RANDOM:
        # random start in [0, 1]^N, normalised (Sec. 4.1.2)
        for j in range(n):
            state, bits = _next(state)
            w[j] = _uniform(bits)
        clip_normalise(w)
    else:
        _deterministic_start(ya, yb, xa, xb, w, start)
    it = 0
    while it < max_iterations:
        # freshly shuffled cycle (Fisher-Yates)
        for j in range(n):
            order[j] = j
        for j in range(n - 1, 0, -1):
            state, bits = _next(state)
            r = int(_uniform(bits) * (j + 1))
            if r > j:
                r = j
            t = order[j]
            order[j] = order[r]
            order[r] = t
        max_change = 0.0
        for jj in range(n):
            if it >= max_iterations:
                break
            i = order[jj]
            # Eq. 29 with y_1 = current ensemble z, y_2 = base denoiser i (summed over the
            # D channels that share the weights; for D = 1 exactly the scalar form)
            c1 = 0.0
            c2 = 0.0
            for k in range(d):
                za = 0.0
                zb = 0.0
                for j in range(n):
                    za += w[j] * ya[j, k]
                    zb += w[j] * yb[j, k]
                da = za - ya[i, k]
                db = zb - yb[i, k]
                c1 += da * da + db * db
                c2 += (za - xb[k]) * da + (zb - xa[k]) * db
            # Eq. 29's clip: alpha in [0, 1] (the paper's and the code's, src/solve.h:112); with
            # away_steps the whole feasible segment of the line w -> e_i: alpha <= 1 keeps the
            # others >= 0, alpha >= -w_i / (1 - w_i) keeps w_i >= 0 (moves weight off denoiser i)
            lower = 0.0
            if away_steps and w[i] < 1.0:
                lower = -w[i] / (1.0 - w[i])
            alpha = 0.0
            if c1 > 0.0 and np.isfinite(c1):
                alpha = c2 / c1
                if not np.isfinite(alpha):
                    alpha = 0.0
                elif alpha < lower:
                    alpha = lower
                elif alpha > 1.0:
                    alpha = 1.0
            if alpha != 0.0:
                for j in range(n):
                    nw = (1.0 - alpha) * w[j]
                    if j == i:
                        nw = 0.0 if alpha == lower else nw + alpha   # exactly 0 at the face
                    change = abs(nw - w[j])
                    if change > max_change:
                        max_change = change
                    w[j] = nw
                # back onto the simplex exactly (rounding of (1 - alpha) * w when w_i is near 1)
                clip_normalise(w)
            it += 1
        if max_change <= tolerance:
            break
    clip_normalise(w)
    return it


@cached_njit(parallel=True)
def iterative_weights(ya, yb, xa, xb, seed_state, max_iterations, tolerance, first_problem,
                      start, away_steps=False):
    """The iterative solver (Sec. 4.1, Eq. 29-31) on P problems of N base
    denoisers whose D channels share the weights: ya, yb (P, N, D) float64; xa, xb (P, D).
    ``seed_state`` from :func:`seed_state`; the problems are first_problem .. first_problem +
    P - 1 of the image (the generator of problem p is seeded from (seed, p), so a block of rows
    solved alone gets the numbers the whole image would); ``start`` the index of the start in
    :data:`STARTS`; ``away_steps``: alpha in [-w_i / (1 - w_i), 1] instead of the paper's [0, 1]
(the module docstring). Returns weights (P, N) and iteration counts (P,)."""
    P, n = ya.shape[0], ya.shape[1]
    seed_state = _mix64(seed_state)
    out = np.empty((P, n))
    iters = np.empty(P, np.int64)
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        w = np.empty(n)
        order = np.empty(n, np.int64)
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            state = _mix64(seed_state + np.uint64(first_problem + p))
            iters[p] = _iterative_one(ya[p], yb[p], xa[p], xb[p], w, order, state,
                                      max_iterations, tolerance, start, away_steps)
            for j in range(n):
                out[p, j] = w[j]
    return out, iters
