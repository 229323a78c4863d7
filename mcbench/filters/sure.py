"""Progressive denoising (Firmino et al. 2022): SURE of a denoised image, the mixing activation
f_act and the t-test safeguard, as pure NumPy functions (float64 inside, never NaN/Inf).

Notation of the paper (Sec. 4): ``x`` the MC render (the noisy image, (H, W, 3) linear HDR
radiance), ``σ²`` its per-pixel, per-channel variance *of the mean* (the renders' ``variance``
layers, :mod:`mcbench.io.buffers`), ``y = f(x)`` the denoised image, ``α`` the per-pixel,
per-channel mixing parameter, ``z = x + α (y − x)`` (Eq. 11).

* :func:`mc_divergence` -- Eq. 2, the Monte Carlo estimate of ``tr(J_F(x) Σ)`` per pixel and
  channel: ``d = (1/(εK)) Σ_k b_k ⊙ (F(x + ε b_k) − F(x))`` with ``b_k ~ N(0, Σ)``, Σ diagonal
  (the paper's assumption, Sec. 3.2); ``d_i`` estimates ``σ_i² ∂F_i/∂x_i`` (the off-diagonal
  terms have zero mean because the b's channels and pixels are independent), i.e. the
  ``σ² f′(x)`` of the one-dimensional SURE. ``ε = 1e-4`` and ``K = 1`` by default (the paper:
  "e.g. 10^-4", K "1 or 4").
* :func:`sure_terms` -- Eq. 1 per pixel (Sec. 4.1): ``SURE = (y − x)² + 2 σ² f′(x) − σ²``, an
  unbiased estimate of ``E[(y − μ)²]`` for Gaussian ``x`` (tested on a linear filter with a known
  divergence); returns the terms the network also sees (``(y − x)²`` and ``σ² f′``).
* :func:`f_act` -- Eq. 19, ``(x1 − x2) / max(x3, ε)`` with ε = 1e-6, and :func:`mixing_alpha`,
  the same clipped to [0, 1] (the paper leaves α unbounded; we keep z between x and y, as the
  authors' public code also does).
* :func:`t_test_scale` -- Eq. 12-18: over each pixel's 11×11 neighbourhood N_p, with the
  Gaussian weights κ (Eq. 15) and the neighbour M_p of largest variance (Eq. 16),
  ``x̄_p = x_{M_p} + Σ κ x_q`` (Eq. 12), ``Var[x̄_p] = Var[x_{M_p}] + Σ κ² Var[x_q]`` (Eq. 13),
  ``z̄_p = z_{M_p} + Σ κ z_q`` (Eq. 14), ``t_p = (z̄_p − x̄_p) / (sqrt(Var[x̄_p]) + ε)`` (Eq. 17)
  and ``α′_p = (1 − Φ(a (|t_p| − c))) α_p`` (Eq. 18), a = 2, c = 4.2, Φ the standard normal CDF.

Choices where the paper is silent or ambiguous (each tested in ``tests/methods/test_progressive.py``):

* **σ_s** (Eq. 15): the paper's "min(sqrt(Var[x̄]), 1) × 10², where x̄ is the image mean" is
  read as Var[x̄] = the image mean of the per-pixel variance of the mean (mean over pixels and
  channels of ``σ²``), which is what the authors' public code computes; so the neighbourhood
  weights are nearly a box at low spp (σ_s ≈ 10-100 px) and narrow at high spp. A noise-free image
  (mean variance 0) would give σ_s = 0: σ_s is floored at :data:`MIN_SIGMA_S` = 1e-3 (as the
  public code), where κ is a spike at the centre pixel (overflow-free: see :func:`gaussian_kappa`).
* **κ is not normalised** (Eq. 15 as printed: ``1/(σ_s sqrt(2π)) exp(−d²/(2σ_s²))``, the 1-D
  normalisation of a 2-D kernel), and x_{M_p} enters with weight 1 on top of its own κ term
  (Eq. 12 as printed): both as the paper writes them.
* **Per channel**: M_p, the sums and t_p are computed per colour channel (the paper's α is per
  pixel and channel; the public code sums the channels). Ties in M_p go to the first neighbour in
  row-major (dy, dx) order; neighbours outside the image are not part of N_p.
* **ε of Eq. 17**: 1e-6 (radiance units; the paper gives none, the public code uses 1e-6).
* **Φ** via ``scipy.special.ndtr`` (the paper's S; the logistic function is its alternative).

Units: ``x``, ``y``, ``z`` radiance; ``σ²``, SURE and its terms radiance²; κ 1/pixel; t
dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.special import ndtr

# Eq. 2: perturbation scale and Monte Carlo iterations (the paper: "e.g. 10^-4", "1 or 4").
EPSILON = 1e-4
ITERATIONS = 1
# Eq. 19: the singularity guard of f_act.
FACT_EPS = 1e-6
# Eq. 12-18 (Sec. 4.2): 11×11 neighbourhood, a = 2 (strength), c = 4.2 (shift), ε of Eq. 17.
WINDOW = 11
T_STRENGTH = 2.0
T_SHIFT = 4.2
T_EPS = 1e-6
# σ_s = min(sqrt(mean variance), 1) × SIGMA_S_SCALE, floored at MIN_SIGMA_S (module docstring).
SIGMA_S_SCALE = 100.0
MIN_SIGMA_S = 1e-3


def _as64(array) -> np.ndarray:
    return np.asarray(array, dtype=np.float64)


def _finite(array: np.ndarray) -> np.ndarray:
    """Replace NaN by 0 and ±Inf by the largest finite float64 (inputs are checked finite
    upstream; this only guards arithmetic overflow of absurd inputs)."""
    return np.nan_to_num(array, nan=0.0, posinf=np.finfo(np.float64).max, neginf=-np.finfo(np.float64).max)


# --------------------------------------------------------------------------- SURE (Eq. 1-2)

def perturbation(variance: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One ``b ~ N(0, Σ)`` with Σ = diag(variance) (Eq. 2): ``sqrt(max(σ², 0)) · N(0, 1)``, float64,
    the shape of ``variance``."""
    std = np.sqrt(np.maximum(_as64(variance), 0.0))
    return std * rng.standard_normal(std.shape)


