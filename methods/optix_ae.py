"""OptiX† (our autoencoder): a stand-in for #7 the OptiX AI denoiser of Zheng et al. 2021.

OptiX's denoiser is NVIDIA's closed network (a descendant of the recurrent denoising autoencoder
of Chaitanya et al. 2017) and has no CPU build, so this is **not OptiX**: it is a U-Net
autoencoder in the style of Chaitanya et al. / OIDN, trained by us on our procedural scenes.
Every table labels it "OptiX† (our autoencoder)". Weights: ``methods/weights/optix_ae.pt``,
record ``optix_ae.json``.

Network (Chaitanya et al. Sec. 4): an encoder of 3×3 convolutions with leaky ReLU (slope 0.1) and
2×2 max pooling, a decoder with nearest-neighbour upsampling and skip connections concatenating the
encoder features of the same scale, direct prediction of the (log-space, albedo-demodulated)
colour. Inputs: log(1 + irradiance), its noise level, albedo, normal, normalised depth (Chaitanya
et al. feed colour, normal, depth and roughness; we have albedo rather than roughness). The output
is the log input plus the decoder's correction (a global skip, our choice), exponentiated and
multiplied by the albedo. Images are padded (edge replication) to a multiple of 16 and cropped back.

Loss: 0.8 × L1 + 0.1 × gradient L1 in log space (Chaitanya et al. Sec. 5.2 without the temporal
term; forward differences for their HFEN).

Scaling against Chaitanya et al.: single frames, no recurrent connections (our renders are stills);
4 pooling levels with widths 32-48-64-80 and a 96-wide bottleneck (theirs: 5-6 levels, widths 32 to
101 growing by 4/3, 7 frames per sequence).
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace
from mcbench.contracts.method import LearnedSpec, MethodSpec

INPUT_CHANNELS = 11


@cache
def network_classes() -> SimpleNamespace:
    """The torch module of the autoencoder (DenoisingAutoencoder), defined on first call so that
    importing this module does not import torch."""
    import torch
    import torch.nn.functional as F
    from torch import nn

    from mcbench.nn.features import exp_radiance, guide_features, irradiance_inputs, remodulate

    def double_conv(in_channels: int, out_channels: int) -> nn.Sequential:
        return nn.Sequential(nn.Conv2d(in_channels, out_channels, 3, padding=1), nn.LeakyReLU(0.1),
                             nn.Conv2d(out_channels, out_channels, 3, padding=1), nn.LeakyReLU(0.1))

    class DenoisingAutoencoder(nn.Module):
        def __init__(self, widths=(32, 48, 64, 80), bottleneck: int = 96):
            super().__init__()
            widths = [int(w) for w in widths]
            self.levels = len(widths)
            ins = [INPUT_CHANNELS] + widths[:-1]
            self.encoders = nn.ModuleList(double_conv(i, o) for i, o in zip(ins, widths))
            self.bottleneck = double_conv(widths[-1], bottleneck)
            ups = [bottleneck] + widths[::-1][:-1]
            self.decoders = nn.ModuleList(double_conv(u + s, s) for u, s in zip(ups, widths[::-1]))
            self.output = nn.Conv2d(widths[0], 3, 3, padding=1)

        def forward(self, buffers):
            _, colour_inputs = irradiance_inputs(buffers)
            x = torch.cat([colour_inputs, guide_features(buffers)], dim=1)
            height, width = x.shape[2:]
            multiple = 2 ** self.levels
            pad_h, pad_w = (-height) % multiple, (-width) % multiple
            if pad_h or pad_w:
                x = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")
            skips = []
            for encoder in self.encoders:
                x = encoder(x)
                skips.append(x)
                x = F.max_pool2d(x, 2)
            x = self.bottleneck(x)
            for decoder, skip in zip(self.decoders, reversed(skips)):
                x = decoder(torch.cat([F.interpolate(x, scale_factor=2, mode="nearest"), skip], dim=1))
            correction = self.output(x)[:, :, :height, :width]
            log_irradiance = colour_inputs[:, :3] + correction
            return remodulate(exp_radiance(log_irradiance), buffers["albedo"])

    return SimpleNamespace(DenoisingAutoencoder=DenoisingAutoencoder)


def build_network(**arch):
    """The autoencoder (a ``torch.nn.Module``) of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().DenoisingAutoencoder(**arch)


def denoise(buffers, *, weights_file):
    """The autoencoder on the full buffer and on each half buffer."""
    from mcbench.nn.inference import denoise_with_network

    return denoise_with_network(METHOD, buffers, weights_file)


METHOD = MethodSpec(
    kind="denoiser", label="#7 OptiX† (our autoencoder, a stand-in)", run=denoise,
    learned=LearnedSpec(network={"widths": [32, 48, 64, 80], "bottleneck": 96}, build_network=build_network,
                        training={"steps": 10000, "batch_size": 8, "patch": 64, "learning_rate": 5e-4,
                                  "loss": "l1_log_gradient"}))
