"""Ensemble denoising (Zheng et al. 2021): per-pixel, per-channel convex combination of
base denoiser outputs with weights from the dual-buffer MSE estimate, then a
cross-bilateral filter on the weight maps.

Objective (Eq. 11-14). For one pixel-channel with base outputs ``y_i^A, y_i^B`` and noisy
halves ``x^A, x^B``, the estimated MSE matrix is <M> = (<M>^A + <M>^B) / 2 with
<M>^A_ij = x^A x^B - x^B (y_i^A + y_j^A) + y_i^A y_j^A (and A <-> B). Since
<M>^A_ij = (y_i^A - x^B)(y_j^A - x^B) + x^A x^B - (x^B)^2, on the simplex (sum w = 1)

    L(w) = w^T <M> w = 1/2 |A w - b|^2 - 1/2 (x^A - x^B)^2,                     (Eq. 25)

with A the 2 x N matrix whose columns are the points a_i = (y_i^A, y_i^B) and
b = (x^B, x^A). So the minimiser of Eq. 13 is given by the Euclidean projection p* of b onto
the convex hull of the N points a_i, and any simplex weights w with A w = p*.

Solvers
-------
``"iterative"`` (paper Sec. 4.1, default): random start, then repeatedly combine the current
ensemble z = (w.y^A, w.y^B) with one base denoiser through the two-denoiser closed form
(Eq. 29) and update w <- (1 - alpha) w + alpha e_i (Eq. 31); the denoiser is chosen cycling
through all N in a freshly shuffled order per cycle; stop when no weight moved by more
than ``tolerance`` over a whole cycle or after ``max_iterations`` iterations.
**Departure (away steps):** the paper clips alpha to [0, 1], so weight only ever moves *towards*
the chosen denoiser and a denoiser that should get weight 0 fades geometrically slowly (with
[0, 1] only 67 % of pixel-channels of random 4-denoiser problems ended within 1e-6 s^2 of the
optimum of Eq. 13 after 1024 iterations, 94 % after 16384; tests/test_ensemble.py). We clip
alpha to the whole feasible segment of the line through w and e_i, [-w_i / (1 - w_i), 1]: a
negative alpha is the same closed form moving weight *off* denoiser i, down to w_i = 0
(exactly 0 at the bound), and w is renormalised after each update against rounding. Every
step is still the exact minimiser of Eq. 13 on its line, so the objective decreases
monotonically as in the paper's argument; 99.6 % (random) and 99.96 % (biased-denoiser
problems) end within 1e-6 s^2 of the optimum, most in under 16 iterations.
Randomness comes from a counter-based splitmix64 generator seeded from
(seed, pixel-channel index), not from ``np.random``: inside numba ``prange`` loops
``np.random`` draws from per-thread states, so which pixel gets which numbers would depend
on thread scheduling and the thread count. With the counter-based generator the result is
identical for identical inputs and seed whatever the threading.

``"exact"``: closed-form 2D geometry. p* = b if b lies in the hull (on a segment, or in a
triangle of the points by Caratheodory), else p* is the closest point over all points and
segments. Hull membership is decided in O(N) by the equivalent separation test: with p the
closest point over all points and segments, b is outside iff every point satisfies
(a_k - p).(b - p) <= 0; the O(N^3) triangle search only runs for the fallback witness.
Non-unique weights (b inside the hull, several points on the optimal face -- collinear or
coincident, e.g. identical base outputs) are resolved by a deterministic rule: among all
optimal simplex weight vectors take the one of **minimum Euclidean norm** (equivalently
closest to the naive average 1/N). It is unique and permutation-equivariant (permuting the
denoisers permutes the weights). It is computed exactly: only candidate points can carry
weight (outside the hull: the points on the optimal face, (a_k - p*).n >= -tol with
n = (b - p*)/|b - p*|; otherwise all N). The equality-constrained minimum-norm solution on
a support S is w_i = 1/|S| + (a_i - a_bar).mu with U mu = p* - a_bar (U the 2 x 2 scatter
of a_i - a_bar over S, pseudo-inverse with eigenvalue threshold relative to trace U and an
absolute floor for coincident points); by
the KKT conditions the answer is the feasible one (w >= -tol, |sum w_i a_i - p*| <= tol)
of minimum norm over all supports S. Fast paths: a unique optimum (one candidate vertex,
or two distinct candidate points) is returned directly, and the minimum-norm solution over
all candidates is taken when it is already non-negative; only otherwise are subsets
enumerated, which is exponential in the number of candidates (2^N - 1 supports, N <= 20
allowed) -- but only on those non-unique pixels. Tolerances are relative to the pixel's
scale max(|y|, |x|) (floor 1e-30): coordinates are divided by it before the geometry.

``"qp"`` (Sec. 5.2.2, the slow baseline of Fig. 6): the same simplex problems, one call per
problem to the general QP solver ``qpsolvers.solve_qp`` (backend ``QP_BACKEND``, quadprog:
dense, active-set), on data divided by the problem's scale with a ridge of 1e-12 (quadprog
needs a definite matrix; A^T A has rank <= 2 per pixel-channel).

Ablations (Sec. 5.2.1-5.2.4)
----------------------------
``weights="unconstrained"`` (Sec. 5.2.1): sum w = 1 without w >= 0. The paper's closed form
w = M^-1 1 / (1^T M^-1 1) (Eq. 19) needs a non-singular matrix, but on sum w = 1 the objective
is 1/2 |A w - b|^2 + const, i.e. <M> may be replaced by 1/2 C^T C (C = A - b 1^T, rank <= 2):
singular for N > 2, and for N > 3 the minimisers form an affine set (Eq. 19 with a
pseudo-inverse is then not even a minimiser in general). We return the minimum-norm minimiser,
w = 1/N + D^+ (b - a_bar) (D the 2 x N centred points: the KKT conditions of the
equality-constrained least squares; D's rows are orthogonal to 1). For N = 2 with
non-singular <M> this is Eq. 19, for N = 3 points in general position the unique A w = b.
The pseudo-inverse drops directions with singular values below max(1e-6 sigma_max,
1e-11 sqrt(N)) in units of the scale (per pixel-channel: the exact solver's 2 x 2 scatter
thresholds, the same up to sqrt(trace) for sigma_max), so |w - 1/N| < 5e11 / sqrt(N): finite,
never NaN/Inf (``unconstrained_least_squares``); the sum is restored to one against rounding.
The weight filter then averages without clipping.
``channels="single"`` (Sec. 5.2.3): one weight vector per pixel shared by the C channels,
minimising the channel-summed objective sum_c L_c(w) = 1/2 |A w - b|^2 + const with A now
2C x N (the points a_i = (y_i^A, y_i^B) in R^2C, b = (x^B, x^A)). ``"iterative"`` sums Eq. 29's
c1 and c2 over the channels (each step is still the exact line minimiser); ``"exact"`` projects
b onto the hull of the points by Wolfe's minimum-norm-point algorithm (finite, exact up to a
Frank-Wolfe gap of 1e-13 scale^2; coincident points -- identical outputs -- share their
weight equally; the weights are unique when the distinct points are affinely independent,
otherwise Wolfe's deterministic answer, not necessarily the minimum-norm one); ``"qp"``
solves the 2C-D problem with the QP solver. ``filter=False`` (Sec. 5.2.4) keeps the raw
weights.

Weight filter (Sec. 4.2): raw combined images z, z^A, z^B, Var[z] ~ (z^A - z^B)^2 / 2, and a
cross-bilateral filter (Eq. 32-34) of all N x C weight maps with one kernel per pixel
guided by z/Var[z], albedo and normal (``mcbench.filters.bilateral``). A convex combination of
simplex vectors stays on the simplex.

Precision and memory (issue 14): the solvers' geometry is float64 throughout (Eq. 29's c1
and the hull tests subtract nearly equal radiance values). :func:`combine` makes one pass down
the image in bands of rows (:data:`FILTER_BLOCK_PIXELS`): it solves blocks of rows
(:data:`BLOCK_PIXELS`; float64 copies of one block's inputs only) as far as a band's halo needs,
straight into the float32 raw weight maps it returns, keeping the guide z, Var[z] (float64: the
filter's colour term needs it, see ``mcbench.filters.bilateral``) of the rows a band still needs only;
filters the band from its tile (the weight filter otherwise in float32: relative rounding
1e-7, far below what a weight map shows; the blend equals the float64 code's to ~1e-15 relMSE,
tests/test_ensemble.py) and blends it (Eq. 35, float64 accumulation). The iterative solver's
generator is keyed by the problem's index in the image, so blocks change nothing; the filter
and blur give each row of a tile the whole image's result bit for bit, the outlier pass to
rounding of its float64 window sums. Whole arrays are only what :func:`combine` returns (three
images, 2N weight maps); the render's layers and the inputs are read by rows
(:data:`READS_ROWS`).

The public code's post-processing (LuisaGroup/Ensemble-Denoising, ``filter.h``/``main.cpp``;
``../shared/study/public-code-facts.md`` items 1-3), each a documented switch of
:func:`combine` and :func:`filter_weights`:
``guide_variance_blur="gaussian9"``: Var[z] blurred with a 9 x 9 Gaussian (OpenCV's sigma-0
rule, sigma = 1.7, borders reflected) before the filter; ``outlier_removal=True``: after the
filter, each weight map's values further than 2.5 standard deviations from the mean of the
other pixels of their 7 x 7 window are replaced by that mean
(:func:`mcbench.filters.bilateral.remove_outliers`), then the weights are projected back onto the
simplex (onto sum one when unconstrained; a pixel-channel left with all weights 0 keeps its
filtered ones); ``colour_distance="sum"``: Eq. 33 summed over the channels instead of averaged.
**Defaults, from the measurement**: ``combine`` blurs the guide variance and removes outliers
by default (``guide_variance_blur="gaussian9"``, ``outlier_removal=True``, ``colour_distance=
"mean"``); ``filter_weights`` keeps the paper's filter alone. Measured with
``python benchmarks/bench_postprocess.py`` on the 72 cases (8 scenes x 9 spp, 128^2) of a finished
default run, iterative solver, mean over the cases of three input sets (OIDN+NFOR+RDFC,
KPCN+NFOR+OIDN+RDFC, OIDN+JBF+NFOR+RDFC; 216 blends), change of mean relMSE / DSSIM against
the paper's filter alone, and the share of blends whose relMSE improves:

================== ========== ========== =======
variant            relMSE     DSSIM      better
================== ========== ========== =======
blur               -2.3 %     -3.9 %     71 %
outliers           -2.3 %     -2.7 %     87 %
sum                +1.4 %     +4.6 %     19 %
blur+outliers      **-3.9 %** **-5.5 %** 79 %
blur+sum           -0.9 %     -0.2 %     35 %
blur+outliers+sum  -3.1 %     -3.7 %     70 %
================== ========== ========== =======

blur+outliers is the best of every input set on both metrics (-2.6 / -5.7 / -3.6 % relMSE).
The paper's filter alone stays available: :data:`PAPER_FILTER` (``guide_variance_blur="none",
outlier_removal=False``; outputs identical to the code before these switches existed, to
2.5e-15 relMSE).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numba import prange

from mcbench.filters.bilateral import (COLOUR_DISTANCES, cross_bilateral_filter_vectors, gaussian_blur,
                               remove_outliers)
from mcbench.jit import cached_njit
from mcbench.io.buffers import Denoised, RenderBuffers

KIND = "combiner"
LABEL = "Ensemble"
# what combine() reads of the render: the noisy halves (Eq. 11-14) and the filter's features
RENDER_LAYERS = ("color_a", "color_b", "albedo", "normal")
# combine() only ever indexes the render's layers and the inputs' images by rows (x[y0:y1]), so a
# job may hand it mcbench.io.exr.LayerRows (layers read from their files by rows) instead of arrays
READS_ROWS = True

SOLVERS = ("iterative", "exact", "qp")
MAX_EXACT_N = 20
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
def _iterative_kernel(ya, yb, xa, xb, seed_state, max_iterations, tolerance, first_problem,
                      start):
    """ya, yb: (P, N, D); xa, xb: (P, D), problems first_problem .. first_problem + P - 1 of the
    image (the generator of problem p is seeded from (seed, p), so a block of rows solved alone
    gets the numbers the whole image would). Returns weights (P, N) and iteration counts (P,)."""
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
def _exact_kernel(ya, yb, xa, xb):
    """ya, yb: (P, N); xa, xb: (P,). Returns weights (P, N) and path codes (P,)."""
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
def _shared_exact_kernel(ya, yb, xa, xb):
    """Weights shared by D channels: ya, yb (P, N, D); xa, xb (P, D). Minimises
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
def _unconstrained_kernel(ya, yb, xa, xb):
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


