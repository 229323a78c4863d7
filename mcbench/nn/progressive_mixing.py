"""The mixing network h_NN of progressive denoising (Firmino et al. 2022, Sec. 4.3) in torch: its
inputs, the swap augmentation, f_act and the network itself (``methods/progressive.py`` builds it
through a cached ``network_classes()``; the NumPy reference of every formula is :mod:`mcbench.filters.sure`).

Inputs (Sec. 4.3), per pixel, (N, 18, H, W): ``log(1 + ·)`` of the MC render x (HDR) and of the
denoised y (DEN), and ``arctan(·)`` of VAR = σ² (the variance of x's mean), SURE (Eq. 1), the
divergence term ``σ² f′`` and ``(y − x)²`` -- in the order (HDR, DEN, VAR, SURE, σ²f′, (y−x)²),
3 channels each. The swap augmentation exchanges HDR with DEN and VAR with SURE (the pairs
(image, its error estimate)) and leaves the other two, which are symmetric in x and y; the mix is
then ``z = y + α (x − y)``, so the network's α is trained on both α and 1 − α (:func:`swapped`).

Without SURE (the ablation of Table 4, ``sure_input=False``): the SURE and σ²f′ channels are zero
(the swap still exchanges VAR with the zero SURE slot, so the network can tell which image it mixes
towards); no divergence is needed.

Output: three values (x1, x2, x3) per pixel and channel (9 channels) through f_act (Eq. 19),
clipped to [0, 1] (:func:`mixing_alpha`); without f_act (ablation) three values used as α
directly, clipped the same way. The last layer is initialised so that α ≈ 0.5 at the start
(biases x1 = 0.5, x2 = 0, x3 = 1 and weights scaled by 0.1; α directly: bias 0.5): with
x3 ≤ ε for half the pixels, as a zero-mean initialisation gives, α would start clipped with zero
gradient there.
"""

from __future__ import annotations

import torch
from torch import nn

from mcbench.nn.features import log_radiance

FACT_EPS = 1e-6          # Eq. 19
INPUT_CHANNELS = 18
PAIRS = ((0, 1), (2, 3))  # input blocks exchanged by the swap: (HDR, DEN), (VAR, SURE)


