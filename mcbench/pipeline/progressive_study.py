"""Progressive denoising's consistency curve (Firmino et al. 2022): one scene rendered at many spp
levels up to high spp (8192 by default), the errors of the noisy render, of the base denoiser,
of progressive denoising (PD, ``methods/progressive.py``) over that base and of the base bounded
by the t-test alone, against spp. PD is built to be *consistent*: its error converges to the noisy
render's as spp grows and is never much worse, whatever the base's bias. Like
:mod:`mcbench.pipeline.oracle` it resolves scene and method names (plugins); the maths is in
``methods/progressive.py`` and :mod:`mcbench.filters.sure`.

Choices:

* **Resolution.** The curve renders at the harness's resolution (config ``resolution`` or the
  scene's declared ``resolution``) divided by ``downscale`` (config ``progressive_curve.downscale``, 2 by
  default), as the oracle study does: four times fewer pixels make the 8192-spp render affordable.
  The ground truth is the harness's reference averaged over ``downscale`` x ``downscale`` blocks
  (:func:`mcbench.combine.oracle_weights.block_average`: with the box pixel filter the block mean is the reference
  of the same camera at the lower resolution). The reference must be much less noisy than the
  top level, or the top of the curve measures the reference's noise: a reference of R spp
  averaged ``downscale`` x ``downscale`` is worth R x downscale² spp at the curve's resolution
  (the default config's 16384-spp references are worth 65536 spp, 8x the 8192-spp top level). The
  reference's own noise floor (:func:`reference_floor`, the relMSE a perfect image would show)
  is written in the Markdown and drawn dashed in the figure, and ``relmse_corrected`` removes it
  (:func:`mcbench.analysis.metrics.relmse_corrected` with the block mean's variance, see
  :func:`block_reference`).
* **Seeds.** Every level has its own seed stream, :func:`mcbench.render.seeds.progressive_curve_seed`
  (level ``i`` of the sorted levels; halves A and B and their sample bins as every render),
  disjoint from the test renders', reference chunks', oracle renders' and training renders'.
  Each level is an independent render (not the first samples of the next level's), so the
  points of one curve carry independent noise. (The slot caps scalar-variant curves at about
  128 x 128 pixels per render; llvm_ad_rgb has no such cap.)
* **Entries** per level: ``noisy`` (the render; its seconds are the render's), the base denoiser
  (``base``, default parameters, seconds of ``denoise``), ``pd_<base>`` (PD with the committed
  weights and SURE's divergence by re-running ``divergence``; seconds of ``combine`` only, the
  base's excluded) and ``pd_<base>_ttest_only`` (``combine(..., network=False)``: α = 1 bounded
  by the t-test of Eq. 18 alone, i.e. the base pulled back to the render where the two disagree
  significantly). The t-test-only line separates the safeguard from the network: both are
  consistent, and the gap between them is what the learned α adds at low spp. The first level
  runs the base and PD once untimed before the timed runs (imports, PD's weights, OIDN's
  device; the outputs are deterministic), and the scene is loaded before the first render, so
  every level's seconds are its own compute.
* **Figure.** relMSE and SMAPE against spp (log-log), one line per entry, the reference's floor
  dashed; the Markdown counts the levels where PD's relMSE is at most the render's (listing the
  exceptions) and gives PD/noisy and t-test-only/noisy relMSE per spp, which should approach 1,
  ideally from below (from just above where the t-test still lets through a bias of the base too
  small to be significant at that spp).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from mcbench import METRICS_COLUMNS, NOISY, BenchError
from mcbench.contracts.method import method_spec
from mcbench.contracts.scene import scene_spec
from mcbench.io.buffers import RenderBuffers
from mcbench.io.exr import ExrError, check_finite, read_layers
from mcbench.analysis.error_speed_figures import pyplot_agg, save_figure
from mcbench.io.tables import read_table, write_csv, write_text
from mcbench.analysis.metrics import relmse, relmse_corrected, smape
from mcbench.analysis.oracle_tables import table_markdown
from mcbench.combine.oracle_weights import block_average
from mcbench.progress import eta_seconds, progress_line
from mcbench.analysis.scene_summary import reference_relmse_floor
from mcbench.render.seeds import MAX_PROGRESSIVE_CURVE_LEVELS, MAX_PROGRESSIVE_CURVE_PASSES, progressive_curve_seed
from mcbench.pipeline.oracle import oracle_size

COLUMNS = ("spp", "entry", "label", "relmse", "relmse_corrected", "smape", "seconds")


def entry_names(base: str) -> list[str]:
    """The table's entries per level, in order: noisy, the base, PD over it, the t-test bound."""
    return [NOISY, base, f"pd_{base}", f"pd_{base}_ttest_only"]