# ---------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------
WEIGHTS = ("simplex", "unconstrained")
CHANNELS = ("rgb", "single")
GUIDE_VARIANCE_BLURS = ("none", "gaussian9")
BLOCK_PIXELS = 1 << 16   # pixels per block of rows that combine() solves at once (memory bound)
_SIMPLEX_TOL = {np.dtype(np.float64): 1e-6, np.dtype(np.float32): 1e-4}  # |sum - 1| after filtering


def _nonfinite_pixels(arrays) -> int:
    """Number of pixels (H, W) where any of ``arrays`` (each (H, W, C) or (N, H, W, C)) holds a
    NaN/Inf in any channel (or input)."""
    bad = None
    for arr in arrays:
        arr = np.asarray(arr)
        finite = np.isfinite(arr)
        if arr.ndim == 4:
            finite = finite.all(axis=0)
        pixel_bad = ~finite.reshape(finite.shape[0], finite.shape[1], -1).all(axis=2)
        bad = pixel_bad if bad is None else bad | pixel_bad
    return 0 if bad is None else int(bad.sum())


def _check_finite(named: dict) -> None:
    """named: {name: array or list of arrays}; raises ValueError with the bad pixel counts."""
    bad = {}
    for name, arrays in named.items():
        count = _nonfinite_pixels(arrays if isinstance(arrays, list) else [arrays])
        if count:
            bad[name] = count
    if bad:
        detail = ", ".join(f"{k}: {c}" for k, c in bad.items())
        raise ValueError(f"non-finite (NaN/Inf) values in {sum(bad.values())} pixel(s) "
                         f"of the ensemble inputs ({detail})")


