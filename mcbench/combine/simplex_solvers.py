"""Simplex-constrained least squares for the ensemble's weights (Zheng et al. 2021 Sec. 4.1,
5.2.1-5.2.3): batches of small problems, one per pixel-channel (or per pixel), each solved
independently (numba ``prange`` over chunks of problems).

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

Solvers (each returns (P, N) float64 weights of P problems)
-----------------------------------------------------------
:func:`iterative_weights` (Sec. 4.1, the paper's): a start (:data:`STARTS`: the paper's random
one, or the best vertex, or the best two-denoiser ensemble by Eq. 29 over all pairs), then
repeatedly combine the current ensemble z = (w.y^A, w.y^B) with one base denoiser through the
two-denoiser closed form (Eq. 29, c1 and c2 summed over the D channels) and update
w <- (1 - alpha) w + alpha e_i (Eq. 31); the denoiser is chosen cycling through all N in a
freshly shuffled order per cycle; stop when no weight moved by more than ``tolerance`` over a
whole cycle or after ``max_iterations`` iterations.
**Departure (away steps):** the paper clips alpha to [0, 1], so weight only ever moves
*towards* the chosen denoiser and a denoiser that should get weight 0 fades geometrically
slowly. We clip alpha to the whole feasible segment of the line through w and e_i,
[-w_i / (1 - w_i), 1]: a negative alpha is the same closed form moving weight *off* denoiser
i, down to w_i = 0 (exactly 0 at the bound), and w is renormalised after each update against
rounding. Every step is still the exact minimiser of Eq. 13 on its line, so the objective
decreases monotonically as in the paper's argument (tests/combine/test_ensemble.py compares how many
problems reach the optimum with and without away steps).
**Departure (random numbers):** a counter-based splitmix64 generator seeded from
(seed, problem index in the image), not ``np.random``: inside numba ``prange`` loops
``np.random`` draws from per-thread states, so which pixel gets which numbers would depend on
thread scheduling and the thread count. With the counter-based generator the result is
identical for identical inputs and seed whatever the threading, and a block of rows solved
alone gets the numbers the whole image would.

:func:`exact_weights` (our addition): closed-form 2D geometry. p* = b if b lies in the hull (on
a segment, or in a triangle of the points by Caratheodory), else p* is the closest point over
all points and segments. Hull membership is decided in O(N) by the equivalent separation test:
with p the closest point over all points and segments, b is outside iff every point satisfies
(a_k - p).(b - p) <= 0; the O(N^3) triangle search only runs for the fallback witness.
Non-unique weights (b inside the hull, several points on the optimal face -- collinear or
coincident, e.g. identical base outputs) are resolved by a deterministic rule: among all
optimal simplex weight vectors take the one of **minimum Euclidean norm** (equivalently
closest to the naive average 1/N). It is unique and permutation-equivariant. It is computed
exactly: only candidate points can carry weight (outside the hull: the points on the optimal
face, (a_k - p*).n >= -tol with n = (b - p*)/|b - p*|; otherwise all N). The
equality-constrained minimum-norm solution on a support S is w_i = 1/|S| + (a_i - a_bar).mu
with U mu = p* - a_bar (U the 2 x 2 scatter of a_i - a_bar over S, pseudo-inverse with
eigenvalue threshold relative to trace U and an absolute floor for coincident points); by the
KKT conditions the answer is the feasible one (w >= -tol, |sum w_i a_i - p*| <= tol) of
minimum norm over all supports S. Fast paths: a unique optimum (one candidate vertex, or two
distinct candidate points) is returned directly, and the minimum-norm solution over all
candidates is taken when it is already non-negative; only otherwise are subsets enumerated,
which is exponential in the number of candidates (2^N - 1 supports, N <= :data:`MAX_EXACT_N`)
-- but only on those non-unique pixels. Tolerances are relative to the pixel's scale
max(|y|, |x|) (floor 1e-30): coordinates are divided by it before the geometry.

:func:`shared_exact_weights` (one weight vector shared by D channels, Sec. 5.2.3): projects b
onto the hull of the points in R^2D by Wolfe's minimum-norm-point algorithm (finite, exact up
to a Frank-Wolfe gap of 1e-13 scale^2; coincident points -- identical outputs -- share their
weight equally; the weights are unique when the distinct points are affinely independent,
otherwise Wolfe's deterministic answer, not necessarily the minimum-norm one).

:func:`qp_simplex_weights` (Sec. 5.2.2, the slow baseline of Fig. 6): one call per problem to
the general QP solver ``qpsolvers.solve_qp`` (backend :data:`QP_BACKEND`, quadprog: dense,
active-set), on data divided by the problem's scale with a ridge of 1e-12 (quadprog needs a
definite matrix; A^T A has rank <= 2 per pixel-channel).

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

All geometry is float64 (Eq. 29's c1 and the hull tests subtract nearly equal radiance values).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.jit import cached_njit

__all__ = ["SOLVERS", "STARTS", "MAX_EXACT_N", "MAX_ITERATIONS", "TOLERANCE", "QP_BACKEND",
           "objective", "seed_state", "iterative_weights", "exact_weights", "shared_exact_weights",
           "unconstrained_weights", "unconstrained_least_squares", "qp_simplex_weights"]

SOLVERS = ("iterative", "exact", "qp")   # the ensemble's solver choices (see the docstring)
MAX_EXACT_N = 20         # the exact solver's largest N (its support enumeration is 2^N)
MAX_ITERATIONS = 1024    # the iterative solver's iteration limit (the paper's)
TOLERANCE = 1e-9         # ... and its stop: no weight moved by more over a whole cycle
_CHUNK = 256  # pixel-channels per parallel work item (scratch arrays are per item)

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
# objective
# ---------------------------------------------------------------------------------------
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


# ---------------------------------------------------------------------------------------
# iterative solver (Sec. 4.1)
# ---------------------------------------------------------------------------------------
@cached_njit()
def _clip_normalise(w):
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
def _iterative_one(ya, yb, xa, xb, w, order, state, max_iterations, tolerance, start):
    """One problem: ya, yb (N, D) with D channels sharing the weights (D = 1 per
    pixel-channel; D = C for one weight vector per pixel, whose Eq. 29 sums c1 and c2 over
    the channels); xa, xb (D,). Writes w (N,); returns the iteration count."""
    n = ya.shape[0]
    d = ya.shape[1]
    if start == START_RANDOM:
        # random start in [0, 1]^N, normalised (Sec. 4.1.2)
        for j in range(n):
            state, bits = _next(state)
            w[j] = _uniform(bits)
        _clip_normalise(w)
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
            # feasible step range on the line w -> e_i: alpha <= 1 keeps the others >= 0, and
            # alpha >= -w_i / (1 - w_i) keeps w_i >= 0 (an "away" step that moves weight off
            # denoiser i; the paper's Eq. 29 clips at 0, see the module docstring)
            lower = 0.0
            if w[i] < 1.0:
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
                _clip_normalise(w)
            it += 1
        if max_change <= tolerance:
            break
    _clip_normalise(w)
    return it


@cached_njit(parallel=True)
def iterative_weights(ya, yb, xa, xb, seed_state, max_iterations, tolerance, first_problem,
                      start):
    """The iterative solver (Sec. 4.1, Eq. 29-31, with away steps) on P problems of N base
    denoisers whose D channels share the weights: ya, yb (P, N, D) float64; xa, xb (P, D).
    ``seed_state`` from :func:`seed_state`; the problems are first_problem .. first_problem +
    P - 1 of the image (the generator of problem p is seeded from (seed, p), so a block of rows
    solved alone gets the numbers the whole image would); ``start`` the index of the start in
    :data:`STARTS`. Returns weights (P, N) and iteration counts (P,)."""
    P, n = ya.shape[0], ya.shape[1]
    seed_state = _mix64(seed_state)
    out = np.empty((P, n))
    iters = np.empty(P, np.int64)
    nchunks = (P + _CHUNK - 1) // _CHUNK
    for c in prange(nchunks):
        w = np.empty(n)
        order = np.empty(n, np.int64)
        for p in range(c * _CHUNK, min(P, (c + 1) * _CHUNK)):
            state = _mix64(seed_state + np.uint64(first_problem + p))
            iters[p] = _iterative_one(ya[p], yb[p], xa[p], xb[p], w, order, state,
                                      max_iterations, tolerance, start)
            for j in range(n):
                out[p, j] = w[j]
    return out, iters


# ---------------------------------------------------------------------------------------
# exact solver (projection onto the convex hull, minimum-norm tie-break)
# ---------------------------------------------------------------------------------------
_GEOM_TOL = 1e-10    # distances in units of the pixel's scale
_W_TOL = 1e-9        # weights
_RES_TOL = 1e-8      # residual |sum w a - p*| in units of the scale
_EIG_TOL = 1e-12     # pseudo-inverse threshold relative to trace(U)


@cached_njit()
def _min_norm_on_support(u, v, idx, m, px, py, wtmp):
    """Equality-constrained min-norm weights on support idx[:m] (others 0).

    Writes wtmp (over all N); returns (feasible, squared norm)."""
    n = u.shape[0]
    for j in range(n):
        wtmp[j] = 0.0
    mu_ = 0.0
    mv_ = 0.0
    for t in range(m):
        mu_ += u[idx[t]]
        mv_ += v[idx[t]]
    mu_ /= m
    mv_ /= m
    s11 = 0.0
    s12 = 0.0
    s22 = 0.0
    for t in range(m):
        du = u[idx[t]] - mu_
        dv = v[idx[t]] - mv_
        s11 += du * du
        s12 += du * dv
        s22 += dv * dv
    ru = px - mu_
    rv = py - mv_
    tr = s11 + s22
    lam_u = 0.0
    lam_v = 0.0
    if tr > 0.0:
        # eigen-decomposition of the symmetric 2x2 scatter, pseudo-inverse
        half = 0.5 * (s11 - s22)
        disc = np.sqrt(half * half + s12 * s12)
        l1 = 0.5 * tr + disc
        l2 = 0.5 * tr - disc
        if abs(s12) > 0.0 or half != 0.0:
            # eigenvector of l1
            if half >= 0.0:
                e1u = half + disc
                e1v = s12
            else:
                e1u = s12
                e1v = disc - half
            nrm = np.sqrt(e1u * e1u + e1v * e1v)
            e1u /= nrm
            e1v /= nrm
        else:
            e1u = 1.0
            e1v = 0.0
        e2u = -e1v
        e2v = e1u
        # relative threshold, plus an absolute one: spreads below 0.1 * _GEOM_TOL (in units
        # of the scale) count as coincident points, not as an (ill-conditioned) direction
        thr = max(_EIG_TOL * tr, m * (0.1 * _GEOM_TOL) ** 2)
        if l1 > thr:
            c = (e1u * ru + e1v * rv) / l1
            lam_u += c * e1u
            lam_v += c * e1v
        if l2 > thr:
            c = (e2u * ru + e2v * rv) / l2
            lam_u += c * e2u
            lam_v += c * e2v
    inv_m = 1.0 / m
    norm2 = 0.0
    ok = True
    ressu = 0.0
    ressv = 0.0
    for t in range(m):
        k = idx[t]
        wk = inv_m + (u[k] - mu_) * lam_u + (v[k] - mv_) * lam_v
        wtmp[k] = wk
        norm2 += wk * wk
        if wk < -_W_TOL:
            ok = False
        ressu += wk * u[k]
        ressv += wk * v[k]
    if ok:
        if np.sqrt((ressu - px) ** 2 + (ressv - py) ** 2) > _RES_TOL:
            ok = False
    return ok, norm2


@cached_njit()
def _triangle_witness(u, v, bu, bv):
    """A triangle of points containing b (Caratheodory) and b's barycentric coordinates."""
    n = u.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                area = (u[j] - u[i]) * (v[k] - v[i]) - (v[j] - v[i]) * (u[k] - u[i])
                if abs(area) <= 1e-14:
                    continue
                b1 = ((u[j] - bu) * (v[k] - bv) - (v[j] - bv) * (u[k] - bu)) / area
                b2 = ((u[k] - bu) * (v[i] - bv) - (v[k] - bv) * (u[i] - bu)) / area
                b3 = 1.0 - b1 - b2
                if b1 >= -1e-12 and b2 >= -1e-12 and b3 >= -1e-12:
                    return True, i, j, k, b1, b2, b3
    return False, 0, 0, 0, 0.0, 0.0, 0.0