def check_spp_levels(spp_levels) -> list[int]:
    """``spp_levels`` sorted: at least 2 distinct even integers >= 2 (BenchError naming
    ``progressive_curve.spp`` otherwise)."""
    try:
        levels = [int(s) for s in spp_levels]
    except (TypeError, ValueError):
        raise BenchError(f"config key 'progressive_curve.spp': need a list of even integers, "
                         f"got {spp_levels!r}") from None
    if any(float(s) != level for s, level in zip(spp_levels, levels)):
        raise BenchError(f"config key 'progressive_curve.spp': levels must be integers, got {list(spp_levels)}")
    bad = [s for s in levels if s < 2 or s % 2]
    if bad:
        raise BenchError(f"config key 'progressive_curve.spp': every level must be an even spp >= 2 "
                         f"(half buffers A and B), got {bad}")
    if len(set(levels)) != len(levels):
        raise BenchError(f"config key 'progressive_curve.spp': levels repeat: {levels}")
    if not 2 <= len(levels) <= MAX_PROGRESSIVE_CURVE_LEVELS:
        raise BenchError(f"config key 'progressive_curve.spp': need 2..{MAX_PROGRESSIVE_CURVE_LEVELS} levels "
                         f"for a curve, got {len(levels)}")
    return sorted(levels)


def curve_size(resolution, scene_resolution, downscale: int) -> tuple[int, int]:
    """``(width, height)`` of the curve's renders (:func:`mcbench.pipeline.oracle.oracle_size`, the
    error naming ``progressive_curve.downscale``)."""
    try:
        return oracle_size(resolution, scene_resolution, downscale)
    except BenchError as error:
        raise BenchError(str(error).replace("oracle.downscale", "progressive_curve.downscale")) from None


