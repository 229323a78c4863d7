"""Filtering an image with predicted per-pixel kernels.

* :func:`apply_pixel_kernels` -- KPCN (Bako et al. 2017, Eq. 5-6): each pixel p has its own
  k×k kernel, the softmax of k² predicted logits z_p(q); ``out(p) = Σ_q softmax(z_p)(q) x(q)``.
* :func:`apply_shared_kernels` -- the weight-sharing kernels of Fan et al. 2021 (Eq. 3-4): one
  importance value I(q) per pixel, ``w_p(q) = exp I(q) / Σ_{q'∈Ω_p} exp I(q')``.

At the image border both restrict the softmax to the neighbours inside the image (our choice:
no padding value leaks into the result and every kernel still sums to one).

Eq. 3-4 need no k×k kernel map at all: with ``e = exp I``,
``R(p) = Σ_{q∈Ω_p} e(q) r(q) / Σ_{q∈Ω_p} e(q) = box_k(e·r)(p) / box_k(e)(p)``, two box filters,
O(1) per pixel whatever k (Fan et al. write a streaming CUDA kernel to the same end; we use
``avg_pool2d``). Importance values are bounded to ``[-IMPORTANCE_BOUND, IMPORTANCE_BOUND]``
(a scaled tanh) so that exp never over- or underflows in float32; tests compare both functions
with explicit unfold-and-softmax kernels.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

IMPORTANCE_BOUND = 10.0


def _unfold(x: torch.Tensor, k: int) -> torch.Tensor:
    """(N, C, H, W) -> (N, C, k², H, W) neighbourhoods, zero outside the image."""
    n, c, h, w = x.shape
    return F.unfold(x, k, padding=k // 2).view(n, c, k * k, h, w)


def inside_mask(height: int, width: int, k: int, device=None, dtype=torch.float32) -> torch.Tensor:
    """(1, k², H, W): 1 where neighbour q of pixel p lies inside the image, else 0."""
    ones = torch.ones(1, 1, height, width, device=device, dtype=dtype)
    return _unfold(ones, k)[:, 0]


def apply_pixel_kernels(image: torch.Tensor, logits: torch.Tensor, k: int) -> torch.Tensor:
    """Filter ``image`` (N, C, H, W) with per-pixel softmax kernels from ``logits`` (N, k², H, W).

    The k² logits of pixel p are ordered row-major over the window (dy, dx) in
    [-k//2, k//2]²; neighbours outside the image are excluded from the softmax.
    """
    n, c, h, w = image.shape
    if logits.shape != (n, k * k, h, w):
        raise ValueError(f"logits have shape {tuple(logits.shape)}, expected {(n, k * k, h, w)}")
    mask = inside_mask(h, w, k, device=image.device, dtype=image.dtype)
    weights = torch.softmax(logits.masked_fill(mask == 0, float("-inf")), dim=1)
    return (_unfold(image, k) * weights.unsqueeze(1)).sum(dim=2)


def bound_importance(raw: torch.Tensor) -> torch.Tensor:
    """Map raw network outputs to importance values in (-IMPORTANCE_BOUND, IMPORTANCE_BOUND)."""
    return IMPORTANCE_BOUND * torch.tanh(raw / IMPORTANCE_BOUND)


def apply_shared_kernels(image: torch.Tensor, importance: torch.Tensor, k: int) -> torch.Tensor:
    """Fan et al. 2021 Eq. 3-4: filter ``image`` (N, C, H, W) with kernels built from one
    importance map ``importance`` (N, 1, H, W) (already bounded, see :func:`bound_importance`).

    Returns (N, C, H, W). Exactly the softmax-of-unfolded-importance kernels, as a ratio of two
    k×k box filters.
    """
    if importance.shape[1] != 1 or importance.shape[2:] != image.shape[2:]:
        raise ValueError(f"importance {tuple(importance.shape)} does not match image {tuple(image.shape)}")
    # A common shift per image leaves every ratio unchanged and keeps exp() <= 1.
    shift = importance.flatten(1).amax(dim=1).view(-1, 1, 1, 1)
    weight = torch.exp(importance - shift)
    numerator = F.avg_pool2d(weight * image, k, stride=1, padding=k // 2, count_include_pad=True)
    denominator = F.avg_pool2d(weight, k, stride=1, padding=k // 2, count_include_pad=True)
    return numerator / denominator.clamp(min=torch.finfo(image.dtype).tiny)
