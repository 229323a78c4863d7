"""Training losses on linear HDR radiance (N, 3, H, W), each a scalar mean over the batch.

* ``l1_log`` -- mean |log(1+y) - log(1+t)|: the L1 loss of KPCN and MCGAN computed in the
  range-compressed space (Bako et al. 2017 train with L1; log(1+x) is their specular transform).
* ``smape`` -- Fan et al. 2021 Eq. 6, ε = 0.01, on HDR values.
* ``l1_log_gradient`` -- Chaitanya et al. 2017 Sec. 5.2: 0.8 × spatial L1 + 0.1 × L1 of the
  spatial gradients (both in log space; their temporal term does not apply to single frames,
  and forward differences stand in for their HFEN high-pass).
* ``relmse`` -- Zheng et al.'s metric (y-t)²/(t²+0.01), reported during validation.

:data:`LOSSES` maps the names used in a method's ``TRAINING["loss"]`` to the functions.
"""

from __future__ import annotations

import torch

from mcbench.nn.features import log_radiance, spatial_gradients


def l1_log(prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    return (log_radiance(prediction) - log_radiance(target)).abs().mean()


def smape(prediction: torch.Tensor, target: torch.Tensor, eps: float = 0.01) -> torch.Tensor:
    """Fan et al. 2021 Eq. 6: mean of |y - t| / (|y| + |t| + ε)."""
    return ((prediction - target).abs() / (prediction.abs() + target.abs() + eps)).mean()


def l1_log_gradient(prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    log_p, log_t = log_radiance(prediction), log_radiance(target)
    spatial = (log_p - log_t).abs().mean()
    gradient = (spatial_gradients(log_p) - spatial_gradients(log_t)).abs().mean()
    return 0.8 * spatial + 0.1 * gradient


def relmse(prediction: torch.Tensor, target: torch.Tensor, eps: float = 0.01) -> torch.Tensor:
    return ((prediction - target) ** 2 / (target ** 2 + eps)).mean()


LOSSES = {"l1_log": l1_log, "smape": smape, "l1_log_gradient": l1_log_gradient, "relmse": relmse}