def block_reference(reference_path: str, width: int, height: int, downscale: int
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """The reference at ``reference_path`` averaged over ``downscale`` x ``downscale`` blocks, and
    the variance of that block mean (None when the EXR has no ``variance`` layer).

    The reference must have the harness's resolution ``(width * downscale, height * downscale)``
    and finite ``color`` (and ``variance``) layers. Its ``variance`` layer holds each pixel's
    variance of the mean v_i (as the case job's entry evaluation,
    :func:`mcbench.pipeline.evaluation.evaluate_entry_values`, reads it for ``relmse_corrected``). The pixels of a block are independent estimates (their samples are), so
    the variance of the block mean m = (1/f²) Σ r_i over the f² pixels (f = ``downscale``) is

        Var[m] = (1/f⁴) Σ v_i = block_average(v, f) / f²,

    i.e. averaging f² pixels divides the reference's noise by f² (the 2 x 2 block mean of a
    65536-spp reference is worth 262144 spp).
    """
    try:
        layers = read_layers(reference_path, ["color", "variance"])
    except ExrError:
        layers = read_layers(reference_path, ["color"])      # missing/corrupt file or no color: its own error
    check_finite(reference_path, layers)
    color = np.asarray(layers["color"], np.float64)
    expected = (height * downscale, width * downscale)
    if color.ndim != 3 or color.shape[:2] != expected:
        raise BenchError(f"{reference_path}: reference is {color.shape[1]}x{color.shape[0]}, the harness's "
                         f"resolution is {expected[1]}x{expected[0]} (the curve's {width}x{height} times "
                         f"progressive_curve.downscale {downscale})")
    variance = layers.get("variance")
    if variance is not None:
        variance = np.maximum(np.asarray(variance, np.float64), 0.0)
        if variance.shape != color.shape:
            raise BenchError(f"{reference_path}: variance layer {variance.shape} does not match color {color.shape}")
        variance = block_average(variance, downscale) / downscale ** 2
    return block_average(color, downscale), variance


def reference_floor(mu: np.ndarray, variance: np.ndarray | None) -> float | None:
    """The reference's relMSE noise floor, mean of Var / (μ² + 0.01) (:func:`mcbench.analysis.scene_summary.reference_relmse_floor`):
    the relMSE a perfect image would show against it; None without a variance."""
    return None if variance is None else reference_relmse_floor(mu, variance)


def _errors(name: str, image: np.ndarray, mu: np.ndarray, variance: np.ndarray | None) -> dict:
    image = np.asarray(image, np.float64)
    if image.shape != mu.shape:
        raise BenchError(f"progressive curve: {name}'s image is {image.shape}, the reference {mu.shape}")
    if not np.isfinite(image).all():
        raise BenchError(f"progressive curve: {name}'s image holds NaN or Inf values")
    errors = {"relmse": relmse(image, mu)}
    if variance is not None:
        errors["relmse_corrected"] = relmse_corrected(image, mu, variance)
    errors["smape"] = smape(image, mu)
    return errors


def _ratio(numerator: float, denominator: float) -> float | None:
    """numerator / denominator when both are finite and the denominator positive, else None."""
    if not (np.isfinite(numerator) and np.isfinite(denominator)) or denominator <= 0:
        return None
    return float(numerator / denominator)


def _cell(value: float | None, digits: int = 3) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def consistency_markdown(table: pd.DataFrame, base: str) -> str:
    """The consistency summary under the table: at how many levels PD's relMSE is at most the noisy
    render's (the exceptions with their ratio), and PD/noisy (and t-test-only/noisy) per spp."""
    entries = entry_names(base)
    pivot = table.pivot(index="spp", columns="entry", values="relmse")
    corrected = (table.pivot(index="spp", columns="entry", values="relmse_corrected")
                 if "relmse_corrected" in table else None)
    levels = list(pivot.index)
    noisy, pd_name, ttest = pivot[entries[0]], pivot[entries[2]], pivot[entries[3]]
    ratios = {spp: _ratio(pd_name[spp], noisy[spp]) for spp in levels}
    exceptions = [spp for spp in levels if pd_name[spp] > noisy[spp]]
    lines = ["", f"**Consistency.** PD's relMSE is at most the noisy render's at {len(levels) - len(exceptions)} "
                 f"of {len(levels)} spp levels"]
    lines[-1] += ("." if not exceptions else
                  "; exceptions (spp: PD/noisy relMSE): "
                  + ", ".join(f"{spp}: {_cell(ratios[spp])}" for spp in exceptions) + ".")
    lines += ["Consistency: PD/noisy approaches 1 as spp grows (PD converges to the render), ideally from "
              "below (below 1 PD improves on the render; above 1 it keeps more of the base's bias than the "
              "render's noise at that spp is worth: the t-test lets the base through where the difference "
              "is not yet significant). The t-test-only bound shows the same without the network.", ""]
    header = ["spp", "PD/noisy relMSE", "t-test only/noisy relMSE"]
    if corrected is not None:
        header += ["PD/noisy relMSE (corrected)"]
    lines += ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    for spp in levels:
        row = [str(spp), _cell(ratios[spp]), _cell(_ratio(ttest[spp], noisy[spp]))]
        if corrected is not None:
            row += [_cell(_ratio(corrected[entries[2]][spp], corrected[entries[0]][spp]))]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def curve_figure(table: pd.DataFrame, path: str, *, entries: list[str], labels: dict[str, str],
                 floor: float | None, title: str) -> None:
    """Two log-log panels, relMSE and SMAPE against spp, one labelled line per entry; the
    reference's relMSE floor dashed on the first. Written atomically (PNG)."""
    import textwrap

    plt = pyplot_agg()
    figure, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    styles = {entries[0]: dict(color="0.35", marker="o"), entries[1]: dict(color="tab:blue", marker="s"),
              entries[2]: dict(color="tab:red", marker="^", linewidth=2.0),
              entries[3]: dict(color="tab:green", marker="v", linestyle="-.")}
    for axis, metric, name in ((axes[0], "relmse", "relMSE"), (axes[1], "smape", "SMAPE")):
        for entry in entries:
            rows = table[table["entry"] == entry].sort_values("spp")
            values = rows[metric].to_numpy(np.float64)
            keep = np.isfinite(values) & (values > 0)         # log axes: positive values only
            axis.plot(rows["spp"].to_numpy()[keep], values[keep], label=labels[entry], markersize=4,
                      **styles.get(entry, {}))
        if metric == "relmse" and floor is not None and np.isfinite(floor) and floor > 0:
            axis.axhline(floor, color="black", linestyle="--", linewidth=1.0,
                         label=f"reference noise floor ({floor:.2g})")
        axis.set_xscale("log", base=2)
        axis.set_yscale("log")
        axis.set_xlabel("samples per pixel")
        axis.set_ylabel(name)
        axis.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    figure.suptitle("\n".join(textwrap.wrap(title, 140)), fontsize=8)
    figure.tight_layout()
    save_figure(figure, path)


def _curve_methods(base: str, divergence: str, *, weights_dir: str | None) -> tuple:
    """``(base module, the base's run, progressive denoising's run)``, each learned one with its
    weights from ``weights_dir``; refused (naming the config key) when ``divergence`` is neither
    ``none`` nor a denoiser that declares a single-image function."""
    from mcbench.pipeline.method_runs import method_function
    from mcbench.pipeline.registry import load_method, single_image_methods

    base_module = load_method(base, kind="denoiser", config_key="progressive_curve.base")
    combiner = load_method("progressive", kind="combiner", config_key="progressive_curve")
    divergences = ("none", *single_image_methods())     # the denoisers that declare a single-image function
    if divergence not in divergences:
        raise BenchError(f"config key 'progressive_curve.divergence': '{divergence}' is not one of "
                         f"{', '.join(divergences)} (none, or a denoiser with a single-image function)")
    return (base_module, method_function(base_module, weights_dir=weights_dir),
            method_function(combiner, weights_dir=weights_dir))


def _curve_scene(module, width: int, height: int, top: int, variant: str, key: str):
    """The scene's description at ``width`` x ``height``, loaded into Mitsuba under ``key`` (the
    load is no level's time); refused when ``top`` spp needs more passes per bin than the seed
    layout has."""
    from mcbench.render.renderer import load_scene_dict, passes_for

    passes = len(passes_for(top // 4 if top % 4 == 0 else top // 2, width, height, variant))
    if passes > MAX_PROGRESSIVE_CURVE_PASSES:
        raise BenchError(f"config key 'progressive_curve.spp': {top} spp at {width}x{height} needs {passes} "
                         f"passes per bin, more than the seed layout's {MAX_PROGRESSIVE_CURVE_PASSES}")
    desc = scene_spec(module).build(width, height)
    load_scene_dict(desc, key=key, variant=variant)
    return desc


def _curve_labels(entries: list[str], base_label: str, divergence: str) -> dict[str, str]:
    """The table labels of the curve's entries (PD's weights are trained by mcbench on its own
    training scenes: the mark † as in every table)."""
    from mcbench import NOISY_LABEL

    return {entries[0]: NOISY_LABEL, entries[1]: base_label,
            entries[2]: f"PD† over {base_label} (divergence: {divergence})",
            entries[3]: f"{base_label} bounded by the t-test alone (PD w/o h_NN)"}


def _level_outputs(buffers: RenderBuffers, entries: list[str], denoise, combine, divergence: str, *,
                   warm_up: bool) -> tuple[dict, dict]:
    """``(images, seconds)`` of the base, PD and the t-test bound on one level's render, keyed
    by entry (the noisy input's image is the render's; its seconds are the caller's). With
    ``warm_up`` the methods run once untimed first (imports, PD's weights, OIDN's device; their
    outputs are deterministic)."""
    if warm_up:
        combine(buffers, [denoise(buffers)], divergence=divergence)
    spent = {}
    clock = time.perf_counter()
    base_out = denoise(buffers)
    spent[entries[1]] = time.perf_counter() - clock
    clock = time.perf_counter()
    pd_out = combine(buffers, [base_out], divergence=divergence)
    spent[entries[2]] = time.perf_counter() - clock
    clock = time.perf_counter()
    bound = combine(buffers, [base_out], network=False)
    spent[entries[3]] = time.perf_counter() - clock
    images = {entries[0]: buffers.color, entries[1]: base_out.full, entries[2]: pd_out.full, entries[3]: bound.full}
    return images, spent


def _write_curve(table: pd.DataFrame, *, table_csv: str, table_md: str, figure_png: str, title: str, base: str,
                 entries: list[str], labels: dict[str, str], floor: float | None) -> None:
    """The curve's table (CSV, and Markdown with the noise floor's note) and figure."""
    write_csv(table_csv, table)
    floor_text = ("The reference has no variance layer: no noise floor, no corrected relMSE." if floor is None else
                  f"Reference noise floor (block-averaged reference, mean of Var / (μ² + 0.01), the relMSE a "
                  f"perfect image would show): {floor:.4g}; relmse_corrected removes it.")
    write_text(table_md, table_markdown(table, title=title) + "\n" + floor_text + "\n"
               + consistency_markdown(table, base))
    curve_figure(table, figure_png, entries=entries, labels=labels, floor=floor, title=title)


def run_consistency_curve(scene: str, reference_path: str, *, table_csv: str, table_md: str, figure_png: str,
                          spp_levels: list[int], base: str = "oidn", divergence: str = "oidn",
                          downscale: int = 2, resolution=None, variant: str = "auto", seed: int = 0,
                          threads: int | None = None, features: str = "first_hit",
                          weights_dir: str | None = None) -> pd.DataFrame:
    """Render ``scene`` at every level of ``spp_levels`` and write the consistency curve's table
    (CSV and Markdown) and figure (PNG).

    ``spp_levels``: even spp >= 2, distinct (sorted here); ``base``: a denoiser module of
    ``methods/`` (default parameters); ``divergence``: PD's divergence base (``none`` or a
    denoiser with a single-image function); ``resolution`` the harness's (``None``: the scene's
    own), divided by ``downscale``; the reference at ``reference_path`` must have the harness's
    resolution. Returns the table: one row per (spp, entry) with columns ``spp``, ``entry``,
    ``label``, ``relmse``, ``relmse_corrected`` (only when the reference has a variance layer),
    ``smape``, ``seconds``; entries :func:`entry_names` (module docstring). ``features``: the
    renders' feature convention (config key ``features``); ``weights_dir``: the learned
    networks' folder (config key ``weights_dir``; default the committed one).
    """
    from mcbench.pipeline.registry import load_scene
    from mcbench.render.renderer import render_dict_buffers
    from mcbench.render.variants import pick_variant, set_threads

    started = time.perf_counter()
    levels = check_spp_levels(spp_levels)
    module = load_scene(scene, config_key="progressive_curve.scene")
    scene_declaration = scene_spec(module)
    width, height = curve_size(resolution, scene_declaration.size, downscale)
    downscale = int(downscale)
    base_module, denoise, combine = _curve_methods(base, divergence, weights_dir=weights_dir)
    mu, reference_variance = block_reference(reference_path, width, height, downscale)
    floor = reference_floor(mu, reference_variance)
    variant = pick_variant(variant)
    set_threads(threads)
    key = f"progressive_curve:{scene}"
    desc = _curve_scene(module, width, height, levels[-1], variant, key)
    entries = entry_names(base)
    labels = _curve_labels(entries, method_spec(base_module).label, divergence)
    label = f"progressive curve {scene} ({width}x{height}, {variant})"
    records, done, render_seconds, method_seconds = [], 0, 0.0, 0.0
    for index, spp in enumerate(levels):
        clock = time.perf_counter()
        layers, _ = render_dict_buffers(
            desc, spp, lambda half, j, p, index=index: progressive_curve_seed(index, half, bin=j, pass_index=p,
                                                                              base_seed=seed),
            key=key, variant=variant, features=features)
        buffers = RenderBuffers(layers=layers, spp=spp, source=f"progressive curve render of '{scene}' at {spp} spp")
        render_spent = time.perf_counter() - clock
        images, spent = _level_outputs(buffers, entries, denoise, combine, divergence, warm_up=index == 0)
        spent[entries[0]] = render_spent
        records += [{"spp": spp, "entry": entry, "label": labels[entry],
                     **_errors(f"{entry} at {spp} spp", images[entry], mu, reference_variance),
                     "seconds": float(spent[entry])} for entry in entries]
        # ETA: renders scale with spp, the methods' time per level does not (measured so far)
        done += spp
        render_seconds += render_spent
        method_seconds += sum(spent[e] for e in entries[1:])
        eta = eta_seconds(render_seconds, done, sum(levels)) + method_seconds / (index + 1) * (len(levels) - index - 1)
        print(progress_line(label, f"{spp} spp done (level {index + 1}/{len(levels)})",
                            time.perf_counter() - started, eta), flush=True)
    table = pd.DataFrame.from_records(records, columns=[c for c in COLUMNS if c != "relmse_corrected"
                                                        or reference_variance is not None])
    title = (f"Progressive denoising's consistency curve (Firmino et al. 2022): {scene} at {width}x{height} "
             f"(harness resolution / {downscale}), spp {', '.join(map(str, levels))}, base {base}, "
             f"divergence {divergence}, seed {seed}, {variant}; {time.perf_counter() - started:.0f} s")
    _write_curve(table, table_csv=table_csv, table_md=table_md, figure_png=figure_png, title=title, base=base,
                 entries=entries, labels=labels, floor=floor)
    return table


def write_progressive_tables(metrics_csv: str, timings_csv: str, out_dir: str, *, pairs: dict[str, str],
                             labels: dict[str, str], metrics: list[str]) -> dict:
    """Progressive denoising's tables (:mod:`mcbench.analysis.progressive_tables`) under ``out_dir``:
    ``consistency.{csv,md}`` (relMSE against the noisy input per spp) and ``per_spp.{csv,md}``
    (each input and its progressive entries: mean error per spp of each of ``metrics``, and the
    seconds each adds per case)."""
    import pandas as pd

    from mcbench.analysis.progressive_tables import (added_seconds, consistency_markdown, consistency_summary,
                                                     consistency_table, per_spp_markdown, per_spp_table, table_entries)

    out = Path(out_dir)
    table = read_table(metrics_csv, columns=METRICS_COLUMNS)
    timings = read_table(timings_csv, columns=("scene", "spp", "method", "seconds"))
    consistency = consistency_table(table, dict(pairs), metric="relmse", noisy=NOISY)
    summary = consistency_summary(consistency)
    write_csv(out / "consistency.csv", consistency, float_format="%.6g")
    write_text(out / "consistency.md", consistency_markdown(consistency, summary, labels, metric="relmse"))
    entries = table_entries(dict(pairs), noisy=NOISY)
    errors = {metric: per_spp_table(table, entries, metric=metric) for metric in metrics}
    seconds = added_seconds(timings, entries)
    long = pd.concat([frame.assign(quantity=metric) for metric, frame in
                      {**errors, **({"seconds": seconds} if not seconds.empty else {})}.items()])
    write_csv(out / "per_spp.csv", long.reset_index(), float_format="%.6g")
    write_text(out / "per_spp.md", per_spp_markdown(errors, seconds, labels))
    return {"consistency": consistency, "summary": summary, "errors": errors, "seconds": seconds}
