"""Deep combiner, multi-buffer (Back et al. 2020, Sec. 4.4, Eq. 14), scaled to a 2-core CPU and
trained by us on our procedural scenes. Weights: ``methods/weights/deep_combiner_mb.pt``,
training record ``deep_combiner_mb.json``.

Like the single-buffer deep combiner (``methods/deep_combiner.py``, which documents the inputs
and the scaling), but the kernel combines B sub-buffers: y_{·,b}, the means of disjoint sample
subsets of the image, and z_{·,b}, the base's kernel (computed from all of the image's samples)
applied to each of them (Back et al. Sec. 5, "we compute the denoising kernel using all the
samples first, then share this kernel among all B buffers"):
``β_c = Σ_b [W_{c,b} z_{c,b} + Σ_{i∈Ω'_c} w_{i,b} (y_{i,b} − z_{i,b})] / W_c``
(:func:`mcbench.nn.combination.combine_multi`), with one softmax over all B·225 weights of a
pixel. An outlier in one sub-buffer can be down-weighted even at the centre pixel, which the
single-buffer kernel cannot do (its w_c multiplies the whole y_c).

Departure: B = 2 sub-buffers, not the paper's B = 4 bins. Every image we combine has exactly two
disjoint sample subsets of its own (:data:`mcbench.io.buffers.SUB_BUFFERS`): the full image has the
half buffers A and B, A has bins 0 and 1, B has bins 2 and 3. So A's result uses only A's samples
(as the ensemble's dual-buffer estimate needs) and one network with a fixed 2×225 output serves
the full image and the halves. Renders without bins (spp not a multiple of 4) and bases without
sub-buffer results (only ``kpcn`` exposes its kernel) are refused with an error naming the file.

Network inputs (38 channels): the single-buffer combiner's 24 image-level channels
(:func:`mcbench.nn.combination.image_inputs`) plus, per sub-buffer, log(1+y_b), log(1+z_b) and
y_b's log-space noise level (:func:`mcbench.nn.combination.sub_buffer_inputs`). Network: the same
five 3×3 layers of 48 channels (two dilated) and a 1×1 layer giving 2×225 logits; 121,650
parameters.

Training: 1100 steps of batch 8, 48² patches, relMSE (a step does twice the combination work of
the single-buffer combiner's).
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace

from mcbench.contracts.method import LearnedSpec, MethodSpec

SUB_BUFFERS = 2


@cache
def network_classes() -> SimpleNamespace:
    """The torch modules of the multi-buffer deep combiner, defined on first call so that
    importing this module does not import torch."""
    import torch
    from torch import nn

    from mcbench.nn.combination import IMAGE_INPUT_CHANNELS, SUB_BUFFER_INPUT_CHANNELS, combination_weights, \
        combine_multi, image_inputs, logit_network, split_sub_buffers, sub_buffer_inputs

    class MultiBufferCombinerNetwork(nn.Module):
        """batch (dict of (N, C, H, W): color, variance, albedo, normal, depth and METHOD.learned.training_keys)
        -> combined radiance (N, 3, H, W)."""

        def __init__(self, channels: int = 48, layers: int = 6, dilated_layers: int = 2, window: int = 15):
            super().__init__()
            self.window = window
            self.body = logit_network(IMAGE_INPUT_CHANNELS + SUB_BUFFERS * SUB_BUFFER_INPUT_CHANNELS,
                                      channels=channels, layers=layers, dilated_layers=dilated_layers,
                                      out_channels=SUB_BUFFERS * window * window)

        def forward(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
            inputs = torch.cat([image_inputs(batch), sub_buffer_inputs(batch, SUB_BUFFERS)], dim=1)
            weights = combination_weights(self.body(inputs), self.window, bins=SUB_BUFFERS)
            combined = combine_multi(split_sub_buffers(batch["color_sub"], SUB_BUFFERS),
                                     split_sub_buffers(batch["correlated_sub"], SUB_BUFFERS), weights)
            return combined if self.training else torch.clamp(combined, min=0.0)

    return SimpleNamespace(MultiBufferCombinerNetwork=MultiBufferCombinerNetwork)


def build_network(**arch):
    """A ``torch.nn.Module`` multi-buffer deep combiner of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().MultiBufferCombinerNetwork(**arch)


def combine(buffers, inputs, *, weights_file):
    """The multi-buffer deep combiner on the full image and on each half buffer, each from its
    own two sub-buffers and ``inputs[0]``'s results on them (exactly one base, e.g. kpcn)."""
    from mcbench.nn.inference import combine_with_network

    return combine_with_network(METHOD, buffers, inputs, weights_file)


METHOD = MethodSpec(
    kind="combiner", label="Deep combiner, multi-buffer† (ours, scaled, trained on our scenes)", run=combine,
    inputs=1,
    learned=LearnedSpec(
        network={"channels": 48, "layers": 6, "dilated_layers": 2, "window": 15},
        training={"steps": 1100, "batch_size": 8, "patch": 48, "learning_rate": 5e-4, "loss": "relmse"},
        build_network=build_network,
        # tensors forward() needs beyond color, variance, albedo, normal, depth: name -> channels
        training_keys={"correlated": 3, "albedo_variance": 3, "normal_variance": 3, "depth_variance": 1,
                       "color_sub": 3 * SUB_BUFFERS, "variance_sub": 3 * SUB_BUFFERS,
                       "correlated_sub": 3 * SUB_BUFFERS},
        # bases that provide results on sub-buffers (Denoised.sub_outputs): only a kernel method can
        correlated_bases=("kpcn",)))
