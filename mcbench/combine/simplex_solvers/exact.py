"""The exact simplex solver per pixel-channel: closed-form 2D geometry with a minimum-norm tie-break
(mcbench's, not the paper's; the problem: :mod:`mcbench.combine.simplex_solvers.problem`).

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
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.combine.simplex_solvers.problem import CHUNK, GEOM_TOL, clip_normalise
from mcbench.jit import cached_njit

__all__ = ["MAX_EXACT_N", "min_norm_on_support", "exact_weights"]

MAX_EXACT_N = 20         # the exact solver's largest N (its support enumeration is 2^N)
_W_TOL = 1e-9        # weights
_RES_TOL = 1e-8      # residual |sum w a - p*| in units of the scale
_EIG_TOL = 1e-12     # pseudo-inverse threshold relative to trace(U)


@cached_njit()
def min_norm_on_support(u, v, idx, m, px, py, wtmp):
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
        # relative threshold, plus an absolute one: spreads below 0.1 * GEOM_TOL (in units
        # of the scale) count as coincident points, not as an (ill-conditioned) direction
        thr = max(_EIG_TOL * tr, m * (0.1 * GEOM_TOL) ** 2)
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
    inside = dist <= GEOM_TOL
    if not inside:
        nu = (bu - pu) / dist
        nv = (bv - pv) / dist
        mx = -np.inf
        for j in range(n):
            mx = max(mx, (u[j] - pu) * nu + (v[j] - pv) * nv)
        inside = mx > 0.5 * dist
    on_boundary = dist <= GEOM_TOL

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
            if (u[j] - pu) * nu + (v[j] - pv) * nv >= -GEOM_TOL:
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
            if np.sqrt(L2) > GEOM_TOL:
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
    ok, _ = min_norm_on_support(u, v, idx, m, pu, pv, wtmp)
    if ok:
        for j in range(n):
            w[j] = wtmp[j]
        clip_normalise(w)
        return 1

    # enumerate supports S subset of candidates
    best_norm = np.inf
    for mask in range(1, 1 << m):
        k = 0
        for t in range(m):
            if (mask >> t) & 1:
                idx[k] = cand[t]
                k += 1
        ok, nrm = min_norm_on_support(u, v, idx, k, pu, pv, wtmp)
        if ok and nrm < best_norm:
            best_norm = nrm
            for j in range(n):
                wbest[j] = wtmp[j]
    if best_norm < np.inf:
        for j in range(n):
            w[j] = wbest[j]
        clip_normalise(w)
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
    clip_normalise(w)
    return 3


@cached_njit(parallel=True)
def exact_weights(ya, yb, xa, xb):
    """The exact solver (minimum-norm tie-break) per pixel-channel: ya, yb (P, N) float64, N <=
    :data:`MAX_EXACT_N`; xa, xb (P,). Returns weights (P, N) and path codes (P,): 0 unique, 1
    min-norm over the candidates, 2 support enumeration, 3 geometric fallback."""
    P, n = ya.shape
    out = np.empty((P, n))
    codes = np.empty(P, np.int8)
    nchunks = (P + CHUNK - 1) // CHUNK
    for c in prange(nchunks):
        w = np.empty(n)
        u = np.empty(n)
        v = np.empty(n)
        cand = np.empty(n, np.int64)
        idx = np.empty(n, np.int64)
        wtmp = np.empty(n)
        wbest = np.empty(n)
        for p in range(c * CHUNK, min(P, (c + 1) * CHUNK)):
            codes[p] = _exact_one(ya[p], yb[p], xa[p], xb[p], w, u, v, cand, idx, wtmp, wbest)
            for j in range(n):
                out[p, j] = w[j]
    return out, codes
