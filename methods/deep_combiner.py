"""Deep combiner, single buffer (Back et al. 2020, "Deep combiner for independent and correlated
pixel estimates", Sec. 3-4.2), scaled to a 2-core CPU and trained by us on our procedural scenes
(no published weights can be downloaded here). Weights: ``methods/weights/deep_combiner.pt``,
training record ``deep_combiner.json``.

It post-processes one base denoiser: per pixel c, a network predicts the weights of a 15×15
window and Eq. 8 combines the independent estimate y (the noisy render) with the correlated
estimate z (the base's output on the same image),
``β_c = z_c + Σ_{i∈Ω'_c} w_i (y_i − z_i) / W_c`` (:func:`mcbench.nn.combination.combine_single`;
the weights are a softmax, so positive with W_c = 1). The combination works on linear radiance;
the network sees log-compressed inputs. One network serves every base in
``METHOD.learned.correlated_bases`` (the paper trains one network for all its correlated inputs).

Network inputs (24 channels, :func:`mcbench.nn.combination.image_inputs`): log(1+y), log(1+z),
log(1+y) − log(1+z), y's log-space noise level, albedo, normal, normalised depth, and the
standard deviations of albedo, normal and depth (depth's over the image's largest depth),
clipped to [0, 1] -- the paper's y, z and KPCN features, with variances as standard deviations.

Output: the Eq. 8 estimate as it is during training; in eval mode (validation, inference)
clamped to ≥ 0 -- radiance is non-negative, and for a non-negative truth the clamp never
increases a pixel's error (the kernel functions themselves never clamp, so Eq. 10 holds for them).

Scaling against the published architecture (what and why):

=====================  ===========================  ==================================
                       Back et al. 2020             ours
=====================  ===========================  ==================================
conv layers            6 × 5×5, 100 channels        5 × 3×3 (two dilated by 2) + 1×1,
                       (receptive field 25×25)      48 channels (receptive field 15×15)
window                 15×15                        15×15
weights                positive, normalised by W_c  softmax over the window (W_c = 1)
loss                   relMSE                       relMSE (Eq. 9)
parameters             over 1M (our count)          104,577
training data          their rendered scenes        our procedural scenes, correlated
                                                    inputs from nfor, kpcn and oidn
=====================  ===========================  ==================================

Training: 2000 steps of batch 8, 48² patches, relMSE.
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace

from mcbench.contracts.method import LearnedSpec, MethodSpec

@cache
def network_classes() -> SimpleNamespace:
    """The torch modules of the deep combiner, defined on first call so that importing this
    module does not import torch (the DAG imports it to read METHOD and check params)."""
    import torch
    from torch import nn

    from mcbench.nn.combination import IMAGE_INPUT_CHANNELS, combination_weights, combine_single, image_inputs, \
        logit_network

    class DeepCombinerNetwork(nn.Module):
        """batch (dict of (N, C, H, W): color, variance, albedo, normal, depth and METHOD.learned.training_keys)
        -> combined radiance (N, 3, H, W)."""

        def __init__(self, channels: int = 48, layers: int = 6, dilated_layers: int = 2, window: int = 15):
            super().__init__()
            self.window = window
            self.body = logit_network(IMAGE_INPUT_CHANNELS, channels=channels, layers=layers,
                                      dilated_layers=dilated_layers, out_channels=window * window)

        def forward(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
            weights = combination_weights(self.body(image_inputs(batch)), self.window)
            combined = combine_single(batch["color"], batch["correlated"], weights)
            return combined if self.training else torch.clamp(combined, min=0.0)

    return SimpleNamespace(DeepCombinerNetwork=DeepCombinerNetwork)


def build_network(**arch):
    """A ``torch.nn.Module`` deep combiner of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().DeepCombinerNetwork(**arch)


def combine(buffers, inputs, *, weights_file):
    """The deep combiner on the full image and on each half buffer; ``inputs`` is exactly one
    base's :class:`mcbench.io.buffers.Denoised`. Each image uses only its own noisy samples and the
    base's result on that image (A never sees B's samples)."""
    from mcbench.nn.inference import combine_with_network

    return combine_with_network(METHOD, buffers, inputs, weights_file)


METHOD = MethodSpec(
    kind="combiner", label="Deep combiner† (ours, scaled, trained on our scenes)", run=combine, inputs=1,
    learned=LearnedSpec(
        network={"channels": 48, "layers": 6, "dilated_layers": 2, "window": 15},
        training={"steps": 2000, "batch_size": 8, "patch": 48, "learning_rate": 5e-4, "loss": "relmse"},
        build_network=build_network,
        # tensors forward() needs beyond color, variance, albedo, normal, depth: name -> channels
        training_keys={"correlated": 3, "albedo_variance": 3, "normal_variance": 3, "depth_variance": 1},
        # the bases whose outputs the network is trained on as z (one network for all of them)
        correlated_bases=("nfor", "kpcn", "oidn")))