def mc_divergence(denoise: Callable[[np.ndarray], np.ndarray], x: np.ndarray, variance: np.ndarray, *,
                  epsilon: float = EPSILON, iterations: int = ITERATIONS, seed=0,
                  reference: np.ndarray | None = None) -> np.ndarray:
    """Eq. 2 per pixel and channel: ``d = (1/(εK)) Σ_k b_k ⊙ (F(x + ε b_k) − F(x))``.

    ``denoise``: F, mapping an (H, W, 3) colour image (float32, as the renders) to its denoised
    (H, W, 3) image; it is called K times on perturbed colour (and once on ``x`` unless
    ``reference`` = F(x) is given: it must be F's output on exactly this ``x`` in this process, or
    the difference sees more than the perturbation). ``variance`` (H, W, 3): σ², the variance of
    the mean of ``x``. ``seed``: anything ``numpy.random.default_rng`` takes (the b_k of one call
    are reproducible). Returns float64 (H, W, 3), the estimate of ``σ² ∂F/∂x`` per element (so
    ``Σ_i d_i`` estimates ``tr(J_F Σ)``); finite.

    The perturbed image is rounded to float32 before F sees it, and the estimator uses the
    perturbation F actually saw, ``(float32(x + ε b) − x) / ε``, in place of b's rounding-free value.
    """
    if iterations < 1:
        raise ValueError(f"Eq. 2 needs at least one Monte Carlo iteration, got {iterations}")
    if not epsilon > 0:
        raise ValueError(f"Eq. 2 needs ε > 0, got {epsilon}")
    x32 = np.asarray(x, dtype=np.float32)
    x64 = x32.astype(np.float64)
    base = _as64(denoise(x32) if reference is None else reference)
    rng = np.random.default_rng(seed)
    total = np.zeros_like(x64)
    for _ in range(int(iterations)):
        b = perturbation(variance, rng)
        perturbed = (x64 + epsilon * b).astype(np.float32)
        seen = (perturbed.astype(np.float64) - x64) / epsilon
        total += seen * (_as64(denoise(perturbed)) - base)
    return _finite(total / (epsilon * iterations))


@dataclass(frozen=True)
class SureTerms:
    """Eq. 1 per pixel and channel, float64 (H, W, 3), radiance².

    sure         ``(y − x)² + 2 σ² f′ − σ²``, the estimate of the denoised image's squared error
    residual_sq  ``(y − x)²``
    divergence   ``σ² f′``, the Monte Carlo divergence term (:func:`mc_divergence`)
    variance     ``σ²``, the estimate of the noisy image's squared error
    """

    sure: np.ndarray
    residual_sq: np.ndarray
    divergence: np.ndarray
    variance: np.ndarray


