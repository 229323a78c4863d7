"""The oracle study's step (Zheng et al. 2021 Sec. 5.2.7, Fig. 11): weights from ground-truth
statistics next to the dual-buffer estimate. Like every pipeline module it resolves scene and
method names (plugins); the maths is :mod:`mcbench.combine.oracle_weights`.

One test scene is rendered ``repetitions + 1`` times at ``spp`` with the oracle seeds of
:func:`mcbench.render.seeds.oracle_render_seed` (repetition r, halves A and B as every render: the
dual-buffer estimate needs them), at the harness's resolution divided by ``downscale``; the
ground truth is the harness's reference averaged over ``downscale`` x ``downscale`` blocks
(:func:`mcbench.combine.oracle_weights.block_average`). The base denoisers run on every repetition; the first
``repetitions`` feed the MSE matrices M (full-buffer outputs, Eq. 7) and M^half (half-buffer
outputs, Eq. 15, two samples per repetition), the last one is held out: the weights solved
from M and M^half and the three dual-buffer combiners run on it give the nine panels of
Fig. 11:

    a-c  M:        one-hot, unconstrained, simplex      (applied to the held-out full outputs)
    d-f  M^half:   one-hot, unconstrained, simplex
    g-i  <M> (dual buffer, the held-out render only): one_hot (prefilter "none"), ensemble
         weights="unconstrained", ensemble (the paper's method, defaults)
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from mcbench import NOISY, BenchError
from mcbench.contracts.scene import scene_spec
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.exr import check_finite, read_layers
from mcbench.io.tables import write_csv, write_text
from mcbench.analysis.oracle_tables import error_table, table_markdown, weight_maps_figure
from mcbench.combine.oracle_weights import (MseMatrixAccumulator, block_average, one_hot_weights, simplex_weights,
                                            unconstrained_weights)
from mcbench.progress import eta_seconds, progress_line
from mcbench.render.seeds import oracle_render_seed
from mcbench.combine.selection import blend

GROUND_TRUTH = {"full": "M (full buffers, Eq. 7)", "half": "M^half (half buffers, Eq. 15)"}
SOLVES = {"one_hot": (one_hot_weights, "one-hot"), "unconstrained": (unconstrained_weights, "unconstrained"),
          "simplex": (simplex_weights, "simplex")}
# the dual-buffer columns g-i: (name, combiner module, params, weights label)
DUAL_BUFFER = (("dual_one_hot", "one_hot", {"prefilter": "none"}, "one-hot"),
               ("dual_unconstrained", "ensemble", {"weights": "unconstrained"}, "unconstrained"),
               ("dual_ensemble", "ensemble", {}, "simplex (ensemble, ours)"))
PANELS = "abcdefghi"


def usable_downscale(resolution, scene_resolution, downscale: int) -> int:
    """``downscale``, or the largest smaller factor that divides the harness's resolution and
    leaves at least 11 pixels a side (1 at worst): small test configs (e.g. 16 x 16) keep an
    oracle study at their own resolution instead of refusing to plan."""
    width, height = (int(v) for v in (resolution if resolution is not None else scene_resolution))
    factor = max(int(downscale), 1)
    while factor > 1 and (width % factor or height % factor or min(width, height) // factor < 11):
        factor -= 1
    return factor


def oracle_size(resolution, scene_resolution, downscale: int) -> tuple[int, int]:
    """``(width, height)`` of the oracle renders: the harness's resolution (config ``resolution``
    or the scene's declared ``resolution``) divided by ``downscale``; BenchError naming the key otherwise."""
    width, height = (int(v) for v in (resolution if resolution is not None else scene_resolution))
    factor = int(downscale)
    if factor < 1 or width % factor or height % factor:
        raise BenchError(f"config key 'oracle.downscale': {downscale} must be >= 1 and divide the "
                         f"resolution {width}x{height}")
    if min(width, height) // factor < 11:
        raise BenchError(f"config key 'oracle.downscale': {width}x{height} / {factor} is below DSSIM's "
                         f"11 pixels a side")
    return width // factor, height // factor