def _check_shapes(xa, xb, ya, yb):
    if xa.ndim != 3 or xa.shape != xb.shape:
        raise ValueError(f"color_a {xa.shape} and color_b {xb.shape} must both be (H, W, C)")
    if ya.ndim != 4 or ya.shape != yb.shape or ya.shape[1:] != xa.shape or ya.shape[0] < 1:
        raise ValueError(f"denoised_a {ya.shape} and denoised_b {yb.shape} must both be "
                         f"(N, H, W, C) with N >= 1 and (H, W, C) = {xa.shape}")


def _check_choices(**named) -> None:
    choices = {"solver": SOLVERS, "weights": WEIGHTS, "channels": CHANNELS,
               "guide_variance_blur": GUIDE_VARIANCE_BLURS, "colour_distance": COLOUR_DISTANCES,
               "start": STARTS}
    for name, value in named.items():
        if value not in choices[name]:
            raise ValueError(f"unknown ensemble {name} '{value}'; choose one of {choices[name]}")


def _seed_state(seed) -> np.uint64:
    return np.uint64(int(seed) % (1 << 64))


def _problems(xa, xb, ya, yb, channels):
    """Solver inputs from float64 blocks xa, xb (T, W, C), ya, yb (N, T, W, C): per pixel-channel
    ya_p, yb_p (P, N) and xa_p, xb_p (P,) (``"rgb"``, P = T W C in (row, column, channel)
    order), or per pixel (P = T W) ya, yb (P, N, C) and xa, xb (P, C) (``"single"``)."""
    n, c = ya.shape[0], xa.shape[2]
    if channels == "rgb":
        return (np.ascontiguousarray(ya.reshape(n, -1).T), np.ascontiguousarray(yb.reshape(n, -1).T),
                xa.ravel(), xb.ravel())
    return (np.ascontiguousarray(ya.reshape(n, -1, c).transpose(1, 0, 2)),
            np.ascontiguousarray(yb.reshape(n, -1, c).transpose(1, 0, 2)),
            xa.reshape(-1, c), xb.reshape(-1, c))


