"""Training examples: a training scene rendered at every noisy level plus a target, cut into crops.

Renders
-------
:func:`training_example` renders each noisy spp level with exactly the conventions of the test
renders (:func:`mcbench.render.renderer.render_dict_buffers`: box filter, independent sampler,
``moment(aov(albedo, sh_normal, depth, path))``, the same pass splitting and float64 moment
sums), plus a ``target_spp`` target (:func:`render_target`: mean colour and variance of that
mean).

Seeds
-----
Every pass gets a training render seed (:func:`mcbench.render.seeds.training_render_seed`; both bit
layouts and why they are disjoint are in :mod:`mcbench.render.seeds`): base seed 7
(:data:`mcbench.render.seeds.TRAINING_BASE_SEED`), which no config may use, so no training render
shares a seed with a test render, nor with another training render. Within an example the
noisy levels, their halves and the target are mutually independent. The scalar variant is
refused (:func:`require_vector_variant`): its pixel seeds ``seed * W * H + ...`` wrap around
2**32 and cannot be kept disjoint. Even if a stream were shared, the training scenes are
different objects from the test scenes (distinct fingerprints,
:mod:`mcbench.training_data.fingerprints`), so no training image would reproduce a test
image's noise.

Crops
-----
``crops_per_image`` crops of ``crop_size`` x ``crop_size`` pixels at seeded random positions,
pairwise disjoint (:func:`crop_boxes`: rejection sampling, falling back to random cells of a
tiling). Each crop holds ``<layer>_spp<N>`` for every layer of :data:`mcbench.io.buffers.ALL_LAYERS`
(and of :data:`mcbench.io.buffers.BIN_LAYERS`, the four sample bins, for levels that are multiples
of 4) and noisy level ``N``, plus ``target`` (H, W, 3) and ``target_variance`` (H, W, 3).
``snakemake training_data`` writes them as ``results/training/example_<seed>_<k>.exr``
(:func:`mcbench.pipeline.training.write_training_example`).
"""

from __future__ import annotations

import time

import numpy as np

from mcbench import BenchError
from mcbench.render.renderer import (forget_scene, moments_to_mean_variance, render_dict_buffers,
                                     render_scene_sums)
from mcbench.render.seeds import training_render_seed
from mcbench.training_data.fingerprints import scene_fingerprint
from mcbench.training_data.generator import random_scene
from mcbench.render.variants import pick_variant

__all__ = ["CROP_SALT", "require_vector_variant", "render_target", "crop_boxes", "training_example"]

CROP_SALT = 0x0C509B0C          # mixed into the crop RNG so crop positions are their own


def require_vector_variant(variant: str = "auto") -> str:
    """Set the Mitsuba variant (:func:`mcbench.render.variants.pick_variant`) and return it; raises
    :class:`BenchError` (config key ``variant``) for scalar variants, whose pixel seeds cannot
    keep training renders disjoint from test renders."""
    variant = pick_variant(variant)
    if variant.startswith("scalar"):
        raise BenchError("config key 'variant': scalar variants cannot keep training render seeds "
                         "disjoint from the test renders' seeds; use llvm_ad_rgb or cuda_ad_rgb")
    return variant


