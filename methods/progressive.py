"""Progressive denoising (Firmino et al. 2022, "Progressive denoising of Monte Carlo rendered
images"), scaled to a 2-core CPU and trained by us on our procedural scenes: a per-pixel mix
``z = x + α′ (y − x)`` of the noisy render x and one input's denoised y (Eq. 11), with α from a
small CNN h_NN that sees both images and their error estimates (the variance of x, SURE of y) and
α′ its t-test-bounded value (Eq. 12-18), so z converges to the truth as spp grows whatever y's
bias. Weights: ``methods/weights/progressive.pt``, training record ``progressive.json``.

Per image (full, A, B), each from its own samples and the input's result on that image (A never
sees B's samples, as the deep combiner): x, σ² (the render's variance of the mean), y;

1. the divergence term σ²f′ of SURE by Eq. 2 (:func:`mcbench.filters.sure.mc_divergence`): the base
   denoiser named by ``divergence`` re-run K times on x + ε b_k, b_k ~ N(0, diag σ²), ε = 1e-4
   (the paper's value), K = ``iterations`` (default 1; the paper: 1 or 4), plus once on x itself
   (F(x) recomputed in this process, so the difference sees only the perturbation);
2. SURE = (y − x)² + 2σ²f′ − σ² (Eq. 1) and the network's 18 inputs
   (:mod:`mcbench.nn.progressive_mixing`), α = clip(f_act(x1, x2, x3), 0, 1) (Eq. 19);
3. α′ = (1 − Φ(2(|t| − 4.2))) α (Eq. 18, :func:`mcbench.filters.sure.t_test`), z = x + α′(y − x).

**The divergence needs F on an arbitrary image.** A combiner receives only its input's three
images, so ``divergence`` names the single-image denoiser to re-run (:func:`methods.single_image_function`:
a method module's ``denoise_image(ImageBuffers)``, or a learned denoiser's network with the weights
beside PD's own), only the colour perturbed (variance and features as rendered). Supported: every
denoiser whose declaration makes it single-image (``MethodSpec.single_image``; the config check
names them), each call costing what one image of the base costs; K + 1 calls per image, 3 images
per case. NFOR and RDFC have no single-image function (they cross-filter the two half buffers),
nor have combiners. For an input that is not itself one of
these -- an ensemble, a deep combiner -- we do not re-run it (the exact divergence of an ensemble
would re-run every member K times on perturbed full, A and B images and then the ensemble's
weights, roughly (K + 1)× the ensemble's whole cost): ``divergence`` may name a member as a
*proxy* (e.g. ``oidn`` for an ensemble containing OIDN: its σ²f′ stands in for the ensemble's), or
``none``: σ²f′ = 0, SURE = (y − x)² − σ², biased low by 2σ²E[f′] (which the t-test does not
need: it uses only x, y, σ² and α). Default ``none`` -- a combiner cannot know which method made
its input, so the config says it (``params: {divergence: oidn}`` for PD over OIDN).

Config parameters (the ablations of Table 4 and the safeguard's parts):

* ``divergence`` -- see above;
* ``sure_input`` (default true) -- false: the network without the SURE and σ²f′ inputs (zeros),
  no re-run; needs weights trained so (``progressive_no_sure.pt``, see "Ablation weights");
* ``f_act`` (default true) -- false: the network outputs α directly (``progressive_no_fact.pt``);
* ``t_test`` (default true) -- false: α′ = α (the same weights);
* ``network`` (default true) -- false: α = 1 before the t-test, i.e. the base's result bounded by
  the t-test alone (no weights needed; a consistent post-process of any denoiser);
* ``iterations`` -- K of Eq. 2; ``seed`` -- the seed of the b_k (per image ``[seed, image]``).

Extras written with the result: ``alpha``, ``alpha_a``, ``alpha_b`` (α′ per image).

Scaling against the paper (what and why):

=====================  =================================  ====================================
                       Firmino et al. 2022                ours
=====================  =================================  ====================================
h_NN                   5×5 conv, 2 residual blocks of     the same (48 channels, 108,681
                       2 3×3 convs, final conv; 48 ch;     parameters; final conv 3×3)
                       ReLU; 'same' padding
inputs                 log(1+x) HDR, DEN; arctan VAR,     the same (18 channels)
                       SURE, σ²f′, (y−x)²
output                 f_act (Eq. 19), 9 channels          the same, α clipped to [0, 1]
swap augmentation      HDR,VAR ↔ DEN,SURE, random         the same, probability 1/2 per item
loss                   SMAPE                              SMAPE (ε = 0.01, mcbench.nn.losses)
optimiser              batch 12, One Cycle, max lr 2e-5,  batch 8 of 48² patches, Adam, cosine
                       2500 epochs, ~10 h on an RTX 3090  from 1e-3, training["steps"] steps on
                                                          2 CPU threads (minutes)
training data          1348 crops 128², 2-4096 spp,       our procedural scenes' 64² crops at
                       refs 32k-131k spp                  4-1024 spp (+ halves), 4096-spp targets
base denoiser          OIDN (pre-trained) / their U-Nets  OIDN 2.x (pyoidn, albedo + normal)
SURE                   K = 4 (their tool), ε = 1e-4       K = 1 (training data and default), ε = 1e-4
t-test                 11×11, a = 2, c = 4.2              the same (choices: mcbench.filters.sure)
=====================  =================================  ====================================

Ablation weights: ``sure_input=false`` and ``f_act=false`` are other networks (Table 4 retrains
for each): ``methods/weights/progressive_no_sure.pt`` / ``progressive_no_fact.pt``
(:func:`ablation_weights_path`), trained on the same data with the same settings by the shared
loop; without them the method stops with an error naming the file.

Training (one command per network, each resumes from its checkpoint): ``python -m
mcbench.pipeline.training progressive full`` (``no_sure``, ``no_fact``;
:func:`mcbench.pipeline.training.train_progressive_variant`) on the crops that
``snakemake --cores 2 --configfile workflow/configs/progressive.yaml training_data`` renders: 24
object scenes (seeds 0-23; 7, 15, 23 validate) × 4 crops of 64², OIDN's results and divergence maps
on them (``training.combiners: {count: 24, fibre_count: 0, crops: 4}``; no fibre scenes), 1500
steps each. The records (``methods/weights/progressive*.json``) hold each run's validation SMAPE
and seconds; ``docs/measurements.md`` lists them.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from types import SimpleNamespace
from typing import Literal

import numpy as np

from mcbench import BenchError
from mcbench.filters import sure as sure_module
from mcbench.filters.sure import divergence_map
from mcbench.io.buffers import BUFFER_SUFFIXES, IMAGE_INDEX, Denoised, RenderBuffers
from mcbench.contracts.method import LearnedSpec, MethodSpec, SingleImageDenoiser
from methods import load_method, method_spec, single_image_function

# The base whose single-image function re-runs for the divergence, or none (module docstring).
DivergenceBase = Literal["none"] | SingleImageDenoiser


@cache
def network_classes() -> SimpleNamespace:
    """The torch module of h_NN, imported on first use (importing this module imports no torch)."""
    from mcbench.nn.progressive_mixing import MixingNetwork

    return SimpleNamespace(MixingNetwork=MixingNetwork)


def build_network(**arch):
    """A ``torch.nn.Module`` h_NN of architecture ``arch`` (keys of METHOD.learned.network)."""
    return network_classes().MixingNetwork(**arch)


def augment_batch(buffers: dict, rng) -> dict:
    """The swap augmentation (Sec. 4.3): a ``swap`` flag per item, 1 with probability 1/2, drawn
    from ``rng`` (the training loop's per-step generator)."""
    from mcbench.nn.progressive_mixing import swap_flags

    return {**buffers, "swap": swap_flags(len(buffers["color"]), rng)}


# --------------------------------------------------------------------------- combination

def _variant_suffix(*, sure_input: bool, f_act: bool) -> str:
    return "" if sure_input and f_act else "_no_sure" if f_act else "_no_fact" if sure_input else "_no_sure_no_fact"


def ablation_weights_path(weights_file: str | Path, *, sure_input: bool, f_act: bool) -> Path:
    """The weights of the network variant beside the full model's ``weights_file`` (``progressive.pt``)."""
    path = Path(weights_file)
    return path.with_name(path.stem + _variant_suffix(sure_input=sure_input, f_act=f_act) + path.suffix)


def weights_read(params: dict) -> tuple[str, ...]:
    """The weights files :func:`combine` reads with ``params``: its network variant's (none
    without the network) and a learned divergence base's (re-run only with the SURE input)."""
    network, sure_input = params.get("network", True), params.get("sure_input", True)
    if not network:
        return ()
    own = (__name__.rsplit(".", 1)[-1] + _variant_suffix(sure_input=sure_input, f_act=params.get("f_act", True)),)
    divergence = params.get("divergence", "none")
    if sure_input and divergence != "none" and method_spec(load_method(divergence)).learned is not None:
        return (*own, divergence)
    return own


def load_variant(weights_file: str | Path, *, sure_input: bool, f_act: bool):
    """The trained h_NN of a variant (beside ``weights_file``; an error naming a missing file)."""
    from mcbench.nn.inference import load_network

    path = ablation_weights_path(weights_file, sure_input=sure_input, f_act=f_act)
    network = load_network(METHOD, path)
    if bool(network.sure_input) != sure_input or bool(network.use_f_act) != f_act:
        raise BenchError(f"{path}: weights of another variant (sure_input={network.sure_input}, "
                         f"f_act={network.use_f_act})")
    return network


def combine_images(buffers: RenderBuffers, inputs: list[Denoised], *, net=None, divergence: str = "none",
                   t_test: bool = True, iterations: int = sure_module.ITERATIONS, seed: int = 0,
                   weights_dir: str | Path | None = None) -> Denoised:
    """Progressive denoising of each image with network ``net`` (an h_NN module in eval mode, or
    None for α = 1) -- :func:`combine` without loading weights (tests pass a random network);
    a learned ``divergence`` base's weights come from ``weights_dir``."""
    if len(inputs) != METHOD.inputs:
        raise BenchError(f"progressive combines exactly {METHOD.inputs} input, got {len(inputs)}")
    base = inputs[0]
    needs_divergence = net is not None and net.sure_input and divergence != "none"
    denoise_image = single_image_function(divergence, weights_dir=weights_dir) if needs_divergence else None
    results, extras = {}, {}
    for which in BUFFER_SUFFIXES:
        image = buffers.image(which)
        x = np.asarray(image.color, np.float64)
        variance = np.maximum(np.asarray(image.variance, np.float64), 0.0)
        y = np.asarray(base.image(which), np.float64)
        if y.shape != x.shape:
            raise BenchError(f"{base.source}: result on image '{which}' is {y.shape}, the render "
                             f"{buffers.source} is {x.shape}")
        if net is None:
            alpha = np.ones_like(x)
        else:
            d = (divergence_map(denoise_image, image, iterations=iterations, seed=[seed, IMAGE_INDEX[which]])
                 if denoise_image is not None else np.zeros_like(x))
            alpha = network_alpha(net, x, y, variance, d)
        if t_test:
            alpha = sure_module.t_test_scale(x, y, variance, alpha)
        results[which] = sure_module.mix(x, y, alpha).astype(np.float32)
        extras["alpha" + BUFFER_SUFFIXES[which]] = alpha.astype(np.float32)
    for which, result in results.items():
        if not np.isfinite(result).all():
            raise BenchError(f"progressive: non-finite output on image '{which}' of {buffers.source}")
    return Denoised(full=results["full"], a=results["a"], b=results["b"], extras=extras)


def network_alpha(net, x: np.ndarray, y: np.ndarray, variance: np.ndarray, divergence: np.ndarray) -> np.ndarray:
    """h_NN's α (float64 (H, W, 3) in [0, 1]) for one image, deterministic float32 inference."""
    from mcbench.nn.inference import array_tensor, deterministic_inference, tensor_image

    batch = {"color": array_tensor(x), "correlated": array_tensor(y), "variance": array_tensor(variance),
             "divergence": array_tensor(np.clip(divergence, -3e38, 3e38))}
    with deterministic_inference():
        return np.asarray(tensor_image(net.alpha(batch)), np.float64)


def combine(buffers, inputs, *, divergence: DivergenceBase = "none", sure_input: bool = True, f_act: bool = True,
            t_test: bool = True, network: bool = True, iterations: int = 1, seed: int = 0, weights_file):
    """Progressive denoising of ``inputs[0]`` (one method's :class:`Denoised`) with the noisy
    render, on the full image and on each half buffer (module docstring); the networks (h_NN's
    variant, a learned divergence base) are read from the folder of ``weights_file``."""
    if iterations < 1:
        raise BenchError(f"progressive: iterations (K of Eq. 2) must be at least 1, got {iterations}")
    net = load_variant(weights_file, sure_input=sure_input, f_act=f_act) if network else None
    return combine_images(buffers, inputs, net=net, divergence=divergence, t_test=t_test,
                          iterations=iterations, seed=seed, weights_dir=Path(weights_file).parent)


# --------------------------------------------------------------------------- ablation training

VARIANTS = {"no_sure": {"sure_input": False}, "no_fact": {"f_act": False}}


def variant_module(variant: str):
    """A stand-in method module for the network variant ``variant`` (a key of :data:`VARIANTS`):
    this module's declaration with its ``network`` and ``label`` changed, named
    ``progressive_<variant>`` so that the shared training loop
    (:func:`mcbench.nn.train.train_network`) writes ``methods/weights/progressive_<variant>.{pt,json}``."""
    import dataclasses
    import types

    if variant not in VARIANTS:
        raise BenchError(f"unknown progressive variant '{variant}'; known: {', '.join(VARIANTS)}")
    module = types.ModuleType(f"methods.progressive_{variant}")
    learned = dataclasses.replace(METHOD.learned, network={**METHOD.learned.network, **VARIANTS[variant]})
    module.METHOD = dataclasses.replace(METHOD, label=f"{METHOD.label}, ablation {variant}", learned=learned)
    return module


METHOD = MethodSpec(
    kind="combiner", label="PD† progressive denoising (ours, scaled, trained on our scenes)", run=combine,
    inputs=1,
    learned=LearnedSpec(
        network={"channels": 48, "first_kernel": 5, "sure_input": True, "f_act": True},
        training={"steps": 1500, "batch_size": 8, "patch": 48, "learning_rate": 1e-3, "loss": "smape",
                  "validate_every": 500},
        build_network=build_network, augment_batch=augment_batch,
        # tensors forward() needs beyond the render's: the base's result and its σ²f′ (Eq. 2)
        training_keys={"correlated": 3, "divergence": 3},
        # trained on OIDN's results with their divergence term ("+sure": mcbench.pipeline.training
        # writes the divergence layers too, into results/training/correlated/oidn+sure/)
        correlated_bases=("oidn+sure",),
        weights_read=weights_read),
    render_layers=tuple(q + s for q in ("color", "variance", "albedo", "normal", "depth")
                        for s in BUFFER_SUFFIXES.values()))