def _stacked_points(ya, yb, xa, xb):
    """Eq. 25 summed over D channels: points (P, N, 2D) a_i = (y_i^A, y_i^B) and targets
    (P, 2D) b = (x^B, x^A)."""
    return np.concatenate([ya, yb], axis=2), np.concatenate([xb, xa], axis=1)


def _solve_block(xa, xb, ya, yb, *, solver, seed, max_iterations, tolerance, weights, channels,
                 first_row, start="random"):
    """Weights of the rows first_row .. first_row + T - 1 of an image: float64 xa, xb (T, W, C),
    ya, yb (N, T, W, C), all finite. Returns (N, T, W, C) float64 weights and (T, W, C) info
    (see :func:`solve_weights`); a block gets exactly the weights of the whole image's solve."""
    n, t, wd, c = ya.shape
    ya_k, yb_k, xa_k, xb_k = _problems(xa, xb, ya, yb, channels)
    per_problem = c if channels == "rgb" else 1
    if channels == "rgb":
        ya_d, yb_d, xa_d, xb_d = (ya_k.reshape(-1, n, 1), yb_k.reshape(-1, n, 1), xa_k.reshape(-1, 1),
                                  xb_k.reshape(-1, 1))
    else:
        ya_d, yb_d, xa_d, xb_d = ya_k, yb_k, xa_k, xb_k
    if weights == "unconstrained":
        if channels == "rgb":
            w = _unconstrained_kernel(ya_k, yb_k, xa_k, xb_k)
        else:
            w = unconstrained_least_squares(*_stacked_points(ya_d, yb_d, xa_d, xb_d))
        info = np.zeros(w.shape[0], np.int64)
    elif solver == "iterative":
        if int(max_iterations) < 1:
            raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
        w, info = _iterative_kernel(ya_d, yb_d, xa_d, xb_d, _seed_state(seed), int(max_iterations),
                                    float(tolerance), first_row * wd * per_problem,
                                    STARTS.index(start))
    elif solver == "exact" and channels == "single":
        w, info = _shared_exact_kernel(ya_d, yb_d, xa_d, xb_d)
    elif solver == "exact":
        if n > MAX_EXACT_N:
            raise ValueError(f"exact solver supports N <= {MAX_EXACT_N} denoisers, got {n}")
        w, info = _exact_kernel(ya_k, yb_k, xa_k, xb_k)
    else:
        w = qp_simplex_weights(*_stacked_points(ya_d, yb_d, xa_d, xb_d))
        info = np.zeros(w.shape[0], np.int64)
    if channels == "rgb":
        return np.ascontiguousarray(w.T).reshape(n, t, wd, c), info.reshape(t, wd, c)
    return (np.ascontiguousarray(np.broadcast_to(w.T.reshape(n, t, wd, 1), (n, t, wd, c))),
            np.ascontiguousarray(np.broadcast_to(info.reshape(t, wd, 1), (t, wd, c))))


def solve_weights(color_a, color_b, denoised_a, denoised_b, solver="iterative", seed=0,
                  max_iterations=1024, tolerance=1e-9, return_info=False, *,
                  weights="simplex", channels="rgb", start="random"):
    """Per-pixel, per-channel ensemble weights minimising Eq. 13 (with <M> from Eq. 11-12).

    Parameters
    ----------
    color_a, color_b : (H, W, C) noisy half buffers x^A, x^B (linear radiance).
    denoised_a, denoised_b : (N, H, W, C) base denoisers' half-buffer outputs y_i^A, y_i^B.
    solver : ``"iterative"`` (Sec. 4.1, Eq. 29-31), ``"exact"`` (projection onto the convex
        hull, minimum-norm tie-break; with ``channels="single"`` Wolfe's minimum-norm-point
        algorithm in 2C dimensions; see the module docstring) or ``"qp"`` (the general QP
        solver ``qpsolvers`` with ``QP_BACKEND``, one call per problem: the slow baseline of
        Fig. 6). Ignored with ``weights="unconstrained"`` (a closed form).
    seed : int, seeds the iterative solver's counter-based generator (ignored otherwise).
    max_iterations : int, iteration limit of the iterative solver (paper: 1024).
    tolerance : float, the iterative solver stops once no weight changed by more than this
        over a whole cycle of N iterations.
    return_info : if True also return per pixel-channel (H, W, C) diagnostics: iteration
        counts (iterative), path codes (exact, ``"rgb"``: 0 unique, 1 min-norm over
        candidates, 2 support enumeration, 3 geometric fallback), Wolfe steps (exact,
        ``"single"``), 0 (qp and unconstrained).
    weights : ``"simplex"`` (Eq. 13: w >= 0, sum 1) or ``"unconstrained"`` (sum 1 only,
        Sec. 5.2.1 ablation): the minimum-norm minimiser (:func:`unconstrained_least_squares`;
        for ``"rgb"`` the same formula through the exact solver's 2 x 2 pseudo-inverse).
    channels : ``"rgb"`` (one weight vector per pixel-channel, the paper's choice) or
        ``"single"`` (one per pixel shared by the C channels, minimising the sum over the
        channels of Eq. 13, Sec. 5.2.3; the weights are repeated along C).
    start : the iterative solver's starting weights: ``"random"`` (the paper's, Sec. 4.1.2),
        ``"vertex"`` (the best single base denoiser) or ``"pair"`` (the best two-denoiser
        ensemble of Eq. 29 over all pairs, O(N^2) per problem; it is the optimum whenever the
        optimum has two non-zero weights, so the solver stops after one cycle). The iterations
        are the paper's either way; see ``benchmarks/bench_solvers.py``.

    All arithmetic is float64 (the solvers' geometry needs it: Eq. 29's c1 and the hull tests
    subtract nearly equal radiance values).

    Returns
    -------
    (N, H, W, C) float64 weights, each pixel-channel summing to 1 (and >= 0 for
    ``"simplex"``).

    Raises
    ------
    ValueError on shape mismatch, unknown solver/weights/channels, or NaN/Inf in any input
    (the message gives the number of bad pixels).
    """
    _check_choices(solver=solver, weights=weights, channels=channels, start=start)
    xa, xb, ya, yb = (np.asarray(a, np.float64) for a in (color_a, color_b, denoised_a, denoised_b))
    _check_shapes(xa, xb, ya, yb)
    _check_finite({"color_a": xa, "color_b": xb, "denoised_a": ya, "denoised_b": yb})
    result, info = _solve_block(xa, xb, ya, yb, solver=solver, seed=seed,
                                max_iterations=max_iterations, tolerance=tolerance,
                                weights=weights, channels=channels, first_row=0, start=start)
    if return_info:
        return result, info
    return result


