"""Ensemble denoising (Zheng et al. 2021): per-pixel, per-channel convex combination of
base denoiser outputs with weights from the dual-buffer MSE estimate, then a
cross-bilateral filter on the weight maps. The library behind it is :mod:`mcbench.combine`
(:mod:`~mcbench.combine.simplex_solvers`, :mod:`~mcbench.combine.ensemble_weights`,
:mod:`~mcbench.combine.weight_filter`, :mod:`~mcbench.combine.blending`); this plugin runs it
on a render in one pass of bands of rows (:mod:`~mcbench.combine.ensemble_driver`).

Objective (Eq. 11-14). For one pixel-channel with base outputs ``y_i^A, y_i^B`` and noisy
halves ``x^A, x^B``, the estimated MSE matrix is <M> = (<M>^A + <M>^B) / 2 with
<M>^A_ij = x^A x^B - x^B (y_i^A + y_j^A) + y_i^A y_j^A (and A <-> B). On the simplex
(sum w = 1)

    L(w) = w^T <M> w = 1/2 |A w - b|^2 - 1/2 (x^A - x^B)^2,                     (Eq. 25)

with A the 2 x N matrix whose columns are the points a_i = (y_i^A, y_i^B) and
b = (x^B, x^A): the minimiser of Eq. 13 projects b onto the convex hull of the points.

Solvers (``solver``)
--------------------
``"iterative"`` (Sec. 4.1, default): random start, then the two-denoiser closed form (Eq. 29)
between the current ensemble and one base denoiser, w <- (1 - alpha) w + alpha e_i (Eq. 31),
cycling through the N denoisers in a freshly shuffled order per cycle, until no weight moves
by more than ``tolerance`` over a cycle or after ``max_iterations`` iterations.
Eq. 29's alpha is clipped to [0, 1] as in the text and the authors' code (src/solve.h:112);
``away_steps=True`` (our option) clips it to the whole feasible segment [-w_i / (1 - w_i), 1]
instead ("away" steps that move weight off denoiser i; every step still minimises Eq. 13 on its
line). c1 is not floored (the text; the code's max(c1, 1e-6), src/solve.h:92, :110, is not in
Eq. 29). **Departure:** the random numbers come from a counter-based splitmix64 generator keyed by
(seed, pixel-channel index), so the result does not depend on threading or on how the image
is cut into blocks. ``start="vertex"``/``"pair"`` replace the random start by the best single
denoiser or the best two-denoiser ensemble (our option).
``"exact"`` (our addition): the exact projection by 2D geometry, non-unique optima resolved
by the minimum-norm weights (unique, permutation-equivariant); with ``channels="single"``
Wolfe's minimum-norm-point algorithm.
``"qp"`` (Sec. 5.2.2, the slow baseline of Fig. 6): a general QP solver per problem, on data
divided by the problem's scale with a ridge of 1e-12.
Details: :mod:`mcbench.combine.simplex_solvers`.

Ablations (Sec. 5.2.1-5.2.4)
----------------------------
``weights="unconstrained"`` (Sec. 5.2.1): sum w = 1 without w >= 0. **Departure:** instead of
Eq. 19's w = M^-1 1 / (1^T M^-1 1), which needs a non-singular <M> (rank <= 2 on sum w = 1,
so singular for N > 2), the minimum-norm minimiser w = 1/N + D^+ (b - a_bar) (D the centred
points, small singular values dropped, so |w - 1/N| < 5e11 / sqrt(N)); the weight filter then
averages without clipping. ``channels="single"`` (Sec. 5.2.3): one weight vector per pixel
shared by the C channels, minimising the channel-summed objective. ``filter=False``
(Sec. 5.2.4) keeps the raw weights.

Weight filter (Sec. 4.2) and blend
----------------------------------
Raw combined images z, z^A, z^B, Var[z] ~ (z^A - z^B)^2 / 2 guide a cross-bilateral filter
(Eq. 32-34) of all N x C weight maps with one kernel per pixel (z / Var[z], albedo, normal);
the filtered weights combine the inputs' full, A and B images (Eq. 35).
**Departures (defaults):** where the text is silent the authors' public code decides (never the
error on the test scenes): the normal standardised per channel over the image (mean, population
std floored at 1e-3, z-score clipped to +-3; src/main.cpp:34-43; ``normal_features=
"standardised"``, ``"raw"`` the normal as rendered), Var[z] blurred with a 9 x 9 Gaussian
(``guide_variance_blur="gaussian9"``), the code's outlier pass on each filtered weight map (a
pixel with any channel 2.5 or more standard deviations from its 48 neighbours' mean takes the
map's 7 x 7 blur, ``outlier_removal="public_code"``), then re-projected onto the simplex; windows
reflected at the borders (``filter_border="reflect101"``); Eq. 33's denominator floored at 1e-6
(``variance_sum_floor``). Eq. 33 sums over the channels (``colour_distance="sum"``, the text and
the code). Eq. 32 stays the text's: 2 sigma^2 in each feature term (the code divides by sigma, its
slip: ``weight_filter.public_code_sigmas``). ``weight_filter.PAPER_FILTER`` is the
paper's filter alone, ``weight_filter.PUBLIC_CODE_FILTER`` the code's. Details:
:mod:`mcbench.combine.weight_filter`; the comparison with the code's output:
``tests/combine/test_ensemble_golden.py``.

Precision and memory: the solvers' geometry is float64; the weight filter works in float32
(relative rounding 1e-7, far below what a weight map shows) but for its colour term, and the
blend accumulates in float64. :func:`combine` makes one pass down the image in bands of rows
(see its docstring), so whole arrays are only what it returns (three images, 2N weight maps);
the render's layers and the inputs are read by rows (``reads_rows`` of :data:`METHOD`).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from mcbench.combine.ensemble_driver import ensemble_in_bands
from mcbench.combine.ensemble_weights import (CHANNELS, ENSEMBLE_DEFAULTS, FILTER_BORDERS,
                                              GUIDE_VARIANCE_BLURS, NORMAL_FEATURES, OUTLIER_PASSES,
                                              WEIGHTS)
from mcbench.combine.simplex_solvers.iterative import MAX_ITERATIONS, STARTS, TOLERANCE
from mcbench.combine.simplex_solvers.problem import SOLVERS
from mcbench.combine.weight_filter import FILTER_PARAMETERS
from mcbench.filters.bilateral import COLOUR_DISTANCES
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.contracts.method import MethodSpec

# the choices combine() validates (owned by mcbench.combine; here for its annotations):
# SOLVERS, STARTS, WEIGHTS, CHANNELS, GUIDE_VARIANCE_BLURS, COLOUR_DISTANCES, OUTLIER_PASSES,
# FILTER_BORDERS, NORMAL_FEATURES

BLOCK_PIXELS = 1 << 16   # pixels per block of rows that combine() solves at once (memory bound)


def combine(buffers: RenderBuffers, inputs: list[Denoised], *,
            solver: Literal[SOLVERS] = ENSEMBLE_DEFAULTS["solver"], seed: int = 0,
            max_iterations: int = MAX_ITERATIONS, tolerance: float = TOLERANCE,
            filter: bool = ENSEMBLE_DEFAULTS["filter"],
            weights: Literal[WEIGHTS] = ENSEMBLE_DEFAULTS["weights"],
            channels: Literal[CHANNELS] = ENSEMBLE_DEFAULTS["channels"],
            radius: int = FILTER_PARAMETERS["radius"],
            sigma_spatial: float = FILTER_PARAMETERS["sigma_spatial"],
            sigma_color: float = FILTER_PARAMETERS["sigma_color"],
            sigma_albedo: float = FILTER_PARAMETERS["sigma_albedo"],
            sigma_normal: float = FILTER_PARAMETERS["sigma_normal"],
            guide_variance_blur: Literal[GUIDE_VARIANCE_BLURS] = (
                ENSEMBLE_DEFAULTS["guide_variance_blur"]),
            outlier_removal: Literal[OUTLIER_PASSES] = ENSEMBLE_DEFAULTS["outlier_removal"],
            colour_distance: Literal[COLOUR_DISTANCES] = ENSEMBLE_DEFAULTS["colour_distance"],
            filter_border: Literal[FILTER_BORDERS] = ENSEMBLE_DEFAULTS["filter_border"],
            normal_features: Literal[NORMAL_FEATURES] = ENSEMBLE_DEFAULTS["normal_features"],
            variance_sum_floor: float = ENSEMBLE_DEFAULTS["variance_sum_floor"],
            start: Literal[STARTS] = ENSEMBLE_DEFAULTS["start"],
            away_steps: bool = ENSEMBLE_DEFAULTS["away_steps"]) -> Denoised:
    """Ensemble of the ``inputs`` (Sec. 4): solve raw weights from the half buffers, filter
    them (unless ``filter=False``, an ablation), and combine (Eq. 35).

    Ablations (Sec. 5.2.1-5.2.4; the defaults are the paper's method): ``weights=
    "unconstrained"`` drops w >= 0 (sum one only; the weight filter then does not clip);
    ``channels="single"`` shares one weight vector per pixel by the RGB channels;
    ``solver="qp"`` solves the same problems with a general QP solver (slow; Fig. 6);
    ``filter=False`` keeps the raw weights. See
    :func:`mcbench.combine.ensemble_weights.solve_weights`. The authors' public code's passes
    around the filter (see :func:`mcbench.combine.weight_filter.filter_weights`):
    ``guide_variance_blur``, ``outlier_removal``, ``colour_distance``, ``filter_border``,
    ``normal_features``, ``variance_sum_floor``; the defaults
    (:data:`mcbench.combine.ensemble_weights.ENSEMBLE_DEFAULTS`) follow the text, and the code
    where the text is silent (the module docstring). ``start``: the iterative solver's start
    (the paper's random one by default); ``away_steps``: its alpha in [-w_i / (1 - w_i), 1]
    instead of the paper's [0, 1] (False by default).

    Memory: one pass down the image in bands of rows, solving blocks of :data:`BLOCK_PIXELS`
    pixels as far as each band's filter halo needs
    (:func:`mcbench.combine.ensemble_driver.ensemble_in_bands`); what stays whole is what is
    returned: the three images and the 2N weight maps. The render's layers and the inputs'
    images are only ever indexed by rows, so they may be read from their files by rows
    (``reads_rows`` of :data:`METHOD`).

    Returns Denoised(full, a, b, extras) with float32 images; ``extras`` holds
    ``weights_raw_{i}`` and ``weights_filtered_{i}`` (H, W, 3) per input i (with
    ``filter=False`` the filtered maps equal the raw ones).

    Raises ValueError if an input holds NaN/Inf, or if a combined image is not finite in
    float32 (only unconstrained weights, bounded by 5e11, on radiance above ~1e26 could).
    """
    images, extras = ensemble_in_bands(
        buffers, inputs, block_pixels=BLOCK_PIXELS, solver=solver, seed=seed, max_iterations=max_iterations,
        tolerance=tolerance, filter=filter, weights=weights, channels=channels, radius=radius,
        sigma_spatial=sigma_spatial, sigma_color=sigma_color, sigma_albedo=sigma_albedo,
        sigma_normal=sigma_normal, guide_variance_blur=guide_variance_blur, outlier_removal=outlier_removal,
        colour_distance=colour_distance, filter_border=filter_border, normal_features=normal_features,
        variance_sum_floor=variance_sum_floor, start=start, away_steps=away_steps)
    return Denoised(full=images["full"], a=images["a"], b=images["b"], extras=extras)


def check_config(params: dict, *, config_key: str) -> None:
    """Parse-time check of what no annotation says: Eq. 33's denominator floor is finite and >= 0."""
    floor = params.get("variance_sum_floor", ENSEMBLE_DEFAULTS["variance_sum_floor"])
    if not (isinstance(floor, (int, float)) and not isinstance(floor, bool) and np.isfinite(floor) and floor >= 0):
        raise ValueError(f"{config_key}.variance_sum_floor: must be a finite number >= 0, got {floor!r}")


METHOD = MethodSpec(
    kind="combiner", label="Ensemble", run=combine, check_config=check_config, comparison_role="ensemble",
    # what combine() reads of the render: the noisy halves (Eq. 11-14) and the filter's features
    render_layers=("color_a", "color_b", "albedo", "normal"),
    # combine() only ever indexes the render's layers and the inputs' images by rows (x[y0:y1]), so a
    # job may hand it mcbench.io.exr.LayerRows (layers read from their files by rows) instead of arrays
    reads_rows=True)