@cached_njit()
def _exact_one(ya, yb, xa, xb, w, u, v, cand, idx, wtmp, wbest):
    """Minimum-norm minimiser of Eq. 13 for one pixel-channel; writes w (N,).

    Returns a code: 0 unique fast path, 1 min-norm over all candidates, 2 enumeration,
    3 fallback to the geometric witness."""
    n = ya.shape[0]
    s = 1e-30
    for j in range(n):
        s = max(s, abs(ya[j]), abs(yb[j]))
    s = max(s, abs(xa), abs(xb))
    for j in range(n):
        u[j] = ya[j] / s
        v[j] = yb[j] / s
    bu = xb / s  # b = (x^B, x^A) pairs with a_i = (y_i^A, y_i^B)
    bv = xa / s
    if n == 1:
        w[0] = 1.0
        return 0

    # closest point over all vertices and segments; the witness (i, j, t) realises it
    best = np.inf
    wi = 0
    wj = 0
    wt = 0.0
    pu = 0.0
    pv = 0.0
    for i in range(n):
        d2 = (u[i] - bu) ** 2 + (v[i] - bv) ** 2
        if d2 < best:
            best = d2
            wi = i
            wj = i
            wt = 0.0
            pu = u[i]
            pv = v[i]
    for i in range(n):
        for j in range(i + 1, n):
            du = u[j] - u[i]
            dv = v[j] - v[i]
            L2 = du * du + dv * dv
            if L2 <= 0.0:
                continue
            t = ((bu - u[i]) * du + (bv - v[i]) * dv) / L2
            if t <= 0.0 or t >= 1.0:
                continue
            qu = u[i] + t * du
            qv = v[i] + t * dv
            d2 = (qu - bu) ** 2 + (qv - bv) ** 2
            if d2 < best:
                best = d2
                wi = i
                wj = j
                wt = t
                pu = qu
                pv = qv
    dist = np.sqrt(best)
    # b is in the hull iff no line through p separates it from the points: if b is outside,
    # p is its projection and every point has (a_k - p).n <= 0; if b is inside at distance
    # dist > 0 from p (any point of the segments), b = sum lambda_k a_k gives
    # max_k (a_k - p).n >= (b - p).n = dist. (Equivalent to Caratheodory's "b lies in some
    # triangle of the points", which is only evaluated for the fallback witness: O(N) here
    # instead of O(N^3).)
    inside = dist <= _GEOM_TOL
    if not inside:
        nu = (bu - pu) / dist
        nv = (bv - pv) / dist
        mx = -np.inf
        for j in range(n):
            mx = max(mx, (u[j] - pu) * nu + (v[j] - pv) * nv)
        inside = mx > 0.5 * dist
    on_boundary = dist <= _GEOM_TOL

    m = 0
    if inside:
        pu = bu
        pv = bv
        for j in range(n):
            cand[m] = j
            m += 1
    else:
        nu = (bu - pu) / dist
        nv = (bv - pv) / dist
        for j in range(n):
            if (u[j] - pu) * nu + (v[j] - pv) * nv >= -_GEOM_TOL:
                cand[m] = j
                m += 1
        # fast paths: the optimum is unique
        if m <= 1:
            for j in range(n):
                w[j] = 0.0
            w[wi if m == 0 else cand[0]] = 1.0
            return 0
        if m == 2:
            i = cand[0]
            j = cand[1]
            du = u[j] - u[i]
            dv = v[j] - v[i]
            L2 = du * du + dv * dv
            if np.sqrt(L2) > _GEOM_TOL:
                t = ((pu - u[i]) * du + (pv - v[i]) * dv) / L2
                t = min(1.0, max(0.0, t))
                for k in range(n):
                    w[k] = 0.0
                w[i] = 1.0 - t
                w[j] = t
                return 0

    # minimum-norm solution over all candidates; optimal if already non-negative
    for t in range(m):
        idx[t] = cand[t]
    ok, _ = _min_norm_on_support(u, v, idx, m, pu, pv, wtmp)
    if ok:
        for j in range(n):
            w[j] = wtmp[j]
        _clip_normalise(w)
        return 1

    # enumerate supports S subset of candidates
    best_norm = np.inf
    for mask in range(1, 1 << m):
        k = 0
        for t in range(m):
            if (mask >> t) & 1:
                idx[k] = cand[t]
                k += 1
        ok, nrm = _min_norm_on_support(u, v, idx, k, pu, pv, wtmp)
        if ok and nrm < best_norm:
            best_norm = nrm
            for j in range(n):
                wbest[j] = wtmp[j]
    if best_norm < np.inf:
        for j in range(n):
            w[j] = wbest[j]
        _clip_normalise(w)
        return 2

    # numerical fallback: the geometric witness (always optimal, maybe not min-norm)
    for j in range(n):
        w[j] = 0.0
    tri = False
    if inside and not on_boundary:
        tri, ti, tj, tk, l1, l2, l3 = _triangle_witness(u, v, bu, bv)
    if tri:
        w[ti] = l1
        w[tj] = l2
        w[tk] = l3
    else:
        w[wi] += 1.0 - wt
        w[wj] += wt
    _clip_normalise(w)
    return 3