def sure_terms(x: np.ndarray, y: np.ndarray, variance: np.ndarray, divergence: np.ndarray) -> SureTerms:
    """SURE of ``y`` = F(x) per pixel and channel (Eq. 1 with diagonal Σ, the 1-D form of Sec. 4.1):
    ``(y − x)² + 2 d − σ²`` with ``d`` from :func:`mc_divergence` (or an exact σ² ∂F/∂x)."""
    x, y, variance, divergence = (_as64(a) for a in (x, y, variance, divergence))
    residual_sq = _finite((y - x) ** 2)
    variance = np.maximum(variance, 0.0)
    return SureTerms(sure=_finite(residual_sq + 2.0 * divergence - variance), residual_sq=residual_sq,
                     divergence=divergence, variance=variance)


# --------------------------------------------------------------------------- f_act, mixing

def f_act(x1, x2, x3, *, eps: float = FACT_EPS) -> np.ndarray:
    """Eq. 19: ``(x1 − x2) / max(x3, ε)``, elementwise, float64 (unbounded; an overflow gives the
    largest finite float64)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite((_as64(x1) - _as64(x2)) / np.maximum(_as64(x3), eps))


def mixing_alpha(x1, x2, x3, *, eps: float = FACT_EPS) -> np.ndarray:
    """α = :func:`f_act` clipped to [0, 1] (module docstring: z stays between x and y)."""
    return np.clip(f_act(x1, x2, x3, eps=eps), 0.0, 1.0)


def mix(x: np.ndarray, y: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Eq. 11: ``z = x + α (y − x)``, float64. Swapping the roles, ``mix(y, x, 1 − α)``, is the
    same image (the swap augmentation of Sec. 4.3 trains the network's α on both)."""
    x, y = _as64(x), _as64(y)
    return x + _as64(alpha) * (y - x)


# --------------------------------------------------------------------------- t-test (Eq. 12-18)

def spatial_sigma(variance: np.ndarray, *, scale: float = SIGMA_S_SCALE, floor: float = MIN_SIGMA_S) -> float:
    """σ_s of Eq. 15 in pixels: ``min(sqrt(mean σ²), 1) × scale``, at least ``floor``
    (module docstring: Var[x̄] read as the image mean of the variance of the mean)."""
    mean = float(np.mean(np.maximum(_as64(variance), 0.0))) if np.size(variance) else 0.0
    return max(min(np.sqrt(mean), 1.0) * scale, floor)


def gaussian_kappa(sigma_s: float, window: int = WINDOW) -> np.ndarray:
    """Eq. 15 on a ``window``×``window`` grid of offsets (row-major (dy, dx), centre at the
    middle): ``κ = exp(−(dx² + dy²)/(2σ_s²)) / (σ_s sqrt(2π))``, float64, not normalised. For
    σ_s below 1/sqrt(2·700) the off-centre weights underflow to 0 and the centre's 1/(σ_s√2π)
    stays finite (σ_s ≥ MIN_SIGMA_S)."""
    if window < 1 or window % 2 == 0:
        raise ValueError(f"the t-test window must be odd and positive, got {window}")
    sigma_s = max(float(sigma_s), MIN_SIGMA_S)
    r = window // 2
    d = np.arange(-r, r + 1, dtype=np.float64)
    squared = d[:, None] ** 2 + d[None, :] ** 2
    return np.exp(-squared / (2.0 * sigma_s ** 2)) / (sigma_s * np.sqrt(2.0 * np.pi))


@dataclass(frozen=True)
class TTest:
    """The quantities of Eq. 12-18 per pixel and channel, float64 (H, W, 3)."""

    x_bar: np.ndarray       # Eq. 12
    var_bar: np.ndarray     # Eq. 13
    z_bar: np.ndarray       # Eq. 14
    t: np.ndarray           # Eq. 17
    scale: np.ndarray       # 1 − Φ(a(|t| − c)), the factor of Eq. 18
    alpha: np.ndarray       # α′, Eq. 18
    sigma_s: float          # Eq. 15's σ_s used


