"""Input transforms of the learned denoisers, as pure functions of (N, C, H, W) tensors.

All radiance is linear HDR (the renders' units); ``variance`` is the per-pixel, per-channel
variance of the pixel mean (:mod:`mcbench.io.buffers`).

* :func:`log_radiance` -- ``log(1 + x)``, the range compression of KPCN's specular branch
  (Bako et al. 2017, Sec. 4.1) and of Chaitanya et al. 2017 (Sec. 5.1).
* :func:`demodulate` / :func:`remodulate` -- divide by ``albedo + ALBEDO_EPS`` before filtering and
  multiply back after (KPCN's diffuse branch, Fan et al. 2021 Sec. 4.2, Chaitanya et al.); our
  renders have no diffuse/specular split, so the whole colour is demodulated. Pixels without a
  meaningful albedo (every channel below ``NO_ALBEDO`` = 0.01: the environment, emitters, delta
  BSDFs, black surfaces -- a quarter of our training pixels) are not demodulated (factor 1, our
  choice): dividing them by ε would scale their colour by up to 316 and any kernel weight a
  neighbour puts on them would leak that much light into the neighbour.
* :func:`log_noise_level` -- the per-pixel standard deviation of ``log(1 + x)`` by the delta
  method, ``sqrt(Var x) / (1 + x)``, averaged over RGB: the noise-level input of every network.
* :func:`normalized_depth` -- depth divided by the image's largest depth, in [0, 1] (Fan et al.
  Sec. 5.1 "linearly scale ... depth to [0, 1]").
* :func:`spatial_gradients` -- forward differences in x and y (KPCN feeds feature gradients).
"""

from __future__ import annotations

import torch

# KPCN's demodulation epsilon (Bako et al. 2017): irradiance = colour / (albedo + 0.00316).
ALBEDO_EPS = 0.00316
# Below this albedo in every channel a pixel is not demodulated (see the module docstring).
NO_ALBEDO = 0.01


def log_radiance(color: torch.Tensor) -> torch.Tensor:
    """``log(1 + max(x, 0))`` of linear radiance, any shape."""
    return torch.log1p(torch.clamp(color, min=0.0))


def exp_radiance(log_color: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`log_radiance` (``exp(y) - 1``, clamped to ≥ 0 and to a finite range)."""
    return torch.expm1(torch.clamp(log_color, min=0.0, max=30.0))


def demodulation_factor(albedo: torch.Tensor) -> torch.Tensor:
    """``albedo + ALBEDO_EPS`` (albedo clipped to [0, 1]), or 1 where every channel of the albedo
    is below ``NO_ALBEDO``; (N, 3, H, W), always ≥ ALBEDO_EPS."""
    albedo = torch.clamp(albedo, 0.0, 1.0)
    has_albedo = albedo.amax(dim=1, keepdim=True) >= NO_ALBEDO
    return torch.where(has_albedo, albedo + ALBEDO_EPS, torch.ones_like(albedo))


def demodulate(color: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
    """Irradiance ``color / demodulation_factor(albedo)`` (N, 3, H, W), colour clamped to ≥ 0."""
    return torch.clamp(color, min=0.0) / demodulation_factor(albedo)


def remodulate(irradiance: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`demodulate`: ``irradiance * demodulation_factor(albedo)``."""
    return irradiance * demodulation_factor(albedo)


def demodulated_variance(variance: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
    """Variance of the irradiance: ``Var x / demodulation_factor(albedo)²``."""
    return torch.clamp(variance, min=0.0) / demodulation_factor(albedo) ** 2


def log_noise_level(value: torch.Tensor, variance: torch.Tensor) -> torch.Tensor:
    """Standard deviation of ``log(1 + value)`` by the delta method, mean over channels.

    ``value`` and ``variance`` (N, C, H, W) in the same linear units; returns (N, 1, H, W),
    dimensionless (relative noise for bright pixels, absolute noise for dark ones).
    """
    std = torch.sqrt(torch.clamp(variance, min=0.0))
    return (std / (1.0 + torch.clamp(value, min=0.0))).mean(dim=1, keepdim=True)


def normalized_depth(depth: torch.Tensor) -> torch.Tensor:
    """Depth (N, 1, H, W) divided by each image's largest depth; zero (no hit) stays zero."""
    scale = depth.flatten(1).amax(dim=1).clamp(min=1e-6).view(-1, 1, 1, 1)
    return torch.clamp(depth, min=0.0) / scale


def spatial_gradients(x: torch.Tensor) -> torch.Tensor:
    """Forward differences ``x[.., y, x+1] - x[.., y, x]`` and ``x[.., y+1, x] - x[.., y, x]``.

    (N, C, H, W) -> (N, 2C, H, W): x-gradients then y-gradients, zero in the last column/row.
    """
    dx = torch.zeros_like(x)
    dy = torch.zeros_like(x)
    dx[..., :, :-1] = x[..., :, 1:] - x[..., :, :-1]
    dy[..., :-1, :] = x[..., 1:, :] - x[..., :-1, :]
    return torch.cat([dx, dy], dim=1)


def guide_features(buffers: dict[str, torch.Tensor]) -> torch.Tensor:
    """The auxiliary features every network sees: albedo (3), normal (3), normalised depth (1).

    Albedo clipped to [0, 1], normals to [-1, 1]; returns (N, 7, H, W).
    """
    return torch.cat([torch.clamp(buffers["albedo"], 0.0, 1.0), torch.clamp(buffers["normal"], -1.0, 1.0),
                      normalized_depth(buffers["depth"])], dim=1)


def irradiance_inputs(buffers: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Demodulated colour and its log-space network input.

    Returns ``(irradiance (N, 3, H, W) linear, inputs (N, 4, H, W))`` where ``inputs`` holds
    ``log(1 + irradiance)`` and its :func:`log_noise_level`.
    """
    irradiance = demodulate(buffers["color"], buffers["albedo"])
    noise = log_noise_level(irradiance, demodulated_variance(buffers["variance"], buffers["albedo"]))
    return irradiance, torch.cat([log_radiance(irradiance), noise], dim=1)
