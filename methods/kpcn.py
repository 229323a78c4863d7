"""KPCN, the kernel-predicting convolutional network (#1 KPCN in Zheng et al. 2021; Bako et al.
2017), scaled to a 2-core CPU and trained by us on our procedural scenes (no published weights
can be downloaded here). Weights: ``methods/weights/kpcn.pt``, training record ``kpcn.json``.

Network (Bako et al. Sec. 4): a stack of convolutions with ReLU predicts, per pixel, the k² logits
of a k×k kernel; the softmax of the logits filters the noisy (demodulated) colour
(:func:`mcbench.nn.kernels.apply_pixel_kernels`, Eq. 5-6 of Bako et al.), then the albedo is
multiplied back.

Sub-buffer results (for the multi-buffer deep combiner, Back et al. 2020 Sec. 5): KPCN exposes
its kernel, so for renders with sample bins the kernel predicted from all of an image's samples
is also applied to each of that image's two sub-buffers (:data:`mcbench.io.buffers.SUB_BUFFERS`:
full -> A, B; A -> bins 0, 1; B -> bins 2, 3), written as the extras of
:data:`mcbench.io.buffers.SUB_OUTPUTS`. A's sub-buffer results use A's kernel, never B's samples.

Inputs (31 channels): log(1 + irradiance) (3), its x/y gradients (6), the delta-method noise
level of log irradiance (1), albedo (3), normal (3), normalised depth (1) and the x/y gradients of
albedo, normal and depth (14) -- Bako et al.'s diffuse-branch inputs with relative variance
replaced by the log-space noise level.

Scaling against the published architecture (what and why):

=====================  ===========================  ==================================
                       Bako et al. 2017             ours
=====================  ===========================  ==================================
branches               diffuse + specular networks  one network on albedo-demodulated
                                                    colour (our renders have no
                                                    diffuse/specular split)
conv layers            9 × 5×5, 100 channels        9 × 3×3, 48 channels (last 1×1)
kernel size            21×21                        13×13
loss                   L1 (per branch)              L1 on log(1+x) of the final colour
training data          600 production frames,       our 112 procedural scenes, 2-1024
                       128 spp, 1.8M patches        spp (full and half buffers)
=====================  ===========================  ==================================
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace
from mcbench.contracts.method import LearnedSpec, MethodSpec

INPUT_CHANNELS = 31


def network_inputs(buffers):
    """(irradiance (N, 3, H, W), network input (N, 31, H, W)) from a dict of (N, C, H, W) tensors."""
    import torch

    from mcbench.nn.features import guide_features, irradiance_inputs, spatial_gradients

    irradiance, colour_inputs = irradiance_inputs(buffers)
    guides = guide_features(buffers)
    inputs = torch.cat([colour_inputs[:, :3], spatial_gradients(colour_inputs[:, :3]), colour_inputs[:, 3:],
                        guides, spatial_gradients(guides)], dim=1)
    return irradiance, inputs


@cache
def network_classes() -> SimpleNamespace:
    """The torch modules of KPCN, defined on first call so that importing this module does not
    import torch (the DAG imports it to read METHOD and check params)."""
    from torch import nn

    from mcbench.nn.features import demodulate, remodulate
    from mcbench.nn.kernels import apply_pixel_kernels

    class KernelPredictingNetwork(nn.Module):
        def __init__(self, channels: int = 48, layers: int = 9, kernel_size: int = 13):
            super().__init__()
            self.kernel_size = kernel_size
            convs, width = [], INPUT_CHANNELS
            for _ in range(layers - 1):
                convs += [nn.Conv2d(width, channels, 3, padding=1), nn.ReLU(inplace=True)]
                width = channels
            convs.append(nn.Conv2d(width, kernel_size * kernel_size, 1))
            self.body = nn.Sequential(*convs)

        def forward(self, buffers, sub_colors=()):
            """The denoised colour (N, 3, H, W); with ``sub_colors`` (each (N, 3, H, W), disjoint
            sample subsets of the same image), also the same kernels applied to each of them."""
            irradiance, inputs = network_inputs(buffers)
            logits = self.body(inputs)
            albedo = buffers["albedo"]
            output = remodulate(apply_pixel_kernels(irradiance, logits, self.kernel_size), albedo)
            if not sub_colors:
                return output
            return output, [remodulate(apply_pixel_kernels(demodulate(color, albedo), logits, self.kernel_size), albedo)
                            for color in sub_colors]

    return SimpleNamespace(KernelPredictingNetwork=KernelPredictingNetwork)


def build_network(**arch):
    """A ``torch.nn.Module`` KPCN of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().KernelPredictingNetwork(**arch)


def denoise(buffers, *, weights_file):
    """KPCN on the full buffer and on each half buffer (three inferences, as Zheng et al. ran it);
    for renders with sample bins also each image's kernel applied to its two sub-buffers."""
    from mcbench.io.buffers import SUB_OUTPUTS, Denoised
    from mcbench.nn.inference import (array_tensor, denoise_with_network, deterministic_inference, image_tensors,
                                      load_network, tensor_image)

    if not buffers.has_sub_buffers():
        return denoise_with_network(METHOD, buffers, weights_file)
    network = load_network(METHOD, weights_file)
    images, extras = {}, {}
    with deterministic_inference():
        for which in ("full", "a", "b"):
            subs = [array_tensor(color) for color, _ in buffers.sub_images(which)]
            output, sub_outputs = network(image_tensors(buffers.image(which)), subs)
            images[which] = tensor_image(output)
            extras.update({name: tensor_image(sub) for name, sub in zip(SUB_OUTPUTS[which], sub_outputs)})
    return Denoised(full=images["full"], a=images["a"], b=images["b"], extras=extras)


METHOD = MethodSpec(
    kind="denoiser", label="#1 KPCN† (ours, scaled, trained on our scenes)", run=denoise,
    learned=LearnedSpec(network={"channels": 48, "layers": 9, "kernel_size": 13}, build_network=build_network,
                        training={"steps": 6000, "batch_size": 8, "patch": 64, "learning_rate": 5e-4,
                                  "loss": "l1_log"}))
