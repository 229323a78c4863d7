"""MCGAN, adversarial Monte Carlo denoising with conditioned auxiliary feature modulation
(#3 MCGAN in Zheng et al. 2021; Xu et al. 2019), scaled to a 2-core CPU and trained by us on
our procedural scenes. Weights: ``methods/weights/mcgan.pt``, record ``mcgan.json``.

Generator (direct prediction): the log-space demodulated colour and its noise level go through a
stack of residual blocks whose activations are modulated by the auxiliary features -- conditioned
feature modulation (CFM, Xu et al. Sec. 4.2): an encoder turns albedo, normal and depth into a
condition map, and each modulation is ``x · (1 + γ(c)) + β(c)`` with γ, β 1×1 convolutions of the
condition (the ``1 +`` is our choice, so an untrained block starts near identity). The network
outputs log-space irradiance, which is exponentiated and multiplied by the albedo. Our
generator predicts the log image as the noisy log input plus a correction (a global skip; our
choice, it keeps the network near identity at high spp where our inputs range up to 1024).

Critic: a conditional patch critic on (log radiance, albedo, normal, depth): three stride-2 4×4
convolutions with leaky ReLU and a 3×3 output, trained as a WGAN-GP critic (Gulrajani et al.
2017, λ_GP = 10; Adam 1e-4, β = (0.5, 0.9)).

Loss: L1 (in log space, see :mod:`mcbench.nn.losses`) plus ``adversarial_weight`` = 0.005 times
the adversarial term; Xu et al. combine L1 with the adversarial loss -- their paper was not
available to us, the weight 0.005 is our recollection of it, stated here as our choice.

Scaling against the published architecture: one generator on demodulated colour instead of
separate diffuse and specular generators; 6 residual blocks of width 32 (the paper's generator is
deeper and wider, with 256² patches); one critic step per generator step.
"""

from __future__ import annotations

from functools import cache
from types import SimpleNamespace
from mcbench.contracts.method import LearnedSpec, MethodSpec



@cache
def network_classes() -> SimpleNamespace:
    """The torch modules of MCGAN (FeatureModulation, ModulatedResidualBlock, Generator, Critic),
    defined on first call so that importing this module does not import torch."""
    import torch
    import torch.nn.functional as F
    from torch import nn

    from mcbench.nn.features import exp_radiance, guide_features, irradiance_inputs, log_radiance, remodulate

    class FeatureModulation(nn.Module):
        """CFM: ``x · (1 + γ(c)) + β(c)`` with γ, β 1×1 convolutions of the condition map c."""

        def __init__(self, channels: int, condition_channels: int):
            super().__init__()
            self.gamma = nn.Conv2d(condition_channels, channels, 1)
            self.beta = nn.Conv2d(condition_channels, channels, 1)

        def forward(self, x, condition):
            return x * (1.0 + self.gamma(condition)) + self.beta(condition)

    class ModulatedResidualBlock(nn.Module):
        def __init__(self, channels: int, condition_channels: int):
            super().__init__()
            self.conv1 = nn.Conv2d(channels, channels, 3, padding=1)
            self.mod1 = FeatureModulation(channels, condition_channels)
            self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)
            self.mod2 = FeatureModulation(channels, condition_channels)

        def forward(self, x, condition):
            y = F.relu(self.mod1(self.conv1(x), condition))
            return x + self.mod2(self.conv2(y), condition)

    class Generator(nn.Module):
        def __init__(self, channels: int = 32, blocks: int = 6, condition_channels: int = 32):
            super().__init__()
            self.encoder = nn.Sequential(
                nn.Conv2d(7, condition_channels, 3, padding=1), nn.ReLU(inplace=True),
                nn.Conv2d(condition_channels, condition_channels, 3, padding=1), nn.ReLU(inplace=True),
                nn.Conv2d(condition_channels, condition_channels, 3, padding=1))
            self.head = nn.Conv2d(4, channels, 3, padding=1)
            self.blocks = nn.ModuleList(ModulatedResidualBlock(channels, condition_channels) for _ in range(blocks))
            self.tail = nn.Conv2d(channels, 3, 3, padding=1)

        def forward(self, buffers):
            _, colour_inputs = irradiance_inputs(buffers)
            condition = self.encoder(guide_features(buffers))
            h = F.relu(self.head(colour_inputs))
            for block in self.blocks:
                h = block(h, condition)
            log_irradiance = colour_inputs[:, :3] + self.tail(h)
            return remodulate(exp_radiance(log_irradiance), buffers["albedo"])

    class Critic(nn.Module):
        """Conditional patch critic: (radiance, buffers) -> (N, 1, H/8, W/8) scores."""

        def __init__(self, channels: int = 32):
            super().__init__()
            c = channels
            self.body = nn.Sequential(
                nn.Conv2d(10, c, 4, stride=2, padding=1), nn.LeakyReLU(0.2),
                nn.Conv2d(c, 2 * c, 4, stride=2, padding=1), nn.LeakyReLU(0.2),
                nn.Conv2d(2 * c, 4 * c, 4, stride=2, padding=1), nn.LeakyReLU(0.2),
                nn.Conv2d(4 * c, 1, 3, padding=1))

        def forward(self, radiance, buffers):
            return self.body(torch.cat([log_radiance(radiance), guide_features(buffers)], dim=1))

    return SimpleNamespace(FeatureModulation=FeatureModulation, ModulatedResidualBlock=ModulatedResidualBlock,
                           Generator=Generator, Critic=Critic)


def build_network(**arch):
    """The generator (a ``torch.nn.Module``) of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().Generator(**arch)


def build_critic(**arch):
    """The WGAN-GP critic of architecture ``arch`` (keys of METHOD.learned.critic)."""
    return network_classes().Critic(**arch)


def denoise(buffers, *, weights_file):
    """MCGAN's generator on the full buffer and on each half buffer."""
    from mcbench.nn.inference import denoise_with_network

    return denoise_with_network(METHOD, buffers, weights_file)


METHOD = MethodSpec(
    kind="denoiser", label="#3 MCGAN† (ours, scaled, trained on our scenes)", run=denoise,
    learned=LearnedSpec(
        network={"channels": 32, "blocks": 6, "condition_channels": 32}, build_network=build_network,
        training={"steps": 5000, "batch_size": 8, "patch": 64, "learning_rate": 5e-4, "loss": "l1_log",
                  "adversarial_weight": 0.005, "gradient_penalty": 10.0, "critic_learning_rate": 1e-4},
        critic={"channels": 32}, build_critic=build_critic))
