"""Weight-sharing kernel prediction network (Fan et al. 2021, "Real-time Monte Carlo Denoising
with Weight Sharing Kernel Prediction Network"), an extra learned base denoiser, trained by
us on our procedural scenes. Weights: ``methods/weights/wskpn.pt``, record ``wskpn.json``.

* **ImportanceNet** (Sec. 4.1): six RepVGG blocks (Ding et al. 2021). In training each block sums
  a 1×1, a 3×3 and a 5×5 convolution, each followed by batch normalisation, and, where input and
  output widths agree, a batch-normalised identity, then applies ReLU;
  :meth:`WeightSharingKPN.fuse` folds the batch norms and re-parameterises every block into the
  single 5×5 convolution it equals (done once after loading weights, Sec. 4.1 "equivalently
  transformed"; tested). The batch norms are RepVGG's own and are needed: without them the four
  summed branches let the activations grow from block to block until the fusion softmax and the
  importance tanh saturated with zero gradients. The sixth block is linear
  (no ReLU): it outputs M importance maps and M fusion logits.
* **Kernel construction** (Sec. 4.2, Eq. 3-4): kernel of size k_i built from importance map i by
  unfold + softmax, here computed exactly as a ratio of two box filters
  (:func:`mcbench.nn.kernels.apply_shared_kernels`); importance bounded to ±10 by a scaled tanh.
* **Kernel fusion** (Eq. 5): kernels of sizes 3, 5, ..., 13 (k_s = 2 and the largest size of the
  paper's BMFR setting) plus a 1×1 "kernel" -- the noisy pixel itself (k_b = 1 instead of the
  paper's 3, our departure): M = 7, fused by per-pixel softmax weights α_i. The paper denoises
  1 spp, where passing a pixel through is never right; our inputs go up to 1024 spp, where it
  often is, and shared importance maps cannot otherwise make every pixel's own weight dominate
  (without it the network was worse than the noisy input at high spp).
* Filtering runs on the HDR irradiance (colour / (albedo + ε)); the albedo is multiplied back
  (Fig. 1).
* Inputs (Sec. 5.1): tone-mapped colour (irradiance, x/(1+x) then gamma 1/2.2), albedo, normal
  scaled to [0, 1], depth scaled to [0, 1] -- the paper's 10 channels -- plus one channel the
  paper lacks: the log-space noise level, because our inputs range over 2-1024 spp rather than
  the paper's fixed 1 spp (or 64 spp).
* Loss: SMAPE (Eq. 6); Adam, learning rate 1e-3 as in Sec. 5.3 (cosine-decayed).

Scaling: hidden width 32 for all blocks (the widths of the paper's Fig. 2 did not survive
extraction); no temporal accumulation (single frames); batch 8 of 64² patches instead of 64 of
128²; a few thousand steps instead of 500 epochs on a GPU.
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace
from mcbench.contracts.method import LearnedSpec, MethodSpec

INPUT_CHANNELS = 11


def network_inputs(buffers):
    """(irradiance (N, 3, H, W), ImportanceNet input (N, 11, H, W)) from a dict of (N, C, H, W) tensors."""
    import torch

    from mcbench.nn.features import demodulate, demodulated_variance, log_noise_level, normalized_depth

    irradiance = demodulate(buffers["color"], buffers["albedo"])
    tone_mapped = (irradiance / (1.0 + irradiance)) ** (1.0 / 2.2)
    noise = log_noise_level(irradiance, demodulated_variance(buffers["variance"], buffers["albedo"]))
    inputs = torch.cat([tone_mapped, torch.clamp(buffers["albedo"], 0.0, 1.0),
                        0.5 * (torch.clamp(buffers["normal"], -1.0, 1.0) + 1.0),
                        normalized_depth(buffers["depth"]), noise], dim=1)
    return irradiance, inputs


@cache
def network_classes() -> SimpleNamespace:
    """The torch modules of WSKPN (RepVGGBlock, WeightSharingKPN), defined on first call so that
    importing this module does not import torch."""
    import torch
    import torch.nn.functional as F
    from torch import nn

    from mcbench.nn.features import remodulate
    from mcbench.nn.kernels import apply_shared_kernels, bound_importance

    class RepVGGBlock(nn.Module):
        """RepVGG block (Ding et al. 2021): Σ of 1×1, 3×3 and 5×5 convolution + batch-norm branches
        and, when widths agree, a batch-norm identity branch; then ReLU (optional).

        :meth:`fuse` folds the (eval-mode) batch norms into the convolutions and sums the branches
        into one 5×5 convolution with bias, exactly.
        """

        def __init__(self, in_channels: int, out_channels: int, activation: bool = True):
            super().__init__()
            self.branches = nn.ModuleList(
                nn.Sequential(nn.Conv2d(in_channels, out_channels, k, padding=k // 2, bias=False),
                              nn.BatchNorm2d(out_channels)) for k in (1, 3, 5))
            self.identity = nn.BatchNorm2d(out_channels) if in_channels == out_channels else None
            self.activation = activation
            self.fused = None       # the single 5×5 nn.Conv2d after fuse()

        def forward(self, x):
            if self.fused is not None:
                y = self.fused(x)
            else:
                y = sum(branch(x) for branch in self.branches)
                if self.identity is not None:
                    y = y + self.identity(x)
            return F.relu(y) if self.activation else y

        @staticmethod
        def _fold(weight, norm):
            """Eval-mode ``norm(conv(x))`` as one convolution: scale the weight, shift the bias."""
            scale = norm.weight.detach() / torch.sqrt(norm.running_var + norm.eps)
            return weight * scale.view(-1, 1, 1, 1), norm.bias.detach() - norm.running_mean * scale

        def fused_parameters(self):
            """Weight (out, in, 5, 5) and bias (out,) of the single 5×5 convolution equal to the
            eval-mode block before its activation."""
            out_channels = self.branches[0][1].num_features
            in_channels = self.branches[0][0].in_channels
            weight = torch.zeros(out_channels, in_channels, 5, 5)
            bias = torch.zeros(out_channels)
            for conv, norm in self.branches:
                pad = (5 - conv.kernel_size[0]) // 2
                w, b = self._fold(F.pad(conv.weight.detach(), (pad, pad, pad, pad)), norm)
                weight += w
                bias += b
            if self.identity is not None:
                eye = torch.zeros(out_channels, in_channels, 5, 5)
                eye[torch.arange(out_channels), torch.arange(out_channels), 2, 2] = 1.0
                w, b = self._fold(eye, self.identity)
                weight += w
                bias += b
            return weight, bias

        def fuse(self) -> None:
            weight, bias = self.fused_parameters()
            conv = nn.Conv2d(weight.shape[1], weight.shape[0], 5, padding=2)
            conv.weight.data.copy_(weight)
            conv.bias.data.copy_(bias)
            self.fused = conv

    class WeightSharingKPN(nn.Module):
        def __init__(self, channels: int = 32, blocks: int = 6, kernel_sizes=(1, 3, 5, 7, 9, 11, 13)):
            super().__init__()
            self.kernel_sizes = [int(k) for k in kernel_sizes]
            m = len(self.kernel_sizes)
            widths = [INPUT_CHANNELS] + [channels] * (blocks - 1)
            layers = [RepVGGBlock(widths[i], widths[i + 1]) for i in range(blocks - 1)]
            layers.append(RepVGGBlock(widths[-1], 2 * m, activation=False))
            self.importance_net = nn.Sequential(*layers)

        def fuse(self) -> None:
            """Re-parameterise every RepVGG block into one 5×5 convolution (inference form)."""
            for block in self.importance_net:
                block.fuse()

        def forward(self, buffers):
            irradiance, inputs = network_inputs(buffers)
            out = self.importance_net(inputs)
            m = len(self.kernel_sizes)
            importance = bound_importance(out[:, :m])
            alpha = torch.softmax(out[:, m:], dim=1)                     # Eq. 5 fusion weights
            fused = sum(alpha[:, i:i + 1] * apply_shared_kernels(irradiance, importance[:, i:i + 1], k)
                        for i, k in enumerate(self.kernel_sizes))
            return remodulate(fused, buffers["albedo"])

    return SimpleNamespace(RepVGGBlock=RepVGGBlock, WeightSharingKPN=WeightSharingKPN)


def build_network(**arch):
    """WSKPN (a ``torch.nn.Module``) of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().WeightSharingKPN(**arch)


def denoise(buffers, *, weights_file):
    """WSKPN on the full buffer and on each half buffer."""
    from mcbench.nn.inference import denoise_with_network

    return denoise_with_network(METHOD, buffers, weights_file)


METHOD = MethodSpec(
    kind="denoiser", label="WSKPN† (Fan et al. 2021; ours, trained on our scenes)", run=denoise,
    learned=LearnedSpec(
        network={"channels": 32, "blocks": 6, "kernel_sizes": [1, 3, 5, 7, 9, 11, 13]}, build_network=build_network,
        # 5000 steps: validation SMAPE gains little after step 5000 of a longer training, and fewer
        # steps keep a retraining (e.g. with new training scenes) short
        training={"steps": 5000, "batch_size": 8, "patch": 64, "learning_rate": 1e-3, "loss": "smape"}))
