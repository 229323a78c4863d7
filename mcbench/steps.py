"""The work behind each Snakemake rule, as plain functions of paths and parameters.

The scripts in ``workflow/scripts/`` only unpack the ``snakemake`` object and call these,
so every step can be run and tested without Snakemake.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

from mcbench import BenchError
from mcbench.buffers import Denoised, RenderBuffers
from mcbench.exr import check_finite, read_layers, read_metadata, write_layers
from mcbench.io import read_json, write_csv, write_json, write_text
from mcbench.metrics import METRICS

NOISY = "noisy"


def _machine() -> str:
    return f"{platform.node()} {platform.machine()} {platform.processor() or ''}".strip()


def run_method(method: str, render_path: str, output_path: str, timing_path: str, *,
               module_name: str, params: dict | None = None, input_paths: list[str] = (),
               scene: str = "", spp: int = 0, threads: int = 1) -> None:
    """Run one base denoiser or combiner on a render and write its output EXR and timing JSON.

    The timing counts the method's compute only (EXR reading and writing excluded), measured
    with ``time.perf_counter``; base denoisers include their three runs (full, A, B).
    """
    from methods import load_method

    module = load_method(module_name, config_key=f"method '{method}'")
    buffers = RenderBuffers.load(render_path)
    inputs = [Denoised.load(p) for p in input_paths]
    for path, denoised in zip(input_paths, inputs):
        if denoised.full.shape != buffers.color.shape:
            raise BenchError(f"{path}: shape {denoised.full.shape} does not match render "
                             f"{render_path} of shape {buffers.color.shape}")
    start = time.perf_counter()
    if module.KIND == "denoiser":
        result = module.denoise(buffers, **(params or {}))
    else:
        result = module.combine(buffers, inputs, **(params or {}))
    seconds = time.perf_counter() - start
    layers = result.layers()
    bad = {name: layer for name, layer in layers.items() if not np.all(np.isfinite(layer))}
    if bad:
        check_finite(f"{output_path} (output of method '{method}')", bad)
    write_layers(output_path, layers, metadata={"method": method, "scene": scene, "spp": spp,
                                                "seconds": f"{seconds:.6f}"})
    height, width = buffers.shape
    write_json(timing_path, {"scene": scene, "spp": spp, "method": method, "module": module_name,
                             "kind": module.KIND, "seconds": seconds, "width": width,
                             "height": height, "threads": threads, "machine": _machine()})


def compute_case_metrics(scene: str, spp: int, reference_path: str, render_path: str,
                         candidate_paths: dict[str, str], metrics: list[str], output_path: str) -> pd.DataFrame:
    """Errors of the noisy input and every candidate against the reference for one test case.

    Writes a tidy CSV with columns scene, spp, candidate, metric, value.
    """
    reference = read_layers(reference_path, ["color"])
    check_finite(reference_path, reference)
    reference = reference["color"]
    images = {NOISY: RenderBuffers.load(render_path).color}
    for candidate, path in candidate_paths.items():
        images[candidate] = Denoised.load(path).full
    rows = []
    for candidate, image in images.items():
        if image.shape != reference.shape:
            source = render_path if candidate == NOISY else candidate_paths[candidate]
            raise BenchError(f"{source}: shape {image.shape} does not match reference "
                             f"{reference_path} of shape {reference.shape}")
        for metric in metrics:
            rows.append({"scene": scene, "spp": spp, "candidate": candidate, "metric": metric,
                         "value": METRICS[metric](image, reference)})
    frame = pd.DataFrame(rows)
    write_csv(output_path, frame)
    return frame


def gather_tables(paths: list[str], output_path: str) -> pd.DataFrame:
    """Concatenate per-case CSVs into one tidy table."""
    frame = pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)
    write_csv(output_path, frame)
    return frame


def gather_timings(paths: list[str], output_path: str) -> pd.DataFrame:
    """Collect the per-job timing JSONs into ``timings.csv`` (one row per method run)."""
    frame = pd.DataFrame([read_json(p) for p in paths])
    columns = ["scene", "spp", "method", "module", "kind", "seconds", "width", "height", "threads", "machine"]
    frame = frame[[c for c in columns if c in frame.columns]].sort_values(["method", "scene", "spp"])
    write_csv(output_path, frame)
    return frame


def write_rankings(metrics_csv: str, metric: str, csv_path: str, md_path: str,
                   order: list[str], labels: dict[str, str]) -> pd.DataFrame:
    """Score-and-rank table (Zheng et al. Table 3 layout) for one metric, as CSV and Markdown."""
    from mcbench.ranking import format_markdown, ranking_table

    metrics = pd.read_csv(metrics_csv)
    table = ranking_table(metrics, metric, order=None)
    write_csv(csv_path, table.reset_index(), float_format="%.4f")
    n_cases = metrics[metrics["metric"] == metric].groupby(["scene", "spp"]).ngroups
    n_entries = table.shape[0]
    header = (f"# Ranking by {metric}\n\nScores per Zheng et al. 2021 Sec. 5.3.3: in each of the "
              f"{n_cases} test cases the {n_entries} entries (candidates and the noisy input) get "
              f"linearly spaced scores from {n_entries} (lowest error) to 1; columns are the mean over "
              f"scenes per spp, `Avg.` the mean over spp. Higher is better.\n\n")
    write_text(md_path, header + format_markdown(table, labels) + "\n")
    return table


def render_noisy(scene: str, spp: int, output_path: str, *, resolution=None, variant: str = "auto",
                 seed: int = 0, threads: int | None = None) -> None:
    """Render the full image and the two half buffers of one (scene, spp) to a multi-layer EXR."""
    from mcbench.render import render_buffers

    layers, metadata = render_buffers(scene, spp, resolution=_resolution(resolution), variant=variant,
                                      seed=seed, threads=threads)
    check_finite(f"{output_path} (render of scene '{scene}' at {spp} spp)", layers)
    write_layers(output_path, layers, metadata=metadata)


def render_reference_chunk(scene: str, spp: int, chunk: int, output_path: str, *, resolution=None,
                           variant: str = "auto", seed: int = 0, threads: int | None = None) -> None:
    """Render one chunk of a reference with its own seeds (never overlapping the noisy renders)."""
    from mcbench.render import render_reference_chunk as render_chunk

    layers, metadata = render_chunk(scene, spp, chunk, resolution=_resolution(resolution),
                                    variant=variant, seed=seed, threads=threads)
    check_finite(f"{output_path} (reference chunk {chunk} of scene '{scene}')", layers)
    write_layers(output_path, layers, metadata=metadata)


def merge_reference(chunk_paths: list[str], output_path: str) -> None:
    """Merge reference chunks (spp-weighted, float64) into the reference with its own variance."""
    from mcbench.render import merge_reference_chunks

    chunks = []
    for path in chunk_paths:
        layers = read_layers(path)
        check_finite(path, layers)
        chunks.append((layers, read_metadata(path)))
    layers, metadata = merge_reference_chunks(chunks)
    write_layers(output_path, layers, metadata=metadata)


def _resolution(resolution):
    if resolution is None:
        return None
    if isinstance(resolution, int):
        return (resolution, resolution)
    return tuple(int(v) for v in resolution)


def _benchmark_cpu_hours(paths: list[Path]) -> float:
    """Sum of Snakemake benchmark ``cpu_time`` (seconds) over existing TSVs, in hours."""
    total = 0.0
    for path in paths:
        if path.exists():
            frame = pd.read_csv(path, sep="\t")
            if "cpu_time" in frame and len(frame):
                total += float(frame["cpu_time"].iloc[-1])
    return total / 3600.0


def write_scene_table(metrics_csv: str, reference_paths: dict[str, str], reference_spp: dict[str, int],
                      benchmarks_dir: str, csv_path: str, md_path: str) -> pd.DataFrame:
    """Scene table with reference noise floors (issue: trustworthy references) and render costs.

    Render costs come from the Snakemake ``benchmark:`` records of the render and reference jobs
    under ``benchmarks_dir`` (read, not declared as inputs: they are side records of those jobs).
    """
    from mcbench.reports import reference_relmse_floor, scene_markdown, scene_rows
    from scenes import load_scene

    metrics = pd.read_csv(metrics_csv)
    floors, info, costs = {}, {}, {}
    bench = Path(benchmarks_dir)
    for scene, path in reference_paths.items():
        layers = read_layers(path, ["color", "variance"])
        check_finite(path, layers)
        floors[scene] = reference_relmse_floor(layers["color"], layers["variance"])
        module = load_scene(scene)
        meta = read_metadata(path)
        info[scene] = {"category": module.CATEGORY, "description": module.DESCRIPTION,
                       "resolution": meta.get("resolution", ""), "reference_spp": reference_spp[scene]}
        costs[scene] = {
            "render_cpu_hours": _benchmark_cpu_hours(sorted(bench.glob(f"render_noisy/{scene}_spp*.tsv"))),
            "reference_cpu_hours": _benchmark_cpu_hours(sorted(bench.glob(f"render_reference/{scene}_chunk*.tsv"))),
        }
    table = scene_rows(metrics, floors, info, costs)
    write_csv(csv_path, table, float_format="%.6g")
    write_text(md_path, scene_markdown(table))
    return table


def write_gallery(reference_paths: dict[str, str], png_path: str) -> None:
    """Gallery of all references with their names (Fig. 3 of Zheng et al.)."""
    from mcbench.reports import gallery_figure

    references = {}
    for scene, path in reference_paths.items():
        layers = read_layers(path, ["color"])
        check_finite(path, layers)
        references[scene] = layers["color"]
    gallery_figure(references, png_path)


def write_training_example(seed: int, output_paths: list[str], *, spp_levels, target_spp: int, resolution,
                           crop_size: int, variant: str = "auto", threads: int | None = None) -> None:
    """Render training scene ``seed`` (mcbench.training) and write one EXR per crop."""
    from mcbench.render import set_threads
    from mcbench.training import training_example

    set_threads(threads)
    crops = training_example(seed, list(spp_levels), target_spp, _resolution(resolution), crop_size,
                             len(output_paths), variant=variant)
    for path, (layers, metadata) in zip(output_paths, crops):
        check_finite(f"{path} (training scene {seed})", layers)
        write_layers(path, layers, metadata=metadata)
