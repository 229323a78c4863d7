"""Combination kernels of Back et al. 2020 ("Deep combiner for independent and correlated pixel
estimates"): combining an independent estimate ``y`` (the noisy render) with a correlated one
``z`` (a denoiser's output) through predicted per-pixel weights, and the network inputs shared by
the single- and multi-buffer deep combiners (``methods/deep_combiner.py``,
``methods/deep_combiner_mb.py``).

Shapes: images (N, C, H, W), sub-buffer stacks (N, B, C, H, W), weights (N, B, k², H, W); torch,
any float dtype (float32 in the networks, float64 in the tests). The window Ω'_c of pixel c is
k×k, ordered row-major over (dy, dx) in [-k//2, k//2]², its centre c at index k²//2; Ω_c is
Ω'_c without c. Neighbours outside the image get weight 0 (as :mod:`mcbench.nn.kernels`).

Single buffer, Eq. 8 (= Eq. 4), with W_c = w_c + Σ_{i∈Ω_c} w_i:

    β_c = [w_c y_c + Σ_{i∈Ω_c} w_i y_i + Σ_{i∈Ω_c} w_i (z_c − z_i)] / W_c.

Because the centre term of Σ w_i (z_c − z_i) vanishes, the sum may run over Ω'_c:
Σ_{i∈Ω_c} w_i (z_c − z_i) = W_c z_c − Σ_{i∈Ω'_c} w_i z_i, hence

    β_c = z_c + (1 / W_c) Σ_{i∈Ω'_c} w_i (y_i − z_i)                           (Eq. 15)

-- the correlated estimate plus a weighted mean of the residuals y − z (the "boosting" form of
Back et al. Sec. 6), valid for any non-negative weights, not only normalised ones.

Multi buffer, Eq. 14, B sub-buffers (disjoint sample subsets) y_{·,b}, z_{·,b} with weights
w_{i,b} and W_c = Σ_b Σ_{i∈Ω'_c} w_{i,b}; the same rearrangement per b gives

    β_c = (1 / W_c) Σ_b [W_{c,b} z_{c,b} + Σ_{i∈Ω'_c} w_{i,b} (y_{i,b} − z_{i,b})],
    W_{c,b} = Σ_{i∈Ω'_c} w_{i,b},

which for B = 1 is Eq. 15. We evaluate it grouped as

    β_c = (1 / W_c) Σ_b [w_{c,b} y_{c,b} + (W_{c,b} − w_{c,b}) z_{c,b} + Σ_{i∈Ω_c} w_{i,b} (y_{i,b} − z_{i,b})]

(the same sum): one window sum over the residual y − z (one unfold instead of two), and the centre
enters as w_c y_c, so that weights w_c = 1, w_i = 0 return y_c bit for bit (z_c + (y_c − z_c)
would round).

Weights: the network's logits go through one softmax over all B·k² window entries of a pixel
(:func:`combination_weights`). That is how the positivity w > 0 of Eq. 4 is enforced, and it
makes W_c = 1 (the normalisation of Eq. 8/14 is then a no-op; the kernels still divide by W_c so
that they are exact for any non-negative weights).

A window without any weight (W_c = 0, only possible for hand-made weights) leaves Eq. 6/13
without information: every β_c minimises it. We then return the independent estimate, the mean
over the sub-buffers of y_c (y_c itself for B = 1): it is unbiased (Eq. 1), whereas z_c may carry
the very bias the combination exists to remove, and it is what the weights w_c = 1, w_i = 0
give. Weights are divided by their per-pixel maximum before the normalisation, so W_c ≥ 1 and a
window of tiny (even subnormal) weights is as exact as one of ordinary weights: no NaN/Inf.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from mcbench.nn.features import guide_features, log_noise_level, log_radiance
from mcbench.nn.kernels import inside_mask

# Network inputs of one image (see image_inputs) and of each sub-buffer (sub_buffer_inputs).
IMAGE_INPUT_CHANNELS = 24
SUB_BUFFER_INPUT_CHANNELS = 7


def window_neighbourhoods(x: torch.Tensor, k: int) -> torch.Tensor:
    """(N, C, H, W) -> (N, C, k², H, W): the k×k window of every pixel (row-major over
    (dy, dx)), zero outside the image."""
    n, c, h, w = x.shape
    return F.unfold(x, k, padding=k // 2).view(n, c, k * k, h, w)


def window_size(entries: int) -> int:
    """The odd window width k of a window of ``entries`` = k² entries (ValueError otherwise)."""
    k = math.isqrt(entries)
    if k * k != entries or k % 2 == 0:
        raise ValueError(f"a window of {entries} entries is not k×k with k odd")
    return k


def combination_weights(logits: torch.Tensor, k: int, *, bins: int = 1) -> torch.Tensor:
    """Positive, normalised kernel weights from network logits.

    ``logits`` (N, bins·k², H, W), channel ``b·k² + j`` for sub-buffer b and window entry j ->
    weights (N, bins, k², H, W): a softmax over all bins·k² entries of each pixel, with the
    neighbours outside the image excluded (weight exactly 0). Every weight inside the image is
    > 0 unless its logit is so far below the largest that exp underflows; the weights of a
    pixel sum to 1 over (bins, window). Finite for any finite logits (softmax subtracts the
    maximum; the centre is always inside the image, so no pixel has all entries excluded).
    """
    n, channels, h, w = logits.shape
    if k < 1 or k % 2 == 0 or bins < 1 or channels != bins * k * k:
        raise ValueError(f"logits have {channels} channels; expected bins·k² = {bins}·{k}² with k odd")
    mask = inside_mask(h, w, k, device=logits.device, dtype=logits.dtype)     # (1, k², H, W)
    masked = logits.view(n, bins, k * k, h, w).masked_fill(mask.unsqueeze(1) == 0, float("-inf"))
    return torch.softmax(masked.flatten(1, 2), dim=1).view(n, bins, k * k, h, w)


def combine_multi(y_sub: torch.Tensor, z_sub: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Eq. 14: combine B independent sub-buffer estimates ``y_sub`` with their correlated
    counterparts ``z_sub`` (both (N, B, C, H, W), linear radiance) using ``weights``
    (N, B, k², H, W), non-negative and finite (ValueError otherwise), not necessarily normalised.

    Returns β (N, C, H, W) in the units of y: the module docstring's form
    ``(Σ_b W_{c,b} z_{c,b} + Σ_b Σ_{i∈Ω'_c} w_{i,b} (y_{i,b} − z_{i,b})) / W_c``, normalised over
    all B sub-buffers and window entries; weights of neighbours outside the image are ignored;
    a pixel whose window holds no weight gets the mean of its y_{c,b}.
    """
    if y_sub.dim() != 5 or z_sub.shape != y_sub.shape:
        raise ValueError(f"y_sub {tuple(y_sub.shape)} and z_sub {tuple(z_sub.shape)} must both be (N, B, C, H, W)")
    n, bins, c, h, w = y_sub.shape
    if weights.dim() != 5 or weights.shape[:2] != (n, bins) or weights.shape[3:] != (h, w):
        raise ValueError(f"weights {tuple(weights.shape)} do not match y_sub {tuple(y_sub.shape)}: "
                         f"expected (N, B, k², H, W)")
    k = window_size(weights.shape[2])
    if not bool(torch.isfinite(weights).all()) or bool((weights < 0).any()):
        raise ValueError("combination weights must be finite and non-negative")
    weights = weights * inside_mask(h, w, k, device=weights.device, dtype=weights.dtype).unsqueeze(1)
    peak = weights.flatten(1, 2).amax(dim=1, keepdim=True)                      # (N, 1, H, W)
    has_weight = peak > 0
    weights = weights / torch.where(has_weight, peak, torch.ones_like(peak)).unsqueeze(1)
    centre_index = k * k // 2
    not_centre = torch.ones(k * k, device=weights.device, dtype=weights.dtype)
    not_centre[centre_index] = 0.0
    neighbours = weights * not_centre.view(1, 1, -1, 1, 1)                      # w_{i,b}, i ∈ Ω_c
    centre = weights[:, :, centre_index]                                        # w_{c,b}: (N, B, H, W)
    neighbour_sum = neighbours.sum(dim=2)                                       # W_{c,b} − w_{c,b}
    residuals = window_neighbourhoods((y_sub - z_sub).flatten(0, 1), k).view(n, bins, c, k * k, h, w)
    numerator = ((centre.unsqueeze(2) * y_sub + neighbour_sum.unsqueeze(2) * z_sub).sum(dim=1)
                 + (residuals * neighbours.unsqueeze(2)).sum(dim=(1, 3)))
    total = (centre + neighbour_sum).sum(dim=1, keepdim=True)                   # W_c ≥ 1 where has_weight
    beta = numerator / torch.where(has_weight, total, torch.ones_like(total))
    return torch.where(has_weight, beta, y_sub.mean(dim=1))