def render_target(desc: dict, spp: int, seed_of, *, key: str, variant: str = "auto"
                  ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """High-spp target of a scene dict: float32 mean colour (H, W, 3), variance of that mean
    (H, W, 3) and the seeds used (pass ``p`` seeded with ``seed_of(p)``; ``key`` as in
    :func:`mcbench.render.renderer.render_scene_sums`)."""
    sums, seeds = render_scene_sums(desc, int(spp), seed_of, key=key, variant=variant)
    mean, variance = moments_to_mean_variance(*sums["color"], int(spp))
    return mean.astype(np.float32), variance.astype(np.float32), seeds


def crop_boxes(seed: int, width: int, height: int, crop_size: int, count: int
               ) -> list[tuple[int, int, int, int]]:
    """``count`` pairwise disjoint crops ``(x0, y0, x1, y1)`` (x1, y1 exclusive) of
    ``crop_size``² inside a ``width`` x ``height`` image, at positions drawn from ``seed``.

    Rejection sampling of uniform positions; if that stalls, random distinct cells of a tiling
    of the image (always disjoint). Raises :class:`BenchError` when the crops cannot fit.
    """
    c = int(crop_size)
    if c < 1 or c > width or c > height:
        raise BenchError(f"crop size {c} does not fit a {width}x{height} image")
    cells = (width // c) * (height // c)
    if count > cells:
        raise BenchError(f"{count} disjoint {c}x{c} crops do not fit a {width}x{height} image "
                         f"(at most {cells})")
    rng = np.random.default_rng((CROP_SALT, int(seed), width, height, c, count))
    boxes: list[tuple[int, int, int, int]] = []
    for _ in range(200 * max(count, 1)):
        if len(boxes) == count:
            return boxes
        x0, y0 = int(rng.integers(0, width - c + 1)), int(rng.integers(0, height - c + 1))
        if all(x0 + c <= bx0 or bx1 <= x0 or y0 + c <= by0 or by1 <= y0
               for bx0, by0, bx1, by1 in boxes):
            boxes.append((x0, y0, x0 + c, y0 + c))
    # Fallback: random cells of a tiling with a random offset (disjoint by construction).
    ox, oy = int(rng.integers(0, width - (width // c) * c + 1)), int(rng.integers(0, height - (height // c) * c + 1))
    chosen = rng.choice(cells, size=count, replace=False)
    columns = width // c
    return [(ox + int(k % columns) * c, oy + int(k // columns) * c,
             ox + int(k % columns) * c + c, oy + int(k // columns) * c + c) for k in chosen]


def training_example(seed: int, spp_levels, target_spp: int, resolution, crop_size: int,
                     crops_per_image: int, variant: str = "auto", features: str = "first_hit"
                     ) -> list[tuple[dict[str, np.ndarray], dict]]:
    """Render training scene ``seed`` and cut it into crops.

    ``spp_levels``: noisy spp levels (powers of two >= 2), each rendered as full + half buffers
    with every layer of :data:`mcbench.io.buffers.ALL_LAYERS` (render_buffers' conventions); ``target_spp``: spp of
    the target (mean colour ``target`` and ``target_variance``, the variance of that mean);
    ``resolution``: ``(width, height)``. Render seeds come from :func:`training_render_seed`
    (base seed 7, disjoint from all test render seeds -- see :mod:`mcbench.render.seeds`).

    Returns ``crops_per_image`` pairs ``(layers, metadata)``: layers ``<layer>_spp<N>`` for
    every layer and level plus ``target`` and ``target_variance``, each cropped to
    ``crop_size``²; metadata (strings): seed, crop index, crop box ``x0,y0,x1,y1``, spp levels,
    target spp, resolution, variant, mitsuba version, scene fingerprint, render seconds, features
    (the convention of :data:`mcbench.render.renderer.FEATURE_CONVENTIONS` the levels were rendered with).
    """
    import mitsuba as mi

    seed = int(seed)
    levels = sorted({int(s) for s in spp_levels})
    if not levels:
        raise BenchError("training_example: no spp levels given")
    for spp in levels:
        training_render_seed(seed, "noisy", spp=spp, half=0)    # validates the level
    if int(target_spp) < 2:
        raise BenchError(f"target spp must be >= 2, got {target_spp}")
    width, height = (int(x) for x in resolution)
    variant = require_vector_variant(variant)
    boxes = crop_boxes(seed, width, height, crop_size, crops_per_image)
    start = time.perf_counter()
    desc = random_scene(seed, width, height)
    fingerprint = scene_fingerprint(desc)
    key = f"training-{seed}"
    full: dict[str, np.ndarray] = {}
    try:
        for spp in levels:
            layers, _ = render_dict_buffers(
                desc, spp, lambda half, j, p, spp=spp: training_render_seed(seed, "noisy", spp, half, p, bin=j),
                key=key, variant=variant, features=features)
            for name, layer in layers.items():
                full[f"{name}_spp{spp}"] = layer
        full["target"], full["target_variance"], _ = render_target(
            desc, int(target_spp), lambda p: training_render_seed(seed, "target", pass_index=p),
            key=key, variant=variant)
    finally:
        forget_scene(key)
    seconds = time.perf_counter() - start
    for name, layer in full.items():
        if not np.all(np.isfinite(layer)):
            raise BenchError(f"training scene {seed}: layer {name} has NaN/Inf")
    out = []
    for k, (x0, y0, x1, y1) in enumerate(boxes):
        layers = {name: np.ascontiguousarray(layer[y0:y1, x0:x1]) for name, layer in full.items()}
        metadata = {"seed": str(seed), "crop": str(k), "crop_box": f"{x0},{y0},{x1},{y1}",
                    "spp_levels": ",".join(map(str, levels)), "target_spp": str(int(target_spp)),
                    "resolution": f"{width}x{height}", "variant": variant,
                    "mitsuba": mi.__version__, "fingerprint": fingerprint,
                    "seconds": f"{seconds:.3f}", "features": features}
        out.append((layers, metadata))
    return out
