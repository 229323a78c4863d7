"""Generic cross (joint) bilateral filter, Zheng et al. 2021 Eq. 32-34.

Used by the ensemble's weight-map filter (``methods/ensemble.py``) and by the
joint-bilateral base denoiser. All maps share one kernel per pixel:

    kappa(p, q) = exp(-|p - q|^2 / (2 sigma_s^2))                       (spatial)
                * exp(-D^2(g(p), g(q)) / (2 sigma_g^2))                  (colour guide, Eq. 33)
                * prod_f exp(-|f(p) - f(q)|^2 / (2 sigma_f^2))            (features, Eq. 32)

    out_k(p) = sum_q kappa(p, q) values_k(q) / sum_q kappa(p, q)          (Eq. 34)

with q over the (2 radius + 1)^2 square window around p clipped at the image borders.

Colour distance (Eq. 33) -- our documented reading of ``|z_p - z_q|^2 / (Var_p + Var_q)``
for RGB is the per-channel mean::

    D^2 = 1/C sum_c (g_p,c - g_q,c)^2 / (v_p,c + v_q,c)

with a guard on the division: when ``v_p,c + v_q,c <= 1e-20`` the channel's term is 0 if
the numerator is 0 and +inf otherwise (kernel 0). Since kappa(p, p) = 1 the normaliser is
always >= 1, so the output is finite for finite inputs.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from mcbench.jit import cached_njit

VARIANCE_FLOOR = 1e-20


@cached_njit(parallel=True)
def _cbf_kernel(values, guide, guide_var, use_guide, inv_two_sg2, feats, inv_two_ss2, radius):
    """values (H, W, K), guide/guide_var (H, W, C), feats (H, W, F) pre-scaled so that the
    feature term is exp(-sum_f (f_p - f_q)^2). Returns (H, W, K) float64."""
    H, W, K = values.shape
    C = guide.shape[2]
    F = feats.shape[2]
    out = np.zeros((H, W, K))
    inv_c = 1.0 / max(C, 1)
    for y in prange(H):
        acc = np.empty(K)
        for x in range(W):
            for k in range(K):
                acc[k] = 0.0
            wsum = 0.0
            y0 = max(0, y - radius)
            y1 = min(H - 1, y + radius)
            x0 = max(0, x - radius)
            x1 = min(W - 1, x + radius)
            for qy in range(y0, y1 + 1):
                dy = qy - y
                for qx in range(x0, x1 + 1):
                    dx = qx - x
                    e = (dy * dy + dx * dx) * inv_two_ss2
                    for f in range(F):
                        d = feats[y, x, f] - feats[qy, qx, f]
                        e += d * d
                    if use_guide:
                        d2 = 0.0
                        for c in range(C):
                            num = guide[y, x, c] - guide[qy, qx, c]
                            num = num * num
                            den = guide_var[y, x, c] + guide_var[qy, qx, c]
                            if den <= VARIANCE_FLOOR:
                                if num != 0.0:
                                    d2 = np.inf
                                    break
                            else:
                                d2 += num / den
                        if d2 == np.inf:
                            continue
                        e += d2 * inv_c * inv_two_sg2
                    wq = np.exp(-e)
                    if wq == 0.0:
                        continue
                    wsum += wq
                    for k in range(K):
                        acc[k] += wq * values[qy, qx, k]
            inv = 1.0 / wsum
            for k in range(K):
                out[y, x, k] = acc[k] * inv
    return out


def cross_bilateral_filter(values, guide, guide_variance, features, feature_sigmas,
                           sigma_spatial, sigma_guide, radius) -> np.ndarray:
    """Filter K maps with one shared cross-bilateral kernel per pixel (Eq. 32-34).

    Parameters
    ----------
    values : (K, H, W) array (a single (H, W) map is accepted and returned as (1, H, W)).
    guide : (H, W, C) colour guide (e.g. the raw combined image z) or None for no colour term.
    guide_variance : (H, W, C) per-pixel variance of ``guide`` (Var[z] in Eq. 33); ignored
        when ``guide`` is None.
    features : list of (H, W, Cf) or (H, W) feature buffers (albedo, normal, depth, ...).
    feature_sigmas : list of positive floats, one per feature (sigma_g in Eq. 32), in the
        feature's units.
    sigma_spatial : positive float, pixels (sigma_s).
    sigma_guide : positive float, unitless (sigma_z, in units of the normalised distance D).
    radius : int >= 0, half width of the square window in pixels.

    Returns
    -------
    (K, H, W) float64 array: the normalised weighted averages (Eq. 34). Finite for finite
    inputs (the centre pixel always has weight 1).
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 2:
        values = values[None]
    if values.ndim != 3:
        raise ValueError(f"values must be (K, H, W), got shape {values.shape}")
    K, H, W = values.shape
    features = list(features or [])
    feature_sigmas = list(feature_sigmas or [])
    if len(features) != len(feature_sigmas):
        raise ValueError(f"{len(features)} features but {len(feature_sigmas)} feature sigmas")
    radius = int(radius)
    if radius < 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    if not sigma_spatial > 0:
        raise ValueError(f"sigma_spatial must be > 0, got {sigma_spatial}")

    scaled = []
    for i, (f, s) in enumerate(zip(features, feature_sigmas)):
        f = np.asarray(f, dtype=np.float64)
        if f.ndim == 2:
            f = f[:, :, None]
        if f.ndim != 3 or f.shape[:2] != (H, W):
            raise ValueError(f"feature {i} has shape {f.shape}, expected ({H}, {W}[, C])")
        if not s > 0:
            raise ValueError(f"feature sigma {i} must be > 0, got {s}")
        scaled.append(f / (np.sqrt(2.0) * float(s)))
    feats = (np.ascontiguousarray(np.concatenate(scaled, axis=2)) if scaled
             else np.zeros((H, W, 0)))

    if guide is not None:
        guide = np.asarray(guide, dtype=np.float64)
        if guide.ndim == 2:
            guide = guide[:, :, None]
        gvar = np.asarray(guide_variance, dtype=np.float64)
        if gvar.ndim == 2:
            gvar = gvar[:, :, None]
        if guide.shape[:2] != (H, W) or gvar.shape != guide.shape:
            raise ValueError(f"guide {guide.shape} / guide_variance {gvar.shape} do not match "
                             f"the values' image size ({H}, {W})")
        if not sigma_guide > 0:
            raise ValueError(f"sigma_guide must be > 0, got {sigma_guide}")
        use_guide = True
        inv_two_sg2 = 1.0 / (2.0 * float(sigma_guide) ** 2)
        guide = np.ascontiguousarray(guide)
        gvar = np.ascontiguousarray(np.maximum(gvar, 0.0))
    else:
        guide = np.zeros((H, W, 1))
        gvar = np.zeros((H, W, 1))
        use_guide = False
        inv_two_sg2 = 0.0

    vals = np.ascontiguousarray(np.moveaxis(values, 0, -1))  # (H, W, K)
    out = _cbf_kernel(vals, guide, gvar, use_guide, inv_two_sg2, feats,
                      1.0 / (2.0 * float(sigma_spatial) ** 2), radius)
    return np.ascontiguousarray(np.moveaxis(out, -1, 0))