def combine_with(weights, denoised) -> np.ndarray:
    """Eq. 3 / 35: sum_i w_i y_i per pixel-channel. (N, H, W, C) x (N, H, W, C) -> (H, W, C)."""
    return np.einsum("nhwc,nhwc->hwc", np.asarray(weights, np.float64),
                     np.asarray(denoised, np.float64))


def _onto_constraint(weights, *, nonnegative, check, fallback=None):
    """In place: filtered (N, H, W, C) weights back onto the simplex (clip at 0, divide by the
    sum; with ``check`` first assert that the sum stayed within rounding of 1) or, for
    unconstrained weights, onto sum one (add (1 - sum) / N). A pixel-channel whose clipped
    weights are all 0 (possible after the per-map outlier removal) takes ``fallback``'s."""
    n = weights.shape[0]
    total = weights.sum(axis=0)
    if not nonnegative:
        weights += (1.0 - total) / n
        return
    if check:
        assert np.all(np.abs(total - 1.0) < _SIMPLEX_TOL[weights.dtype]), \
            "filtered weights left the simplex"
    np.maximum(weights, 0.0, out=weights)
    total = weights.sum(axis=0)
    empty = ~(total > 0)
    if empty.any():
        weights[:, empty] = fallback[:, empty]
        total[empty] = 1.0
    weights /= total


FILTER_BLOCK_PIXELS = 1 << 17   # output pixels per band of the tiled weight filter (memory bound)


def _tile_rows(y0, y1, height, *, radius, blur, outliers):
    """The rows each stage needs for the final weights of rows y0 .. y1 - 1 (half-open ranges,
    clipped to the image): (o0, o1) the filtered rows the outlier pass reads (its window's
    radius :data:`OUTLIER_RADIUS` around them), (f0, f1) the rows of raw weights, z and
    features the filter reads for those (``radius`` around), (v0, v1) the rows of Var[z] the
    9 x 9 blur reads for those (4 around)."""
    r_out = OUTLIER_RADIUS if outliers else 0
    r_blur = 4 if blur else 0
    o0, o1 = max(0, y0 - r_out), min(height, y1 + r_out)
    f0, f1 = max(0, o0 - radius), min(height, o1 + radius)
    return (o0, o1), (f0, f1), (max(0, f0 - r_blur), min(height, f1 + r_blur))


def _filter_band(values, y0, y1, guide, guide_variance, v0, albedo, normal, *, radius,
                 sigma_spatial, sigma_color, sigma_albedo, sigma_normal, nonnegative,
                 guide_variance_blur, outlier_removal, colour_distance, dtype):
    """Sec. 4.2 plus the public code's optional passes for the rows y0 .. y1 - 1 of an image of
    H rows, from a tile with its halo (:func:`_tile_rows`): ``values`` (N, H, W, C) raw weights
    (whole, or any array-like read by rows), ``guide`` and ``guide_variance`` planar (C, T, W)
    float64 holding the rows v0 .. v0 + T - 1 of z and Var[z] (at least (v0, v1) of
    :func:`_tile_rows`), ``albedo``, ``normal`` (H, W, 3) read by rows. Returns the final weights
    (N, y1 - y0, W, C) of ``dtype``.

    Each stage works on the rows it needs only; the filter and the blur give every row exactly
    the whole image's result (:func:`mcbench.filters.bilateral.cross_bilateral_filter_vectors`,
    :func:`mcbench.filters.bilateral.gaussian_blur`: same sums in the same order), the outlier pass's
    window statistics start their running sums at the tile (float64; differences ~1e-16
    relative, tests/test_ensemble.py)."""
    height = values.shape[1]
    (o0, o1), (f0, f1), (vv0, vv1) = _tile_rows(
        y0, y1, height, radius=radius, blur=guide_variance_blur == "gaussian9",
        outliers=outlier_removal)
    z = np.moveaxis(guide[:, f0 - v0:f1 - v0], 0, 2)
    if guide_variance_blur == "gaussian9":
        var = gaussian_blur(np.moveaxis(guide_variance[:, vv0 - v0:vv1 - v0], 0, 2),
                            kernel_size=9, rows=(f0, f1), first_row=vv0, height=height)
    else:
        var = np.moveaxis(guide_variance[:, f0 - v0:f1 - v0], 0, 2)
    out = cross_bilateral_filter_vectors(values[:, f0:f1], z, var, [albedo[f0:f1], normal[f0:f1]],
                                         [sigma_albedo, sigma_normal], sigma_spatial, sigma_color,
                                         radius, colour_distance=colour_distance, dtype=dtype,
                                         rows=(o0 - f0, o1 - f0))
    _onto_constraint(out, nonnegative=nonnegative, check=True)
    if not outlier_removal:
        return out
    keep = slice(y0 - o0, y1 - o0)
    cleaned = remove_outliers(out, radius=OUTLIER_RADIUS, threshold=OUTLIER_THRESHOLD)[:, keep]
    _onto_constraint(cleaned, nonnegative=nonnegative, check=False, fallback=out[:, keep])
    return cleaned