def _stack(outputs: list[Denoised], which: str) -> np.ndarray:
    return np.stack([np.asarray(d.image(which), np.float64) for d in outputs])


def _combiner_weights(result: Denoised, count: int) -> np.ndarray:
    """(N, H, W, 3) weight maps a combiner applied to the full image (its ``weights_filtered_i``)."""
    return np.stack([np.asarray(result.extras[f"weights_filtered_{i}"], np.float64) for i in range(count)])


def _oracle_reference(reference_path: str, scene: str, width: int, height: int, downscale: int) -> np.ndarray:
    """The reference block-averaged to ``width`` x ``height``; refused unless it has the harness's
    resolution (``downscale`` times that)."""
    reference = read_layers(reference_path, ["color"])
    check_finite(reference_path, reference)
    reference = np.asarray(reference["color"], np.float64)
    if reference.shape[:2] != (height * downscale, width * downscale):
        raise BenchError(f"{reference_path}: reference is {reference.shape[1]}x{reference.shape[0]}, the "
                         f"harness's resolution for '{scene}' is {width * downscale}x{height * downscale}")
    return block_average(reference, downscale)


def _render_repetitions(desc, bases: list, mu: np.ndarray, *, scene: str, spp: int, repetitions: int, seed: int,
                        variant: str, features: str, label: str, started: float) -> tuple[dict, RenderBuffers, list]:
    """Render ``repetitions + 1`` times with the oracle seeds and denoise each render with every
    base (``bases``: each a function of the render): ``(accumulators, held-out render, its outputs)``, the MSE matrices of the full buffers'
    and the halves' outputs over the first ``repetitions`` renders, the last held out."""
    from mcbench.render.renderer import render_dict_buffers

    accumulators = {"full": MseMatrixAccumulator(mu, count=len(bases)),
                    "half": MseMatrixAccumulator(mu, count=len(bases))}
    for r in range(repetitions + 1):
        layers, _ = render_dict_buffers(
            desc, spp, lambda half, j, p, r=r: oracle_render_seed(r, half, bin=j, pass_index=p, base_seed=seed),
            key=f"oracle:{scene}", variant=variant, features=features)
        buffers = RenderBuffers(layers=layers, spp=spp, source=f"oracle render {r} of '{scene}'")
        outputs = [denoise(buffers) for denoise in bases]
        if r < repetitions:
            accumulators["full"].add(_stack(outputs, "full"))
            accumulators["half"].add(_stack(outputs, "a"))
            accumulators["half"].add(_stack(outputs, "b"))
        elapsed = time.perf_counter() - started
        print(progress_line(label, f"render {r + 1}/{repetitions + 1} denoised", elapsed,
                            eta_seconds(elapsed, r + 1, repetitions + 1)), flush=True)
    return accumulators, buffers, outputs


def _oracle_images(accumulators: dict, held_out: RenderBuffers, held_outputs: list,
                   denoisers: list[str], *, weights_dir: str | None) -> tuple[dict, dict, dict]:
    """``(images, weight maps, table rows)`` keyed by entry: the panels a-i (each solve of each
    ground-truth statistics, then the dual-buffer combiners on the held-out render), the held-out
    noisy render and each base's output."""
    from mcbench.pipeline.method_runs import method_function
    from mcbench.pipeline.registry import load_method

    full = _stack(held_outputs, "full")
    images, maps, rows = {}, {}, {}
    panel = iter(PANELS)
    for statistics, accumulator in accumulators.items():
        matrix = accumulator.matrix()
        for solve_name, (solve, weights_label) in SOLVES.items():
            name = f"gt_{statistics}_{solve_name}"
            maps[name] = solve(matrix)
            images[name] = blend(maps[name], full)
            rows[name] = {"panel": next(panel), "statistics": GROUND_TRUTH[statistics], "weights": weights_label}
    for name, combiner, params, weights_label in DUAL_BUFFER:
        result = method_function(load_method(combiner, kind="combiner"), weights_dir=weights_dir)(
            held_out, held_outputs, **params)
        maps[name] = _combiner_weights(result, len(held_outputs))
        images[name] = np.asarray(result.full, np.float64)
        rows[name] = {"panel": next(panel), "statistics": "<M> (dual buffer, held-out render)",
                      "weights": weights_label}
    images[NOISY] = np.asarray(held_out.color, np.float64)
    rows[NOISY] = {"panel": "-", "statistics": "-", "weights": "noisy input (held-out render)"}
    for name, output in zip(denoisers, held_outputs):
        images[name] = np.asarray(output.full, np.float64)
        rows[name] = {"panel": "-", "statistics": "-", "weights": f"base denoiser {name}"}
    return images, maps, rows