def t_test(x: np.ndarray, y: np.ndarray, variance: np.ndarray, alpha: np.ndarray, *,
           window: int = WINDOW, strength: float = T_STRENGTH, shift: float = T_SHIFT,
           eps: float = T_EPS, sigma_s: float | None = None) -> TTest:
    """The t-test safeguard of Sec. 4.2 (Eq. 12-18) on one image.

    ``x`` noisy (H, W, 3), ``y`` denoised, ``variance`` σ² of ``x``, ``alpha`` the network's α
    (H, W, 3) (or broadcastable); ``sigma_s`` overrides :func:`spatial_sigma`. Per pixel p and
    channel: the neighbourhood N_p is the ``window``×``window`` square cut to the image, M_p its
    neighbour of largest σ² (first in row-major order on ties), κ :func:`gaussian_kappa`. Returns
    a :class:`TTest`; every array finite.
    """
    x, y, variance = _as64(x), _as64(y), np.maximum(_as64(variance), 0.0)
    alpha = np.broadcast_to(_as64(alpha), x.shape)
    z = mix(x, y, alpha)
    sigma = spatial_sigma(variance) if sigma_s is None else max(float(sigma_s), MIN_SIGMA_S)
    if window < 1 or window % 2 == 0:
        raise ValueError(f"the t-test window must be odd and positive, got {window}")
    r = window // 2
    h, w = x.shape[:2]
    # Σ_q κ_pq v_q over the window cut to the image: κ = g(dy) g(dx) / (σ_s sqrt(2π)) is separable
    # (g(d) = exp(−d²/(2σ_s²))), so two 1-D passes of `window` taps over zero-padded arrays.
    g = np.exp(-np.arange(-r, r + 1, dtype=np.float64) ** 2 / (2.0 * sigma ** 2))
    norm = 1.0 / (sigma * np.sqrt(2.0 * np.pi))
    sum_x = norm * _separable_sum(x, g, r)
    sum_z = norm * _separable_sum(z, g, r)
    sum_v = norm ** 2 * _separable_sum(variance, g * g, r)
    # M_p: running maximum of σ² over the window offsets in row-major (dy, dx) order (strictly
    # greater replaces, so the first of equal maxima stays); outside the image σ² = −inf.
    pad = ((r, r), (r, r)) + ((0, 0),) * (x.ndim - 2)
    xp, zp = np.pad(x, pad), np.pad(z, pad)
    vp = np.pad(variance, pad, constant_values=-np.inf)
    best_v = np.full_like(x, -np.inf)
    best_x = np.zeros_like(x)
    best_z = np.zeros_like(x)
    better = np.empty(x.shape, dtype=bool)
    for i in range(window):
        for j in range(window):
            vs = vp[i:i + h, j:j + w]
            np.greater(vs, best_v, out=better)
            np.copyto(best_v, vs, where=better)
            np.copyto(best_x, xp[i:i + h, j:j + w], where=better)
            np.copyto(best_z, zp[i:i + h, j:j + w], where=better)
    x_bar = best_x + sum_x                         # Eq. 12
    var_bar = np.maximum(best_v, 0.0) + sum_v      # Eq. 13
    z_bar = best_z + sum_z                         # Eq. 14
    t = _finite((z_bar - x_bar) / (np.sqrt(var_bar) + eps))    # Eq. 17
    scale = 1.0 - ndtr(strength * (np.abs(t) - shift))          # Eq. 18
    return TTest(x_bar=x_bar, var_bar=var_bar, z_bar=z_bar, t=t, scale=scale, alpha=scale * alpha,
                 sigma_s=sigma)


def _separable_sum(image: np.ndarray, taps: np.ndarray, r: int) -> np.ndarray:
    """Σ_{dy,dx} taps[dy] taps[dx] image[p + (dy, dx)] with zeros outside the image (H, W[, C])."""
    h, w = image.shape[:2]
    rows = np.zeros_like(image)
    padded = np.pad(image, ((r, r),) + ((0, 0),) * (image.ndim - 1))
    for i, tap in enumerate(taps):
        rows += tap * padded[i:i + h]
    out = np.zeros_like(image)
    padded = np.pad(rows, ((0, 0), (r, r)) + ((0, 0),) * (image.ndim - 2))
    for j, tap in enumerate(taps):
        out += tap * padded[:, j:j + w]
    return out


def t_test_scale(x, y, variance, alpha, **options) -> np.ndarray:
    """α′ of Eq. 18 (:func:`t_test`'s ``alpha``), float64 (H, W, 3)."""
    return t_test(x, y, variance, alpha, **options).alpha


def divergence_map(denoise_image: Callable, image, *, iterations: int = ITERATIONS, epsilon: float = EPSILON,
                   seed=0) -> np.ndarray:
    """σ²f′ of Eq. 2 for one image (float64 (H, W, 3)): ``denoise_image`` (a function of an
    :class:`mcbench.io.buffers.ImageBuffers`, returning (H, W, 3) radiance) re-run on ``image`` with
    its colour perturbed (variance and features as they are), K = ``iterations`` times plus once
    unperturbed (:func:`mc_divergence`)."""
    from dataclasses import replace

    return mc_divergence(lambda color: denoise_image(replace(image, color=color)), image.color,
                         image.variance, epsilon=epsilon, iterations=iterations, seed=seed)
