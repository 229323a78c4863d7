"""The ensemble's raw weights (Zheng et al. 2021 Sec. 4.1, 5.2.1-5.2.3) for whole images or blocks
of rows, and the ensemble's options: their choices, defaults (:data:`ENSEMBLE_DEFAULTS`) and
checks.

For every pixel-channel with base outputs y_i^A, y_i^B (N denoisers) and noisy halves x^A, x^B,
:func:`solve_weights` minimises the dual-buffer MSE estimate

    L(w) = w^T <M> w = 1/2 |A w - b|^2 - 1/2 (x^A - x^B)^2                      (Eq. 13, 25)

(<M> of Eq. 11-12; A's columns a_i = (y_i^A, y_i^B), b = (x^B, x^A)) on the simplex
(w >= 0, sum w = 1) with the solvers of :mod:`mcbench.combine.simplex_solvers` (each solver's module gives its
equations and our departures):

* ``solver``: ``"iterative"`` (Sec. 4.1, Eq. 29-31, the paper's), ``"exact"`` (projection onto
  the convex hull, minimum-norm tie-break; our addition) or ``"qp"`` (a general QP solver, the
  slow baseline of Sec. 5.2.2, Fig. 6);
* ``weights="unconstrained"`` (Sec. 5.2.1): sum w = 1 without w >= 0, the minimum-norm
  minimiser (a closed form; ``solver`` is ignored);
* ``channels="single"`` (Sec. 5.2.3): one weight vector per pixel shared by the C channels,
  minimising the channel-summed objective sum_c L_c(w) = 1/2 |A w - b|^2 + const with A now
  2C x N (the points a_i = (y_i^A, y_i^B) in R^2C, b = (x^B, x^A)): ``"iterative"`` sums Eq.
  29's c1 and c2 over the channels, ``"exact"`` uses Wolfe's minimum-norm-point algorithm,
  ``"qp"`` the QP solver on the 2C-D problem;
* ``start``: the iterative solver's start (the paper's random one by default);
* ``away_steps``: the iterative solver's alpha in [-w_i / (1 - w_i), 1] (our option) instead of
  the paper's [0, 1] (Eq. 29, the default).

:func:`solve_block` solves the rows y0 .. y1 - 1 of an image alone with exactly the weights the
whole image's solve gives them (the iterative solver's generator is keyed by the problem's
index in the image), so a caller may solve an image block by block.
"""

from __future__ import annotations

import numpy as np

from mcbench.combine.simplex_solvers.exact import MAX_EXACT_N, exact_weights
from mcbench.combine.simplex_solvers.iterative import MAX_ITERATIONS, STARTS, TOLERANCE, iterative_weights, seed_state
from mcbench.combine.simplex_solvers.problem import SOLVERS
from mcbench.combine.simplex_solvers.qp import qp_simplex_weights
from mcbench.combine.simplex_solvers.shared_exact import shared_exact_weights
from mcbench.combine.simplex_solvers.unconstrained import unconstrained_least_squares, unconstrained_weights
from mcbench.filters.bilateral import COLOUR_DISTANCES

__all__ = ["WEIGHTS", "CHANNELS", "GUIDE_VARIANCE_BLURS", "OUTLIER_PASSES", "FILTER_BORDERS",
           "NORMAL_FEATURES", "CHOICES", "ENSEMBLE_DEFAULTS",
           "check_choices", "check_away_steps", "check_shapes", "check_finite", "nonfinite_pixels", "raise_nonfinite",
           "solve_block", "solve_weights"]

WEIGHTS = ("simplex", "unconstrained")
CHANNELS = ("rgb", "single")
GUIDE_VARIANCE_BLURS = ("none", "gaussian9")   # the weight filter's guide-variance blur
#: the weight filter's outlier pass: none, a value -> its neighbours' mean (mcbench's), the public code's
OUTLIER_PASSES = ("none", "neighbour_mean", "public_code")
#: the weight filter's window at the image borders: clipped, or reflected as the public code does
FILTER_BORDERS = ("clip", "reflect101")
#: the normal feature: as rendered, or standardised per channel as the public code does
NORMAL_FEATURES = ("raw", "standardised")
#: every choice option of the ensemble and its values
CHOICES = {"solver": SOLVERS, "weights": WEIGHTS, "channels": CHANNELS,
           "guide_variance_blur": GUIDE_VARIANCE_BLURS, "colour_distance": COLOUR_DISTANCES,
           "outlier_removal": OUTLIER_PASSES, "filter_border": FILTER_BORDERS,
           "normal_features": NORMAL_FEATURES, "start": STARTS}