def combine_single(y: torch.Tensor, z: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Eq. 8: combine the independent estimate ``y`` with the correlated estimate ``z`` (both
    (N, C, H, W), linear radiance) using ``weights`` (N, k², H, W) or (N, 1, k², H, W),
    non-negative and finite, not necessarily normalised.

    Returns β (N, C, H, W) = z_c + Σ_{i∈Ω'_c} w_i (y_i − z_i) / W_c (Eq. 15, derived in the
    module docstring); weights outside the image are ignored; a pixel whose window holds no
    weight gets y_c. Exactly :func:`combine_multi` with B = 1.
    """
    if weights.dim() == 4:
        weights = weights.unsqueeze(1)
    return combine_multi(y.unsqueeze(1), z.unsqueeze(1), weights)


# ---------------------------------------------------------------------------------------------
# Network inputs and the logit network shared by the two deep combiners.

def split_sub_buffers(stacked: torch.Tensor, bins: int) -> torch.Tensor:
    """(N, bins·C, H, W), sub-buffers concatenated along channels -> (N, bins, C, H, W)."""
    n, channels, h, w = stacked.shape
    if channels % bins:
        raise ValueError(f"{channels} channels do not split into {bins} sub-buffers")
    return stacked.reshape(n, bins, channels // bins, h, w)


def feature_noise_levels(batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """Standard deviations of the features' pixel means, (N, 7, H, W) dimensionless in [0, 1]:
    albedo (3) and normal (3) from ``albedo_variance``/``normal_variance`` as they are (both
    features live in [0, 1] / [-1, 1]), depth (1) from ``depth_variance`` divided by the image's
    largest depth (the scale of :func:`mcbench.nn.features.normalized_depth`); each clipped to
    [0, 1]. High where a pixel mixes surfaces (edges, fine geometry, depth of field)."""
    depth_scale = batch["depth"].flatten(1).amax(dim=1).clamp(min=1e-6).view(-1, 1, 1, 1)
    levels = [torch.sqrt(torch.clamp(batch["albedo_variance"], min=0.0)),
              torch.sqrt(torch.clamp(batch["normal_variance"], min=0.0)),
              torch.sqrt(torch.clamp(batch["depth_variance"], min=0.0)) / depth_scale]
    return torch.clamp(torch.cat(levels, dim=1), 0.0, 1.0)


def image_inputs(batch: dict[str, torch.Tensor]) -> torch.Tensor:
    """The image-level network input of a deep combiner, (N, IMAGE_INPUT_CHANNELS = 24, H, W):
    log(1+y) (3), log(1+z) (3), their difference log(1+y) − log(1+z) (3; where the base changed
    the image), y's log-space noise level (1, :func:`mcbench.nn.features.log_noise_level`), the
    guide features (7, :func:`mcbench.nn.features.guide_features`) and their noise levels (7,
    :func:`feature_noise_levels`). ``batch`` holds ``color`` (y), ``variance``, ``correlated``
    (z), the features and their variances, each (N, C, H, W)."""
    log_y, log_z = log_radiance(batch["color"]), log_radiance(batch["correlated"])
    return torch.cat([log_y, log_z, log_y - log_z, log_noise_level(batch["color"], batch["variance"]),
                      guide_features(batch), feature_noise_levels(batch)], dim=1)


def sub_buffer_inputs(batch: dict[str, torch.Tensor], bins: int) -> torch.Tensor:
    """Per sub-buffer b, log(1+y_b) (3), log(1+z_b) (3) and y_b's log-space noise level (1),
    concatenated over b: (N, bins·SUB_BUFFER_INPUT_CHANNELS, H, W), from ``color_sub``,
    ``correlated_sub`` and ``variance_sub`` (each (N, bins·3, H, W)). A firefly in one bin shows
    as a jump of that bin's log(1+y_b) and noise level against the other's."""
    y_sub = split_sub_buffers(batch["color_sub"], bins)
    z_sub = split_sub_buffers(batch["correlated_sub"], bins)
    variance_sub = split_sub_buffers(batch["variance_sub"], bins)
    parts = []
    for b in range(bins):
        parts += [log_radiance(y_sub[:, b]), log_radiance(z_sub[:, b]), log_noise_level(y_sub[:, b], variance_sub[:, b])]
    return torch.cat(parts, dim=1)


def logit_network(in_channels: int, *, channels: int, layers: int, dilated_layers: int,
                  out_channels: int) -> nn.Sequential:
    """The kernel-predicting stack: ``layers − 1`` 3×3 convolutions of ``channels`` filters with
    ReLU (the middle ``dilated_layers`` of them dilated by 2), then a 1×1 convolution to
    ``out_channels`` logits. Receptive field 1 + 2·(layers − 1) + 2·dilated_layers pixels
    (15 for 6 layers, 2 dilated: the 15×15 window). Spatial size is preserved."""
    hidden = layers - 1
    if hidden < 1 or not 0 <= dilated_layers <= hidden:
        raise ValueError(f"need layers ≥ 2 and 0 ≤ dilated_layers ≤ layers − 1, got {layers}, {dilated_layers}")
    first_dilated = (hidden - dilated_layers) // 2
    modules, width = [], in_channels
    for index in range(hidden):
        dilation = 2 if first_dilated <= index < first_dilated + dilated_layers else 1
        modules += [nn.Conv2d(width, channels, 3, padding=dilation, dilation=dilation), nn.ReLU(inplace=True)]
        width = channels
    modules.append(nn.Conv2d(width, out_channels, 1))
    return nn.Sequential(*modules)