def _filter_all(values, guide, guide_variance, albedo, normal, *, dtype, **options):
    """:func:`_filter_band` over the bands of :data:`FILTER_BLOCK_PIXELS` pixels of whole
    arrays: values (N, H, W, C), guide and guide_variance planar (C, H, W) float64. Returns
    (N, H, W, C) of ``dtype``."""
    n, h, wd, c = values.shape
    out = np.empty((n, h, wd, c), dtype)
    step = max(1, FILTER_BLOCK_PIXELS // max(wd, 1))
    for y0 in range(0, h, step):
        y1 = min(h, y0 + step)
        out[:, y0:y1] = _filter_band(values, y0, y1, guide, guide_variance, 0, albedo, normal,
                                     dtype=dtype, **options)
    return out


# combine() options of the paper's filter alone, without the public code's passes
PAPER_FILTER = {"guide_variance_blur": "none", "outlier_removal": False, "colour_distance": "mean"}
OUTLIER_RADIUS = 3         # the public code's 7 x 7 window
OUTLIER_THRESHOLD = 2.5    # ... and its 2.5 standard deviations


def filter_weights(weights, denoised_full, denoised_a, denoised_b, albedo, normal, radius=7,
                   sigma_spatial=3.0, sigma_color=2.0, sigma_albedo=0.25, sigma_normal=0.15,
                   *, nonnegative=True, guide_variance_blur="none", outlier_removal=False,
                   colour_distance="mean", dtype=np.float64):
    """Cross-bilateral filter of the raw weight maps (Sec. 4.2, Eq. 32-34).

    weights, denoised_full, denoised_a, denoised_b : (N, H, W, C); albedo, normal (H, W, 3).
    The guide is the raw combined image z = sum w y_i with Var[z] ~ (z^A - z^B)^2 / 2; all
    N x C maps share one kernel per pixel. Defaults are the paper's (radius 7 px,
    sigma_s 3, sigma_z 2, sigma_albedo 0.25, sigma_normal 0.15). The public code's passes
    (:func:`combine`): ``guide_variance_blur="gaussian9"`` blurs Var[z] with
    :func:`mcbench.filters.bilateral.gaussian_blur` (9 x 9) first, ``outlier_removal=True`` runs
    :func:`mcbench.filters.bilateral.remove_outliers` (7 x 7, 2.5 sigma) on the filtered maps and
    re-projects them, ``colour_distance="sum"`` sums Eq. 33 over the channels. ``dtype`` is the
    filter's working precision (:mod:`mcbench.filters.bilateral`; :func:`combine` uses float32).
    Returns (N, H, W, C) weights of ``dtype`` on the simplex; with ``nonnegative=False``
    (unconstrained weights, Sec. 5.2.1) weights summing to one, of any sign: no clipping,
    and the sum is restored against rounding by adding (1 - sum) / N to each weight.
    """
    _check_choices(guide_variance_blur=guide_variance_blur, colour_distance=colour_distance)
    w = np.asarray(weights, np.float64)
    z = _planar64(combine_with(w, denoised_full))
    var = _planar64(0.5 * (combine_with(w, denoised_a) - combine_with(w, denoised_b)) ** 2)
    return _filter_all(w, z, var, np.asarray(albedo), np.asarray(normal), dtype=dtype,
                       radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                       sigma_albedo=sigma_albedo, sigma_normal=sigma_normal,
                       nonnegative=nonnegative, guide_variance_blur=guide_variance_blur,
                       outlier_removal=outlier_removal, colour_distance=colour_distance)


def _planar64(image) -> np.ndarray:
    """(H, W, C) -> contiguous (C, H, W) float64 (the filter's layout of z and Var[z])."""
    return np.ascontiguousarray(np.moveaxis(np.asarray(image, np.float64), 2, 0))


def blend(weights, inputs, which) -> np.ndarray:
    """Eq. 35 for image ``which`` (``"full"``, ``"a"``, ``"b"``) of the Denoised ``inputs``:
    sum_i w_i y_i accumulated in float64 one input at a time; weights (N, H, W, C). Returns
    (H, W, C) float64."""
    return _blend_rows(weights, inputs, which, slice(None))


def _blend_rows(weights, inputs, which, rows) -> np.ndarray:
    """:func:`blend` on the rows ``rows`` (a slice) of the weights and of each input's image
    (whole arrays or array-likes read by rows). Returns (T, W, C) float64."""
    return _blend_band(weights, inputs, rows, (which,))[which]


def _blend_band(weights, inputs, rows, images=("full", "a", "b")) -> dict:
    """Eq. 35 on the rows ``rows`` (a slice) for each image in ``images``, input by input (one
    read of an input's rows when it is read from its file): {image: (T, W, C) float64}, each
    accumulated in float64 in input order as :func:`blend`."""
    out = {}
    for w, d in zip(weights, inputs):
        w = w[rows]
        for which in images:
            term = w * np.asarray(d.image(which)[rows], np.float64)
            if which not in out:
                out[which] = np.zeros(term.shape)
            out[which] += term
    return out


class _Solver:
    """combine()'s solve (Sec. 4.1) of blocks of :data:`BLOCK_PIXELS` pixels of rows, in order,
    on demand (:meth:`until`): raw weights into ``raw`` (float32), and for the filter the guide
    z and Var[z] of the rows solved (float64, planar blocks) until :meth:`drop_before` lets them
    go, so only a band's halo of them is ever held. Counts non-finite input pixels block by
    block; at the first, it stops solving, counts the rest and raises the message of
    :func:`_check_finite` (whole-image counts)."""

    def __init__(self, buffers, inputs, raw, *, guide, options):
        self.buffers, self.inputs, self.raw = buffers, inputs, raw
        self.guide, self.options = guide, options
        _, self.height, self.width, _ = raw.shape
        self.step = max(1, BLOCK_PIXELS // max(self.width, 1))
        self.next_row = 0
        self.blocks: list[tuple[int, np.ndarray, np.ndarray]] = []   # (first row, z, Var[z])

    def _block(self, rows):
        xa = np.asarray(self.buffers.color_a[rows], np.float64)
        xb = np.asarray(self.buffers.color_b[rows], np.float64)
        ya, yb, yf = (np.empty((len(self.inputs),) + xa.shape) for _ in range(3))
        for i, d in enumerate(self.inputs):    # input by input: one read of a file's rows
            ya[i], yb[i], yf[i] = d.a[rows], d.b[rows], d.full[rows]
        block = {"color_a": xa, "color_b": xb, "denoised_a": ya, "denoised_b": yb,
                 "denoised_full": yf}
        if self.guide:   # the filter's features: checked here too when read from files by rows
            for name in ("albedo", "normal"):
                layer = getattr(self.buffers, name)
                if not isinstance(layer, np.ndarray):
                    block[name] = np.asarray(layer[rows])
        return block

    def _raise_nonfinite(self, bad):
        for y0 in range(self.next_row, self.height, self.step):
            block = self._block(slice(y0, min(self.height, y0 + self.step)))
            for name, array in block.items():
                bad[name] = bad.get(name, 0) + _nonfinite_pixels([array])
        bad = {name: count for name, count in bad.items() if count}
        detail = ", ".join(f"{k}: {c}" for k, c in bad.items())
        raise ValueError(f"non-finite (NaN/Inf) values in {sum(bad.values())} pixel(s) "
                         f"of the ensemble inputs ({detail})")

    def until(self, row):
        """Solve blocks until every row < ``row`` is."""
        while self.next_row < min(row, self.height):
            y0 = self.next_row
            rows = slice(y0, min(self.height, y0 + self.step))
            block = self._block(rows)
            # a NaN/Inf makes the sum non-finite (an overflowing sum only costs the exact count)
            if not all(np.isfinite(a.sum()) for a in block.values()):
                bad = {name: _nonfinite_pixels([a]) for name, a in block.items()}
                if any(bad.values()):
                    self.next_row = rows.stop
                    self._raise_nonfinite(bad)
            ya, yb = block["denoised_a"], block["denoised_b"]
            w, _ = _solve_block(block["color_a"], block["color_b"], ya, yb, first_row=y0,
                                **self.options)
            self.raw[:, rows] = w
            if self.guide:
                z = _planar64(combine_with(w, block["denoised_full"]))
                var = _planar64(0.5 * (combine_with(w, ya) - combine_with(w, yb)) ** 2)
                self.blocks.append((y0, z, var))
            self.next_row = rows.stop

    def guide_rows(self, v0, v1):
        """z and Var[z] of the rows v0 .. v1 - 1 (solved, not dropped): planar (C, v1 - v0, W)."""
        parts = [(max(v0, y0) - y0, min(v1, y0 + z.shape[1]) - y0, z, var)
                 for y0, z, var in self.blocks if y0 < v1 and y0 + z.shape[1] > v0]
        if len(parts) == 1:
            a, b, z, var = parts[0]
            return z[:, a:b], var[:, a:b]
        return (np.concatenate([z[:, a:b] for a, b, z, _ in parts], axis=1),
                np.concatenate([var[:, a:b] for a, b, _, var in parts], axis=1))

    def drop_before(self, row):
        """Let the guide blocks that end at or before ``row`` go."""
        self.blocks = [b for b in self.blocks if b[0] + b[1].shape[1] > row]


def combine(buffers: RenderBuffers, inputs: list[Denoised], *,
            solver: Literal["iterative", "exact", "qp"] = "iterative", seed: int = 0,
            max_iterations: int = 1024, tolerance: float = 1e-9, filter: bool = True,
            weights: Literal["simplex", "unconstrained"] = "simplex",
            channels: Literal["rgb", "single"] = "rgb",
            radius: int = 7, sigma_spatial: float = 3.0, sigma_color: float = 2.0,
            sigma_albedo: float = 0.25, sigma_normal: float = 0.15,
            guide_variance_blur: Literal["none", "gaussian9"] = "gaussian9",
            outlier_removal: bool = True,
            colour_distance: Literal["mean", "sum"] = "mean",
            start: Literal["random", "vertex", "pair"] = "random") -> Denoised:
    """Ensemble of the ``inputs`` (Sec. 4): solve raw weights from the half buffers, filter
    them (unless ``filter=False``, an ablation), and combine (Eq. 35).

    Ablations (Sec. 5.2.1-5.2.4; the defaults are the paper's method): ``weights=
    "unconstrained"`` drops w >= 0 (sum one only; the weight filter then does not clip);
    ``channels="single"`` shares one weight vector per pixel by the RGB channels;
    ``solver="qp"`` solves the same problems with a general QP solver (slow; Fig. 6);
    ``filter=False`` keeps the raw weights. See :func:`solve_weights`. The authors' public
    code's passes around the filter (see :func:`filter_weights`): ``guide_variance_blur``,
    ``outlier_removal``, ``colour_distance``; the defaults blur and remove outliers, the best
    variant measured on the default study (module docstring), and ``guide_variance_blur="none",
    outlier_removal=False`` is the paper's filter alone. ``start``: the iterative solver's start (see
    :func:`solve_weights`; the paper's random one by default).

    Memory (issue 14): one pass down the image in bands of :data:`FILTER_BLOCK_PIXELS` pixels.
    For each band the rows are solved (blocks of :data:`BLOCK_PIXELS` pixels, float64 copies of
    one block only) as far as its halo needs (:func:`_tile_rows`: 14 rows with the default
    passes), straight into the float32 raw weight maps, keeping the float64 guide z and Var[z]
    of those rows only; the band is filtered from its tile (float32 but the colour term;
    :func:`_filter_band`), written to the float32 filtered maps, and blended (Eq. 35, float64
    accumulation) into the float32 images. What stays whole is what is returned: the three
    images and the 2N weight maps. The render's layers and the inputs' images are only ever
    indexed by rows (``x[y0:y1]``), so they may be array-likes read from their files by rows
    (:class:`mcbench.io.exr.LayerRows`, see :data:`READS_ROWS`): then no input is ever held whole.
    Each input row is read twice (solve, blend).

    Returns Denoised(full, a, b, extras) with float32 images; ``extras`` holds
    ``weights_raw_{i}`` and ``weights_filtered_{i}`` (H, W, 3) per input i (with
    ``filter=False`` the filtered maps equal the raw ones).

    Raises ValueError if an input holds NaN/Inf, or if a combined image is not finite in
    float32 (only unconstrained weights, bounded by 5e11, on radiance above ~1e26 could).
    """
    if not inputs:
        raise ValueError("the ensemble needs at least one input")
    _check_choices(solver=solver, weights=weights, channels=channels, start=start,
                   guide_variance_blur=guide_variance_blur, colour_distance=colour_distance)
    xa, xb = buffers.color_a, buffers.color_b
    shape = tuple(np.shape(xa))
    for i, d in enumerate(inputs):
        for which in ("full", "a", "b"):
            if tuple(np.shape(d.image(which))) != shape:
                raise ValueError(f"ensemble input {i} ({d.source}) image {which} has shape "
                                 f"{np.shape(d.image(which))}, the render's is {shape}")
    _check_shapes(np.empty(shape, np.uint8), np.empty(np.shape(xb), np.uint8),
                  np.empty((1,) + shape, np.uint8), np.empty((1,) + shape, np.uint8))
    n = len(inputs)
    h, wd, c = shape
    raw = np.empty((n, h, wd, c), np.float32)
    filt = np.empty((n, h, wd, c), np.float32) if filter else raw
    images = {key: np.empty((h, wd, c), np.float32) for key in ("full", "a", "b")}
    solve = _Solver(buffers, inputs, raw, guide=filter,
                    options=dict(solver=solver, seed=seed, max_iterations=max_iterations,
                                 tolerance=tolerance, weights=weights, channels=channels,
                                 start=start))
    passes = dict(radius=radius, blur=guide_variance_blur == "gaussian9", outliers=outlier_removal)
    options = dict(radius=radius, sigma_spatial=sigma_spatial, sigma_color=sigma_color,
                   sigma_albedo=sigma_albedo, sigma_normal=sigma_normal,
                   nonnegative=weights == "simplex", guide_variance_blur=guide_variance_blur,
                   outlier_removal=outlier_removal, colour_distance=colour_distance,
                   dtype=np.float32)
    step = max(1, FILTER_BLOCK_PIXELS // max(wd, 1))
    for y0 in range(0, h, step):
        y1 = min(h, y0 + step)
        if filter:
            v0, v1 = _tile_rows(y0, y1, h, **passes)[2]
            solve.until(v1)
            z, var = solve.guide_rows(v0, v1)
            filt[:, y0:y1] = _filter_band(raw, y0, y1, z, var, v0, buffers.albedo, buffers.normal,
                                          **options)
            del z, var
            solve.drop_before(_tile_rows(y1, y1 + 1, h, **passes)[2][0])
        else:
            solve.until(y1)
        for key, rows in _blend_band(filt, inputs, slice(y0, y1)).items():
            images[key][y0:y1] = rows
    solve.until(h)      # (h == 0)
    extras = {}
    for i in range(n):
        extras[f"weights_raw_{i}"] = raw[i]
    for i in range(n):
        extras[f"weights_filtered_{i}"] = filt[i]
    bad = [key for key, image in images.items() if not np.isfinite(image).all()]
    if bad:
        raise ValueError(f"ensemble ({weights} weights) combined image(s) {bad} overflow "
                         f"float32")
    return Denoised(full=images["full"], a=images["a"], b=images["b"], extras=extras)