@cached_njit(parallel=True)
def exact_weights(ya, yb, xa, xb):
    """The exact solver (minimum-norm tie-break) per pixel-channel: ya, yb (P, N) float64, N <=
    :data:`MAX_EXACT_N`; xa, xb (P,). Returns weights (P, N) and path codes (P,): 0 unique, 1
    min-norm over the candidates, 2 support enumeration, 3 geometric fallback."""
    P, n = ya.shape
    out = np.empty((P, n))
    codes = np.empty(P, np.int8)
    nchunks = (P + _CHUNK - 1) // _CHUNK
    for c in prange(nchunks):
        w = np.empty(n)
        u = np.empty(n)
        v = np.empty(n)
        cand = np.empty(n, np.int64)
        idx = np.empty(n, np.int64)
        wtmp = np.empty(n)
        wbest = np.empty(n)
        for p in range(c * _CHUNK, min(P, (c + 1) * _CHUNK)):
            codes[p] = _exact_one(ya[p], yb[p], xa[p], xb[p], w, u, v, cand, idx, wtmp, wbest)
            for j in range(n):
                out[p, j] = w[j]
    return out, codes


# ---------------------------------------------------------------------------------------
# exact solver for weights shared by the channels (Wolfe's minimum-norm-point algorithm)
# ---------------------------------------------------------------------------------------
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
    _clip_normalise(w)
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
    nchunks = (P + _CHUNK - 1) // _CHUNK
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
        for p in range(c * _CHUNK, min(P, (c + 1) * _CHUNK)):
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
                        if (abs((ya[p, j, e] - xb[p, e]) / s - q[g, e]) > _GEOM_TOL
                                or abs((yb[p, j, e] - xa[p, e]) / s - q[g, dim + e]) > _GEOM_TOL):
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


# ---------------------------------------------------------------------------------------
# unconstrained weights (Sec. 5.2.1 ablation): sum to one, any sign
# ---------------------------------------------------------------------------------------
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
    nchunks = (P + _CHUNK - 1) // _CHUNK
    for c in prange(nchunks):
        u = np.empty(n)
        v = np.empty(n)
        idx = np.arange(n)
        wtmp = np.empty(n)
        for p in range(c * _CHUNK, min(P, (c + 1) * _CHUNK)):
            s = max(1e-30, abs(xa[p]), abs(xb[p]))
            for j in range(n):
                s = max(s, abs(ya[p, j]), abs(yb[p, j]))
            for j in range(n):
                u[j] = ya[p, j] / s
                v[j] = yb[p, j] / s
            # feasibility flag ignored: b need not lie in the points' affine hull
            _min_norm_on_support(u, v, idx, n, xb[p] / s, xa[p] / s, wtmp)
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


# ---------------------------------------------------------------------------------------
# general-purpose QP (the slow baseline of Fig. 6)
# ---------------------------------------------------------------------------------------
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