def run_oracle_study(scene: str, reference_path: str, *, table_csv: str, table_md: str, weights_png: str,
                     denoisers: list[str], repetitions: int, spp: int, downscale: int, resolution=None,
                     variant: str = "auto", seed: int = 0, threads: int | None = None,
                     features: str = "first_hit", weights_dir: str | None = None) -> pd.DataFrame:
    """Run the oracle study of one scene and write its table (CSV and Markdown) and weight maps (PNG).

    ``denoisers``: base denoiser modules of ``methods/`` (default parameters); ``repetitions``
    (R >= 2) renders feed the statistics, one more is held out; ``spp`` even; ``resolution``
    the harness's (``None``: the scene's own), divided by ``downscale`` (the reference at
    ``reference_path`` must have the harness's resolution). Returns the table: one row per panel
    a-i (``panel``, ``statistics``, ``weights``, ``relmse``, ``dssim``) then the held-out noisy
    render and each base denoiser (panel ``-``), errors against the block-averaged reference.
    ``features``: the renders' feature convention (config key ``features``); ``weights_dir``: the
    learned bases' weights folder (config key ``weights_dir``; default the committed one).
    """
    from mcbench.pipeline.method_runs import method_function
    from mcbench.pipeline.registry import load_method, load_scene
    from mcbench.render.variants import pick_variant, set_threads

    started = time.perf_counter()
    module = load_scene(scene, config_key="oracle.scene")
    scene_declaration = scene_spec(module)
    width, height = oracle_size(resolution, scene_declaration.size, downscale)
    repetitions, spp = int(repetitions), int(spp)
    if repetitions < 2:
        raise BenchError(f"config key 'oracle.repetitions': need at least 2, got {repetitions}")
    if len(denoisers) < 2:
        raise BenchError(f"config key 'oracle.denoisers': need at least 2 base denoisers, got {denoisers}")
    bases = [method_function(load_method(name, kind="denoiser", config_key=f"oracle.denoisers[{i}]"),
                             weights_dir=weights_dir) for i, name in enumerate(denoisers)]
    mu = _oracle_reference(reference_path, scene, width, height, downscale)
    variant = pick_variant(variant)
    set_threads(threads)
    desc = scene_declaration.build(width, height)
    accumulators, held_out, held_outputs = _render_repetitions(
        desc, bases, mu, scene=scene, spp=spp, repetitions=repetitions, seed=seed, variant=variant, features=features,
        label=f"oracle {scene} ({width}x{height}, {spp} spp, {variant})", started=started)
    images, maps, rows = _oracle_images(accumulators, held_out, held_outputs, denoisers, weights_dir=weights_dir)
    table = error_table(images, mu, rows=rows)
    write_csv(table_csv, table)
    seconds = time.perf_counter() - started
    title = (f"Weights from ground-truth statistics (Zheng et al. 2021 Fig. 11): {scene} at {width}x{height}, "
             f"{spp} spp, R = {repetitions} renders for the statistics + 1 held out, bases "
             f"{', '.join(denoisers)}, seed {seed}, {variant}; {seconds:.0f} s")
    write_text(table_md, table_markdown(table, title=title))
    weight_maps_figure({f"({rows[n]['panel']}) {rows[n]['statistics'].split(' (')[0]} {rows[n]['weights']}": maps[n]
                        for n in maps}, weights_png, denoisers=list(denoisers), title=title)
    return table