def sure_maps(x: torch.Tensor, y: torch.Tensor, variance: torch.Tensor, divergence: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """``(SURE, (y − x)²)`` per pixel and channel (Eq. 1, :func:`mcbench.filters.sure.sure_terms`)."""
    residual_sq = (y - x) ** 2
    return residual_sq + 2.0 * divergence - torch.clamp(variance, min=0.0), residual_sq


def network_inputs(x: torch.Tensor, y: torch.Tensor, variance: torch.Tensor, divergence: torch.Tensor, *,
                   swap: torch.Tensor | None = None, sure_input: bool = True) -> torch.Tensor:
    """(N, 18, H, W) inputs of h_NN from (N, 3, H, W) x, y, σ², σ²f′ (module docstring); ``swap``
    (N, 1, 1, 1) of 0/1 exchanges (HDR, VAR) with (DEN, SURE) per item."""
    variance = torch.clamp(variance, min=0.0)
    sure, residual_sq = sure_maps(x, y, variance, divergence)
    if not sure_input:
        sure, divergence = torch.zeros_like(sure), torch.zeros_like(divergence)
    blocks = [log_radiance(x), log_radiance(y), torch.atan(variance), torch.atan(sure),
              torch.atan(divergence), torch.atan(residual_sq)]
    if swap is not None:
        blocks = swapped(blocks, swap)
    return torch.cat(blocks, dim=1)


def swapped(blocks: list[torch.Tensor], swap: torch.Tensor) -> list[torch.Tensor]:
    """``blocks`` with each pair of :data:`PAIRS` exchanged where ``swap`` (N, 1, 1, 1) is 1."""
    blocks = list(blocks)
    on = swap.to(blocks[0].dtype)
    for i, j in PAIRS:
        blocks[i], blocks[j] = (on * blocks[j] + (1 - on) * blocks[i], on * blocks[i] + (1 - on) * blocks[j])
    return blocks


def f_act(x1: torch.Tensor, x2: torch.Tensor, x3: torch.Tensor, eps: float = FACT_EPS) -> torch.Tensor:
    """Eq. 19: ``(x1 − x2) / max(x3, ε)``."""
    return (x1 - x2) / torch.clamp(x3, min=eps)


def mixing_alpha(outputs: torch.Tensor, *, use_f_act: bool = True) -> torch.Tensor:
    """α (N, 3, H, W) in [0, 1] from the last layer's (N, 9, H, W) (x1, x2, x3 blocks) or, without
    f_act, (N, 3, H, W) outputs."""
    if use_f_act:
        x1, x2, x3 = torch.split(outputs, 3, dim=1)
        return torch.clamp(f_act(x1, x2, x3), 0.0, 1.0)
    return torch.clamp(outputs, 0.0, 1.0)


class MixingNetwork(nn.Module):
    """h_NN (Fig. 6): a ``first_kernel``² convolution, two residual blocks of two 3×3 convolutions,
    a final 3×3 convolution; ReLU after all but the last; 'same' padding.

    ``forward(batch)``: ``batch`` holds (N, C, H, W) ``color`` (x), ``variance`` (σ²),
    ``correlated`` (y, the base's result), ``divergence`` (σ²f′, Eq. 2) and optionally ``swap``
    (N, 1, 1, 1); returns z (N, 3, H, W) = a + α (b − a) with (a, b) = (x, y), or (y, x) where
    swapped. :meth:`alpha` returns α for (x, y).
    """

    def __init__(self, channels: int = 48, first_kernel: int = 5, sure_input: bool = True, f_act: bool = True):
        super().__init__()
        self.sure_input, self.use_f_act = bool(sure_input), bool(f_act)
        self.conv_in = nn.Conv2d(INPUT_CHANNELS, channels, first_kernel, padding=first_kernel // 2)
        self.blocks = nn.ModuleList(
            nn.ModuleList([nn.Conv2d(channels, channels, 3, padding=1), nn.Conv2d(channels, channels, 3, padding=1)])
            for _ in range(2))
        outputs = 9 if self.use_f_act else 3
        self.conv_out = nn.Conv2d(channels, outputs, 3, padding=1)
        with torch.no_grad():
            self.conv_out.weight.mul_(0.1)
            bias = [0.5] * 3 + [0.0] * 3 + [1.0] * 3 if self.use_f_act else [0.5] * 3
            self.conv_out.bias.copy_(torch.tensor(bias))

    def raw_alpha(self, inputs: torch.Tensor) -> torch.Tensor:
        h = torch.relu(self.conv_in(inputs))
        for first, second in self.blocks:
            h = torch.relu(second(torch.relu(first(h))) + h)
        return mixing_alpha(self.conv_out(h), use_f_act=self.use_f_act)

    def alpha(self, batch: dict[str, torch.Tensor], swap: torch.Tensor | None = None) -> torch.Tensor:
        """α (N, 3, H, W) in [0, 1]: the weight of the second image of the (possibly swapped) pair."""
        inputs = network_inputs(batch["color"], batch["correlated"], batch["variance"], batch["divergence"],
                                swap=swap, sure_input=self.sure_input)
        return self.raw_alpha(inputs)

    def forward(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        swap = batch.get("swap")
        x, y = batch["color"], batch["correlated"]
        alpha = self.alpha(batch, swap)
        if swap is None:
            return x + alpha * (y - x)
        on = swap.to(x.dtype)
        a, b = on * y + (1 - on) * x, on * x + (1 - on) * y
        return a + alpha * (b - a)


def swap_flags(batch_size: int, rng) -> torch.Tensor:
    """(N, 1, 1, 1) float32 of 0/1, each item swapped with probability 1/2, from a NumPy
    Generator (the training loop seeds it per step, so a resumed run draws the same flags)."""
    return torch.from_numpy(rng.integers(0, 2, size=(batch_size, 1, 1, 1)).astype("float32"))