#: The ensemble's (``methods/ensemble.py``'s combine()) defaults of the options that change what
#: is solved or filtered. The first four are the paper's method (changing one is an ablation,
#: Sec. 5.2.1-5.2.4). The rest follow the paper's text where it decides and the authors' public
#: code where the text is silent (LuisaGroup/Ensemble-Denoising at becc556; never chosen by their
#: error on the test scenes). Text: the iterative solver starts at random and clips Eq. 29's alpha
#: to [0, 1] (``away_steps=False``; the code too, src/solve.h:112), Eq. 33's ||.||^2 sums over the
#: channels (text and code), and Eq. 32's feature terms divide by 2 sigma^2 (the code divides by
#: sigma, listed as its slip; the sigmas are a switch). Silent text, so the code's: the normal is
#: standardised per channel (mean, population std floored at 1e-3, z-score clipped to +-3,
#: src/main.cpp:34-43), the guide variance is blurred (9 x 9), the filtered maps pass the code's
#: outlier pass (``remove_outliers<3>``, whole pixel -> 7 x 7 blur), windows reflect at the
#: borders and Eq. 33's denominator is floored at 1e-6. docs/fidelity_ensemble.md measures each.
#: ``mcbench.analysis.comparison_tables`` reads them to tell an ablation or a variant from the full
#: method.
ENSEMBLE_DEFAULTS = {"weights": "simplex", "channels": "rgb", "solver": "iterative", "filter": True,
                     "guide_variance_blur": "gaussian9", "outlier_removal": "public_code",
                     "colour_distance": "sum", "filter_border": "reflect101",
                     "normal_features": "standardised", "variance_sum_floor": 1e-6, "start": "random",
                     "away_steps": False}


def nonfinite_pixels(arrays) -> int:
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


def raise_nonfinite(counts: dict) -> None:
    """counts: {name: number of bad pixels}; raises ValueError naming the non-zero ones (if any)."""
    bad = {name: count for name, count in counts.items() if count}
    if bad:
        detail = ", ".join(f"{k}: {c}" for k, c in bad.items())
        raise ValueError(f"non-finite (NaN/Inf) values in {sum(bad.values())} pixel(s) "
                         f"of the ensemble inputs ({detail})")


def check_finite(named: dict) -> None:
    """named: {name: array or list of arrays}; raises ValueError with the bad pixel counts."""
    raise_nonfinite({name: nonfinite_pixels(arrays if isinstance(arrays, list) else [arrays])
                     for name, arrays in named.items()})


def check_shapes(xa, xb, ya, yb) -> None:
    """Raises ValueError unless xa, xb are (H, W, C) and ya, yb (N, H, W, C) with N >= 1."""
    if xa.ndim != 3 or xa.shape != xb.shape:
        raise ValueError(f"color_a {xa.shape} and color_b {xb.shape} must both be (H, W, C)")
    if ya.ndim != 4 or ya.shape != yb.shape or ya.shape[1:] != xa.shape or ya.shape[0] < 1:
        raise ValueError(f"denoised_a {ya.shape} and denoised_b {yb.shape} must both be "
                         f"(N, H, W, C) with N >= 1 and (H, W, C) = {xa.shape}")


def check_away_steps(away_steps) -> None:
    """Raises ValueError unless ``away_steps`` is a bool (True/False, not 0/1 or a string)."""
    if not isinstance(away_steps, (bool, np.bool_)):
        raise ValueError(f"ensemble away_steps must be true or false, got {away_steps!r}")


def check_choices(**named) -> None:
    """Raises ValueError for a value of an option of :data:`CHOICES` outside its choices."""
    for name, value in named.items():
        if value not in CHOICES[name]:
            raise ValueError(f"unknown ensemble {name} '{value}'; choose one of {CHOICES[name]}")


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


def solve_block(xa, xb, ya, yb, *, solver, seed, max_iterations, tolerance, weights, channels,
                first_row, start="random", away_steps=False):
    """Weights of the rows first_row .. first_row + T - 1 of an image: float64 xa, xb (T, W, C),
    ya, yb (N, T, W, C), all finite (unchecked). Returns (N, T, W, C) float64 weights and
    (T, W, C) info (see :func:`solve_weights`); a block gets exactly the weights of the whole
    image's solve."""
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
            w = unconstrained_weights(ya_k, yb_k, xa_k, xb_k)
        else:
            w = unconstrained_least_squares(*_stacked_points(ya_d, yb_d, xa_d, xb_d))
        info = np.zeros(w.shape[0], np.int64)
    elif solver == "iterative":
        if int(max_iterations) < 1:
            raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
        w, info = iterative_weights(ya_d, yb_d, xa_d, xb_d, seed_state(seed), int(max_iterations),
                                    float(tolerance), first_row * wd * per_problem,
                                    STARTS.index(start), bool(away_steps))
    elif solver == "exact" and channels == "single":
        w, info = shared_exact_weights(ya_d, yb_d, xa_d, xb_d)
    elif solver == "exact":
        if n > MAX_EXACT_N:
            raise ValueError(f"exact solver supports N <= {MAX_EXACT_N} denoisers, got {n}")
        w, info = exact_weights(ya_k, yb_k, xa_k, xb_k)
    else:
        w = qp_simplex_weights(*_stacked_points(ya_d, yb_d, xa_d, xb_d))
        info = np.zeros(w.shape[0], np.int64)
    if channels == "rgb":
        return np.ascontiguousarray(w.T).reshape(n, t, wd, c), info.reshape(t, wd, c)
    return (np.ascontiguousarray(np.broadcast_to(w.T.reshape(n, t, wd, 1), (n, t, wd, c))),
            np.ascontiguousarray(np.broadcast_to(info.reshape(t, wd, 1), (t, wd, c))))


def solve_weights(color_a, color_b, denoised_a, denoised_b, solver=ENSEMBLE_DEFAULTS["solver"],
                  seed=0, max_iterations=MAX_ITERATIONS, tolerance=TOLERANCE, return_info=False, *,
                  weights=ENSEMBLE_DEFAULTS["weights"], channels=ENSEMBLE_DEFAULTS["channels"],
                  start=ENSEMBLE_DEFAULTS["start"], away_steps=ENSEMBLE_DEFAULTS["away_steps"]):
    """Per-pixel, per-channel ensemble weights minimising Eq. 13 (with <M> from Eq. 11-12).

    Parameters
    ----------
    color_a, color_b : (H, W, C) noisy half buffers x^A, x^B (linear radiance).
    denoised_a, denoised_b : (N, H, W, C) base denoisers' half-buffer outputs y_i^A, y_i^B.
    solver : ``"iterative"`` (Sec. 4.1, Eq. 29-31), ``"exact"`` (projection onto the convex
        hull, minimum-norm tie-break; with ``channels="single"`` Wolfe's minimum-norm-point
        algorithm in 2C dimensions; see :mod:`mcbench.combine.simplex_solvers`) or ``"qp"`` (the
        general QP solver ``qpsolvers`` with ``QP_BACKEND``, one call per problem: the slow
        baseline of Fig. 6). Ignored with ``weights="unconstrained"`` (a closed form).
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
    away_steps : the iterative solver's range of Eq. 29's alpha: False (the paper's [0, 1]) or
        True ([-w_i / (1 - w_i), 1], steps that also move weight off the chosen denoiser; our
        option, :mod:`mcbench.combine.simplex_solvers.iterative`). Ignored by the other solvers.

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
    check_choices(solver=solver, weights=weights, channels=channels, start=start)
    check_away_steps(away_steps)
    xa, xb, ya, yb = (np.asarray(a, np.float64) for a in (color_a, color_b, denoised_a, denoised_b))
    check_shapes(xa, xb, ya, yb)
    check_finite({"color_a": xa, "color_b": xb, "denoised_a": ya, "denoised_b": yb})
    result, info = solve_block(xa, xb, ya, yb, solver=solver, seed=seed,
                               max_iterations=max_iterations, tolerance=tolerance,
                               weights=weights, channels=channels, first_row=0, start=start,
                               away_steps=away_steps)
    if return_info:
        return result, info
    return result
