"""The work behind each Snakemake rule, as plain functions of paths and parameters.

The scripts in ``workflow/scripts/`` only unpack the ``snakemake`` object and call these,
so every step can be run and tested without Snakemake.
"""

from __future__ import annotations

import json
import platform
import re
import time
from pathlib import Path

import numpy as np

from mcbench import BenchError
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.exr import check_finite, read_layers, read_metadata, write_layers
from mcbench.io.tables import read_json, read_table, write_csv, write_json, write_text
from mcbench.analysis.metrics import METRICS, REFERENCE_METRICS

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
    run_methods([{"name": method, "module": module_name, "params": params or {},
                  "input_paths": list(input_paths), "exr": output_path, "timing": timing_path}],
                render_path, scene=scene, spp=spp, threads=threads)


def run_methods(entries: list[dict], render_path: str, *, scene: str = "", spp: int = 0,
                threads: int = 1) -> None:
    """Run several methods of one test case in one process, in the given order (one DAG job).

    ``entries``: dicts with ``name``, ``module``, ``params``, ``input_paths`` (the output EXRs
    of the method's inputs) and ``exr``, ``timing`` (where its output and timing record go),
    in dependency order: an entry may take an earlier entry's output as an input. The render and
    every input EXR are read once; an input made earlier in the same call is read back from the
    file just written, so each method sees exactly what a job of its own would see (results
    do not depend on the batching). Every method gets its own output, timing record and output
    check. The timing is the method's compute on the case (``time.perf_counter``; EXR reading and
    writing excluded) after an untimed run on the case's top-left 32 x 32 crop (once per module and
    parameters: methods that differ only in their inputs share it), so that just-in-time
    compilation, numba's cache loading and first-call set-up are not counted (they are paid once
    per process, whatever the image size); the first failure stops the call, naming the
    method. Methods are imported once per process (a learned method's torch import is paid once
    per batch, not once per method).
    """
    from methods import load_method

    modules = {entry["module"]: load_method(entry["module"], config_key=f"method '{entry['name']}'")
               for entry in entries}
    by_rows = reads_rows(modules.values())
    if by_rows:
        buffers = _render_by_rows(render_path, render_layers(modules.values()))
    else:
        buffers = RenderBuffers.load(render_path, layers=render_layers(modules.values()))
    loaded: dict[str, Denoised] = {}

    def input_of(path: str) -> Denoised:
        if path not in loaded:
            denoised = _denoised_by_rows(path) if by_rows else Denoised.load(path, extras=True)
            if denoised.full.shape != buffers.color.shape:
                raise BenchError(f"{path}: shape {denoised.full.shape} does not match render "
                                 f"{render_path} of shape {buffers.color.shape}")
            loaded[path] = denoised
        return loaded[path]

    height, width = buffers.shape
    warmed: set[tuple[str, str]] = set()
    for entry in entries:
        method, module_name, params = entry["name"], entry["module"], dict(entry.get("params") or {})
        module = modules[module_name]
        inputs = [input_of(path) for path in entry.get("input_paths", ())]
        # untimed run on a corner crop: compiles / loads the method's JIT kernels (numba's cache
        # load alone took 0.6 s of a 0.06 s ensemble at 128x128) and first-call set-up, once per
        # module and parameters in the process (the 31 pool ensembles share one)
        key = (module_name, json.dumps(params, sort_keys=True, default=str))
        if key not in warmed:
            _apply(module, *_corner_crop(buffers, inputs), params)
            warmed.add(key)
        start = time.perf_counter()
        result = _apply(module, buffers, inputs, params)
        seconds = time.perf_counter() - start
        layers = result.layers()
        bad = {name: layer for name, layer in layers.items() if not np.all(np.isfinite(layer))}
        if bad:
            check_finite(f"{entry['exr']} (output of method '{method}')", bad)
        write_layers(entry["exr"], layers, metadata={"method": method, "scene": scene, "spp": spp,
                                                     "seconds": f"{seconds:.6f}"})
        write_json(entry["timing"], {"scene": scene, "spp": spp, "method": method, "module": module_name,
                                     "kind": module.KIND, "seconds": seconds, "width": width,
                                     "height": height, "threads": threads, "machine": _machine()})


WARM_UP_SIZE = 32  # pixels per side of the untimed warm-up crop of run_methods


def reads_rows(modules) -> bool:
    """Whether a job of these method modules reads its render and inputs by rows: every module
    declares ``READS_ROWS`` (methods/__init__.py; the ensemble), so no layer is held whole (a
    1024^2 N = 8 ensemble job: about 520 MiB instead of about 840, ``benchmarks/bench_ensemble.py``).
    Such a method reads the rows it needs inside its own call, so its recorded seconds include
    those reads (uncompressed scanlines, a few per cent of its compute); a batch with any other
    method reads every file whole, before the timed call."""
    modules = list(modules)
    return bool(modules) and all(getattr(module, "READS_ROWS", False) for module in modules)


def _render_by_rows(path: str, layers: tuple[str, ...] | None) -> RenderBuffers:
    """A render whose layers (``color`` and ``layers``) are :class:`mcbench.io.exr.LayerRows`: only
    the header is read here; the method checks the rows it reads for NaN/Inf."""
    from mcbench.io.exr import layer_rows

    names = list(dict.fromkeys(["color", *(layers or ())]))
    return RenderBuffers(layers=layer_rows(path, names), spp=int(read_metadata(path).get("spp", 0)), source=path)


def _denoised_by_rows(path: str) -> Denoised:
    """A method's output as :class:`mcbench.io.exr.LayerRows` of ``color``, ``color_a``, ``color_b``
    (read by rows when the method indexes them; no extras: a READS_ROWS method reads none)."""
    from mcbench.io.exr import layer_rows

    layers = layer_rows(path, ["color", "color_a", "color_b"])
    return Denoised(full=layers["color"], a=layers["color_a"], b=layers["color_b"], source=path)


def render_layers(modules) -> tuple[str, ...] | None:
    """The render layers a job of these method modules reads: the union of their
    ``RENDER_LAYERS`` (methods/__init__.py), or None (every layer) when one does not declare it."""
    names: dict[str, None] = {}
    for module in modules:
        declared = getattr(module, "RENDER_LAYERS", None)
        if declared is None:
            return None
        names.update(dict.fromkeys(declared))
    return tuple(names)


def _apply(module, buffers: RenderBuffers, inputs: list[Denoised], params: dict) -> Denoised:
    if module.KIND == "denoiser":
        return module.denoise(buffers, **params)
    return module.combine(buffers, inputs, **params)


def _corner_crop(buffers: RenderBuffers, inputs: list[Denoised]) -> tuple[RenderBuffers, list[Denoised]]:
    """The top-left WARM_UP_SIZE^2 pixels of a render and of its inputs (every layer)."""
    h, w = (min(WARM_UP_SIZE, n) for n in buffers.shape)

    def corner(layer: np.ndarray) -> np.ndarray:  # contiguous, like a loaded layer (same kernels)
        return np.ascontiguousarray(layer[:h, :w])

    crop = RenderBuffers(layers={k: corner(v) for k, v in buffers.layers.items()}, spp=buffers.spp,
                         source=buffers.source)
    cropped = [Denoised(full=corner(d.full), a=corner(d.a), b=corner(d.b),
                        extras={k: corner(v) for k, v in d.extras.items()} if d.extras else None)
               for d in inputs]
    return crop, cropped


def compute_case_metrics(scene: str, spp: int, reference_path: str, render_path: str,
                         candidate_paths: dict[str, str], metrics: list[str], output_path: str, *,
                         flip_maps_path: str | None = None) -> pd.DataFrame:
    """Errors of the noisy input and every candidate against the reference for one test case.

    Writes a tidy CSV with columns scene, spp, candidate, metric, value; with ``flip_maps_path``
    also every entry's per-pixel HDR-FLIP map (one (H, W) layer per entry, named like it), from
    the same evaluation as the ``flip`` metric, so the viewer does not evaluate FLIP again.
    """
    import pandas as pd

    from mcbench.analysis.metrics import flip_with_map

    start = time.perf_counter()
    needs_variance = any(metric in REFERENCE_METRICS for metric in metrics)
    reference = read_layers(reference_path, ["color", "variance"] if needs_variance else ["color"])
    check_finite(reference_path, reference)
    reference_variance = reference.get("variance")
    reference = reference["color"]
    images = {NOISY: RenderBuffers.load(render_path).color}
    for candidate, path in candidate_paths.items():
        images[candidate] = Denoised.load(path).full
    rows, flip_maps = [], {}
    for candidate, image in images.items():
        if image.shape != reference.shape:
            source = render_path if candidate == NOISY else candidate_paths[candidate]
            raise BenchError(f"{source}: shape {image.shape} does not match reference "
                             f"{reference_path} of shape {reference.shape}")
        flip_value = None
        if flip_maps_path is not None:
            flip_maps[candidate], flip_value = flip_with_map(image, reference)
        for metric in metrics:
            if metric == "flip" and flip_value is not None:
                value = flip_value
            elif metric in REFERENCE_METRICS:
                value = REFERENCE_METRICS[metric](image, reference, reference_variance)
            else:
                value = METRICS[metric](image, reference)
            rows.append({"scene": scene, "spp": spp, "candidate": candidate, "metric": metric, "value": value})
    frame = pd.DataFrame(rows)
    if flip_maps_path is not None:
        # seconds: this step's reading and computing (benchmarks/dag_overhead.py's metric compute)
        write_layers(flip_maps_path, flip_maps, metadata={"scene": scene, "spp": spp, "what": "HDR-FLIP maps",
                                                          "seconds": f"{time.perf_counter() - start:.6f}"})
    write_csv(output_path, frame)
    return frame


def read_case_metrics(path: str, *, candidates: list[str], metric_names: list[str],
                      case: tuple[str, int] | None = None) -> pd.DataFrame:
    """One per-case metrics CSV, refused (naming the file) unless it is whole: every candidate
    and metric once with a finite value, and only the case ``(scene, spp)`` when given."""
    from mcbench.analysis.ranking import check_complete

    frame = read_table(path)
    check_complete(frame, candidates=candidates, metric_names=metric_names,
                   cases=None if case is None else [case], source=path)
    if case is not None and len(frame.groupby(["scene", "spp"])) != 1:
        raise BenchError(f"{path}: holds more cases than ({case[0]}, {case[1]})")
    return frame


def gather_tables(paths: list[str], output_path: str, *, candidates: list[str], metric_names: list[str],
                  cases: list[tuple[str, int]]) -> pd.DataFrame:
    """Concatenate the per-case CSVs (``paths[i]`` holds ``cases[i]``) into one tidy table, after
    checking each is complete (:func:`read_case_metrics`): no table is ranked over lost rows."""
    import pandas as pd

    if len(paths) != len(cases):
        raise BenchError(f"{output_path}: {len(paths)} case files for {len(cases)} cases")
    frames = [read_case_metrics(path, candidates=candidates, metric_names=metric_names, case=case)
              for path, case in zip(paths, cases)]
    frame = pd.concat(frames, ignore_index=True)
    write_csv(output_path, frame)
    return frame


def gather_timings(paths: list[str], output_path: str) -> pd.DataFrame:
    """Collect the per-job timing JSONs into ``timings.csv`` (one row per method run)."""
    import pandas as pd

    frame = pd.DataFrame([read_json(p) for p in paths])
    columns = ["scene", "spp", "method", "module", "kind", "seconds", "width", "height", "threads", "machine"]
    frame = frame[[c for c in columns if c in frame.columns]].sort_values(["method", "scene", "spp"])
    write_csv(output_path, frame)
    return frame


def write_rankings(metrics_csv: str, metric: str, csv_path: str, md_path: str, *,
                   candidates: list[str], labels: dict[str, str], tex_path: str | None = None,
                   order: list[str] | None = None, note: str = "") -> pd.DataFrame:
    """Score-and-rank table (Zheng et al. Table 3 layout) for one metric, as CSV and Markdown,
    and as a LaTeX booktabs table at ``tex_path`` when given (label ``tab:ranking-<metric>``).

    ``candidates`` (with the noisy input) is the ranking pool: rows of other candidates (the
    extra methods, ranked in their own tables) are left out; a metrics table missing a pool
    candidate, or any incomplete case, stops here instead of being ranked. ``order``: the rows'
    order (the pool's ID order; default best Avg. first). ``note``: a sentence for the Markdown
    (e.g. that the pool is partial, so the scores are on another scale than the paper's)."""
    from mcbench.analysis.metrics import METRIC_LABELS
    from mcbench.analysis.ranking import check_complete, format_latex, format_markdown, ranking_table

    metrics = read_table(metrics_csv)
    # the ranking pool: the comparison methods' rows are ranked in their own tables
    metrics = metrics[metrics["candidate"].isin(candidates)]
    check_complete(metrics[metrics["metric"] == metric], candidates=candidates, metric_names=[metric],
                   source=metrics_csv)
    table = ranking_table(metrics, metric, order=order)
    write_csv(csv_path, table.reset_index(), float_format="%.4f")
    n_cases = metrics[metrics["metric"] == metric].groupby(["scene", "spp"]).ngroups
    n_entries = table.shape[0]
    scoring = (f"Scores per Zheng et al. 2021 Sec. 5.3.3: in each of the "
               f"{n_cases} test cases the {n_entries} entries (candidates and the noisy input) get "
               f"linearly spaced scores from {n_entries} (lowest error) to 1; columns are the mean over "
               f"scenes per spp, `Avg.` the mean over spp. Higher is better.")
    shown_note = f"\n\n{note}" if note else ""
    write_text(md_path, f"# Ranking by {metric}\n\n{scoring}{shown_note}\n\n" + format_markdown(table, labels) + "\n")
    if tex_path is not None:
        caption = (f"Ranking by {METRIC_LABELS.get(metric, metric)}. " + scoring.replace("`", "")
                   + " Best per column in bold.")
        write_text(tex_path, format_latex(table, labels, caption=caption, label=f"tab:ranking-{metric}"))
    return table


def write_extras_rankings(metrics_csv: str, metric: str, csv_path: str, md_path: str, *, pool: list[str],
                          extras: list[str], labels: dict[str, str], tex_path: str | None = None) -> pd.DataFrame:
    """The extra methods' scores (:func:`mcbench.analysis.ranking.extras_table`): each method outside the
    ranking pool scored in a pool that adds it alone to ``pool`` (the candidates and the noisy
    input), as CSV, Markdown and LaTeX (label ``tab:extras-<metric>``). No extras: a table with a
    sentence saying so."""
    from mcbench.analysis.metrics import METRIC_LABELS
    from mcbench.analysis.ranking import extras_table, format_latex, format_markdown

    metrics = read_table(metrics_csv, columns=("scene", "spp", "candidate", "metric", "value"))
    table = extras_table(metrics, metric, pool=list(pool), extras=list(extras))
    write_csv(csv_path, table.reset_index(), float_format="%.4f")
    entries = len(pool) + 1
    scoring = (f"Each method outside the ranking pool is scored in a pool that adds it alone to the "
               f"{len(pool)} entries of the main table (candidates and the noisy input): in each test case the "
               f"{entries} entries get scores from {entries} (lowest error) to 1, and the row is the method's own "
               f"score (Zheng et al. 2021 Sec. 5.3.3), so the main table never depends on these methods.")
    body = format_markdown(table, labels) if len(table) else "No method outside the ranking pool in this config."
    write_text(md_path, f"# Extra methods by {METRIC_LABELS.get(metric, metric)}\n\n{scoring}\n\n{body}\n")
    if tex_path is not None:
        text = (format_latex(table, labels, caption=f"Extra methods by {METRIC_LABELS.get(metric, metric)}. "
                             + scoring + " Best per column in bold.", label=f"tab:extras-{metric}")
                if len(table) else "% No method outside the ranking pool in this config.\n")
        write_text(tex_path, text)
    return table


def render_noisy(scene: str, spp: int, output_path: str, *, resolution=None, variant: str = "auto",
                 seed: int = 0, threads: int | None = None) -> None:
    """Render the full image and the two half buffers of one (scene, spp) to a multi-layer EXR."""
    from mcbench.render.renderer import render_buffers
    from scenes import load_scene

    layers, metadata = render_buffers(load_scene(scene), spp, resolution=_resolution(resolution),
                                      variant=variant, seed=seed, threads=threads)
    check_finite(f"{output_path} (render of scene '{scene}' at {spp} spp)", layers)
    write_layers(output_path, layers, metadata=metadata)


def render_reference_chunk(scene: str, spp: int, chunk: int, output_path: str, *, resolution=None,
                           variant: str = "auto", seed: int = 0, threads: int | None = None) -> None:
    """Render one chunk of a reference with its own seeds (never overlapping the noisy renders)."""
    from mcbench.render.renderer import render_reference_chunk as render_chunk
    from scenes import load_scene

    layers, metadata = render_chunk(load_scene(scene), spp, chunk, resolution=_resolution(resolution),
                                    variant=variant, seed=seed, threads=threads)
    check_finite(f"{output_path} (reference chunk {chunk} of scene '{scene}')", layers)
    write_layers(output_path, layers, metadata=metadata)


def merge_reference(chunk_paths: list[str], output_path: str) -> None:
    """Merge reference chunks (spp-weighted, float64) into the reference with its own variance."""
    from mcbench.render.renderer import merge_reference_chunks

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


def _benchmark_cpu_hours(paths: list[str]) -> float:
    """Sum of Snakemake benchmark ``cpu_time`` (seconds, last repeat) over TSVs, in hours."""
    total = 0.0
    for path in paths:
        frame = read_table(path, sep="\t", columns=["cpu_time"])
        if not len(frame):
            raise BenchError(f"{path}: benchmark record without a cpu_time row")
        total += float(frame["cpu_time"].iloc[-1])
    return total / 3600.0


def _records_of(scene: str, paths: list[str]) -> list[str]:
    """The benchmark records of ``scene`` among ``paths`` (file names ``<scene>_spp<N>.tsv`` /
    ``<scene>_chunk<K>.tsv``)."""
    return [p for p in paths if re.fullmatch(rf"{re.escape(scene)}_(spp|chunk)\d+\.tsv", Path(p).name)]


def write_scene_table(metrics_csv: str, reference_paths: dict[str, str], reference_spp: dict[str, int],
                      csv_path: str, md_path: str, *, noisy_records: list[str],
                      reference_records: list[str], tex_path: str | None = None) -> pd.DataFrame:
    """Scene table with reference noise floors (issue: trustworthy references) and render costs.

    Render costs come from the Snakemake ``benchmark:`` records of the noisy render jobs
    (``noisy_records``) and reference chunk jobs (``reference_records``), inputs of the rule.
    """
    import pandas as pd

    from mcbench.analysis.reports import reference_relmse_floor, scene_latex, scene_markdown, scene_rows
    from scenes import load_scene

    metrics = read_table(metrics_csv, columns=["scene", "spp", "candidate", "metric", "value"])
    floors, info, costs = {}, {}, {}
    for scene, path in reference_paths.items():
        layers = read_layers(path, ["color", "variance"])
        check_finite(path, layers)
        floors[scene] = reference_relmse_floor(layers["color"], layers["variance"])
        module = load_scene(scene)
        meta = read_metadata(path)
        info[scene] = {"category": module.CATEGORY, "description": module.DESCRIPTION,
                       "resolution": meta.get("resolution", ""), "reference_spp": reference_spp[scene]}
        costs[scene] = {
            "render_cpu_hours": _benchmark_cpu_hours(_records_of(scene, noisy_records)),
            "reference_cpu_hours": _benchmark_cpu_hours(_records_of(scene, reference_records)),
        }
    table = scene_rows(metrics, floors, info, costs)
    write_csv(csv_path, table, float_format="%.6g")
    write_text(md_path, scene_markdown(table))
    if tex_path is not None:
        write_text(tex_path, scene_latex(table, caption="Test scenes: reference spp and the reference's estimated "
                                                        "relMSE against the noisy and best candidate's relMSE at the "
                                                        "highest spp; a floor ratio below 10 (bold) means the "
                                                        "reference is too noisy to rank there."))
    return table


def write_gallery(reference_paths: dict[str, str], png_path: str) -> None:
    """Gallery of all references with their names (Fig. 3 of Zheng et al.)."""
    from mcbench.analysis.reports import gallery_figure

    references = {}
    for scene, path in reference_paths.items():
        layers = read_layers(path, ["color"])
        check_finite(path, layers)
        references[scene] = layers["color"]
    gallery_figure(references, png_path)


def write_training_example(seed: int, output_paths: list[str], *, spp_levels, target_spp: int, resolution,
                           crop_size: int, variant: str = "auto", threads: int | None = None) -> None:
    """Render training scene ``seed`` (mcbench.training_data) and write one EXR per crop."""
    from mcbench.training_data import training_example
    from mcbench.render.variants import set_threads

    set_threads(threads)
    crops = training_example(seed, list(spp_levels), target_spp, _resolution(resolution), crop_size,
                             len(output_paths), variant=variant)
    for path, (layers, metadata) in zip(output_paths, crops):
        check_finite(f"{path} (training scene {seed})", layers)
        write_layers(path, layers, metadata=metadata)


SURE_SUFFIX = "+sure"   # a training base "<name>+sure" also writes SURE's divergence term


def write_correlated_training_inputs(base: str, crop_paths: list[str], output_paths: list[str], *,
                                     threads: int | None = None) -> None:
    """Run base denoiser ``base`` (``methods/<base>.py``; a learned one with its committed weights)
    on every noisy level of each training crop and write its results, the correlated inputs of
    the deep combiner's training (Back et al. 2020 Sec. 5): per level ``N`` the layers
    ``correlated_spp<N>``, ``correlated_a_spp<N>``, ``correlated_b_spp<N>`` and, for a base that
    writes sub-buffer results (:data:`mcbench.io.buffers.SUB_OUTPUTS`, e.g. kpcn),
    ``correlated<half>_sub<j>_spp<N>``.

    ``base`` ``<name>+sure`` (progressive denoising's training data): also the divergence term of
    SURE of each image, ``divergence<half>_spp<N>`` (Eq. 2 with K = 1, ε = 1e-4, the base's
    single-image function re-run on the perturbed colour; ``methods.progressive.divergence_map``,
    seeded by crop, level and image)."""
    from mcbench.io.buffers import SUB_OUTPUTS
    from mcbench.nn.data import HALF_OF, crop_render_layers
    from mcbench.render.variants import set_threads
    from methods import load_method

    if threads:
        set_threads(threads)
        try:
            import torch
            torch.set_num_threads(int(threads))
        except ImportError:
            pass
    name, with_sure = (base[:-len(SURE_SUFFIX)], True) if base.endswith(SURE_SUFFIX) else (base, False)
    module = load_method(name, kind="denoiser", config_key=f"base '{base}'")
    if with_sure:
        from methods.progressive import IMAGE_INDEX, divergence_map, single_image_denoiser
        denoise_image = single_image_denoiser(name)
    if len(crop_paths) != len(output_paths):
        raise BenchError(f"{len(crop_paths)} crops for {len(output_paths)} outputs of base '{base}'")
    for crop_path, output_path in zip(crop_paths, output_paths):
        meta = read_metadata(crop_path)
        if "spp_levels" not in meta:
            raise BenchError(f"{crop_path}: not a training crop (no spp_levels metadata)")
        levels = [int(v) for v in meta["spp_levels"].split(",")]
        layers = read_layers(crop_path)
        check_finite(crop_path, layers)
        out, start = {}, time.perf_counter()
        for level in levels:
            buffers = RenderBuffers(layers=crop_render_layers(layers, level), spp=level,
                                    source=f"{crop_path} at {level} spp")
            result = module.denoise(buffers)
            for half, which in HALF_OF.items():
                out[f"correlated{half}_spp{level}"] = result.image(which)
                extras = result.extras or {}
                for j, sub_name in enumerate(SUB_OUTPUTS[which]):
                    if sub_name in extras:
                        out[f"correlated{half}_sub{j}_spp{level}"] = extras[sub_name]
                if with_sure:
                    seed = [int(meta.get("seed", 0)), int(meta.get("crop", 0)), level, IMAGE_INDEX[which]]
                    out[f"divergence{half}_spp{level}"] = divergence_map(
                        denoise_image, buffers.image(which), seed=seed).astype(np.float32)
        check_finite(f"{output_path} (results of '{base}' on {crop_path})", out)
        write_layers(output_path, out, metadata={"base": base, "seed": meta.get("seed", ""),
                                                 "crop": meta.get("crop", ""), "spp_levels": meta["spp_levels"],
                                                 "seconds": f"{time.perf_counter() - start:.3f}"})


def learned_method(name: str):
    """``methods/<name>.py`` checked to be a learned method (NETWORK, TRAINING, build_network):
    a denoiser, or a combiner trained on base results (``CORRELATED_BASES``, ``TRAINING_KEYS``)."""
    from mcbench.io.weights import check_learned_method
    from methods import load_method

    module = check_learned_method(load_method(name, config_key=f"network '{name}'"))
    if module.KIND == "combiner":
        missing = [a for a in ("CORRELATED_BASES", "TRAINING_KEYS") if not hasattr(module, a)]
        if missing:
            raise BenchError(f"methods/{name}.py: a learned combiner needs {', '.join(missing)}")
    return module


def training_data(name: str, crop_files: list[str], correlated_files: dict[str, list[str]] | None = None):
    """The training data of learned method ``name``: its crops (a denoiser: the crop paths
    themselves) or, for a combiner, :func:`mcbench.nn.data.load_combiner_crops` over the results
    of its ``CORRELATED_BASES`` (``correlated_files``: {base: files, one per crop})."""
    module = learned_method(name)
    if module.KIND != "combiner":
        return list(crop_files)
    from mcbench.nn.data import load_combiner_crops

    correlated_files = correlated_files or {}
    missing = [b for b in module.CORRELATED_BASES if b not in correlated_files]
    if missing:
        raise BenchError(f"{name}: no results of base(s) {missing} for its training")
    return load_combiner_crops(crop_files, {b: correlated_files[b] for b in module.CORRELATED_BASES},
                               module.TRAINING_KEYS)


def train_learned_method(name: str, crop_files: list[str], *args, correlated_files=None, **kwargs):
    """Train ``methods/<name>.py`` (:func:`mcbench.nn.train.train_network`) on
    :func:`training_data` (the step resolves the name, core never imports methods)."""
    from mcbench.nn.train import train_network

    return train_network(learned_method(name), training_data(name, crop_files, correlated_files), *args, **kwargs)


def write_error_curves(metrics_csv: str, metric: str, png_path: str, *, labels: dict[str, str],
                       candidates: list[str] | None = None) -> None:
    """Error against spp of every candidate (or of ``candidates`` only), per scene and averaged, for
    one metric (mcbench.analysis.figures, like Fig. 13 of Zheng et al.); ``labels``: candidate -> legend label."""
    from mcbench.analysis.figures import error_curves, error_curves_figure

    metrics = read_table(metrics_csv, columns=["scene", "spp", "candidate", "metric", "value"])
    if candidates is not None:
        metrics = metrics[metrics["candidate"].isin(candidates)]
    error_curves_figure(error_curves(metrics, metric=metric), png_path, metric=metric, labels=labels)


def write_study(metrics_csv: str, out_dir: str, *, metrics: list[str], labels: dict[str, str],
                candidates: list[str], n_resamples: int, seed: int) -> dict:
    """The 39-candidate study's tables (:func:`mcbench.analysis.study.write_study_tables`) under ``out_dir``:
    beside the paper's Table 3, recommendations, findings, bootstrap intervals, summary."""
    from mcbench.analysis.study import write_study_tables

    return write_study_tables(metrics_csv, out_dir, metrics=list(metrics), labels=labels,
                              candidates=[c for c in candidates if c != NOISY], noisy=NOISY,
                              n_resamples=n_resamples, seed=seed)


def recommended_names(recommendations_csv: str, metric: str) -> list[str]:
    """The ensembles the study recommends under ``metric`` (any scope), in the table's order; the
    relMSE ones when the table has none for ``metric`` (e.g. a metric the study did not rank)."""
    table = read_table(recommendations_csv)
    for chosen in (metric, "relmse"):
        rows = table[(table["metric"] == chosen) & table["ours"].notna()]
        if len(rows):
            return list(dict.fromkeys(str(n) for n in rows["ours"]))
    return []


def write_study_figures_of(metrics_csv: str, timings_csv: str, recommendations_csv: str, scores_ci_csv: str,
                           render_paths: list[str], paths: dict[str, str], *, metric: str, candidates: list[str],
                           labels: dict[str, str], inputs: dict[str, list[str]]) -> None:
    """The study's figures for one metric (:func:`mcbench.analysis.study_figures.write_study_figures`): the
    bases and the ensembles the study recommends (``recommendations_csv``) as curves, the bootstrap
    intervals of ``scores_ci_csv`` on the size figure, render times from the renders' EXRs."""
    from mcbench.analysis.study_figures import curve_candidates, write_study_figures

    recommended = [n for n in recommended_names(recommendations_csv, metric) if n in candidates]
    intervals = read_table(scores_ci_csv)
    ci = (intervals.rename(columns={"avg_ci_low": "ci_low", "avg_ci_high": "ci_high"})[["candidate", "ci_low", "ci_high"]]
          .dropna() if len(intervals) else None)
    write_study_figures(metrics_csv, timings_csv, render_paths, paths, metric=metric,
                        candidates=[c for c in candidates if c != NOISY],
                        curves=[c for c in curve_candidates(recommended) if c in candidates], recommended=recommended,
                        labels=labels, inputs=inputs, noisy=NOISY, ci=ci)


def write_speed_error(metrics_csv: str, timings_csv: str, png_path: str, *, metric: str,
                      labels: dict[str, str], inputs: dict[str, list[str]]) -> None:
    """Each method's mean compute time (timings.csv; a combiner's with the ``inputs`` it takes)
    against its mean ``metric`` error (metrics.csv), as a labelled log-log scatter."""
    from mcbench.analysis.figures import speed_error_figure, speed_error_points

    metrics = read_table(metrics_csv, columns=["scene", "spp", "candidate", "metric", "value"])
    timings = read_table(timings_csv, columns=["scene", "spp", "method", "seconds"])
    points = speed_error_points(metrics, timings, metric=metric, inputs=inputs)
    speed_error_figure(points, png_path, metric=metric, labels=labels)


def write_viewer_case(scene: str, spp: int, reference_path: str, render_path: str,
                      candidate_paths: dict[str, str], case_dir: str, *,
                      weight_inputs: dict[str, list[str]], flip_maps_path: str | None = None) -> dict:
    """One case's images of the static viewer (mcbench.analysis.viewer.write_case_images) in
    ``case_dir``, with its manifest fragment as ``case.json``: the reference, the noisy input
    and every candidate tone-mapped at each exposure, their relMSE and FLIP error maps, and
    the filtered weight maps of each candidate that ``weight_inputs`` gives inputs
    ({candidate: input names}) and whose EXR holds ``weights_filtered_{i}`` for each input.
    ``flip_maps_path``: the case's FLIP maps from :func:`compute_case_metrics` (else evaluated here)."""
    from mcbench.analysis.viewer import CASE_RECORD, write_case_images

    reference = read_layers(reference_path, ["color"])
    check_finite(reference_path, reference)
    reference = reference["color"]
    sources = {NOISY: render_path, **candidate_paths}
    images, weights = {}, {}
    for name, path in sources.items():
        layers = read_layers(path)
        check_finite(path, layers)
        if layers.get("color") is None or layers["color"].shape != reference.shape:
            shape = None if layers.get("color") is None else layers["color"].shape
            raise BenchError(f"{path}: color of shape {shape} does not match reference {reference_path} "
                             f"of shape {reference.shape}")
        images[name] = layers["color"]
        inputs = weight_inputs.get(name, [])
        if inputs and all(f"weights_filtered_{i}" in layers for i in range(len(inputs))):
            weights[name] = [(input_name, layers[f"weights_filtered_{i}"]) for i, input_name in enumerate(inputs)]
    flip_maps = None
    if flip_maps_path is not None:
        flip_maps = read_layers(flip_maps_path, list(sources))
        check_finite(flip_maps_path, flip_maps)
    fragment = write_case_images(case_dir, reference=reference, images=images, weights=weights, flip_maps=flip_maps)
    write_json(Path(case_dir) / CASE_RECORD, {"scene": scene, "spp": int(spp), **fragment})
    return fragment


def write_viewer(metrics_csv: str, case_dirs: list[str], output_dir: str, *, cases: list[tuple[str, int]],
                 candidates: list[str], labels: dict[str, str], metric_names: list[str],
                 static_dir: str) -> dict:
    """The static image viewer in ``output_dir``: the page of ``static_dir`` (index.html,
    viewer.js, viewer.css), every case folder (``case_dirs[i]`` holds ``cases[i]``, written by
    :func:`write_viewer_case`) and ``data.js``, the manifest with each case's numbers from
    ``metrics_csv`` (every entry must have every metric of ``metric_names``). Returns the manifest."""
    from mcbench.analysis.viewer import CASE_RECORD, assemble_viewer, build_manifest, case_numbers, directory_bytes

    if len(case_dirs) != len(cases):
        raise BenchError(f"{output_dir}: {len(case_dirs)} case folders for {len(cases)} cases")
    metrics = read_table(metrics_csv)
    entries = [NOISY] + list(candidates)
    fragments, numbers = {}, {}
    for (scene, spp), case_dir in zip(cases, case_dirs):
        record_path = Path(case_dir) / CASE_RECORD
        try:
            record = read_json(record_path)
        except (OSError, ValueError) as exc:
            raise BenchError(f"{record_path}: cannot read the viewer case record ({exc})") from exc
        if (record.get("scene"), record.get("spp")) != (scene, int(spp)):
            raise BenchError(f"{record_path}: holds case ({record.get('scene')}, {record.get('spp')}), "
                             f"expected ({scene}, {spp})")
        fragments[(scene, int(spp))] = record
        numbers[(scene, int(spp))] = case_numbers(metrics, scene=scene, spp=int(spp), entries=entries,
                                                  metric_names=metric_names, source=metrics_csv)
    scenes = list(dict.fromkeys(scene for scene, _ in cases))
    spps = sorted({int(spp) for _, spp in cases})
    manifest = build_manifest(scenes=scenes, spps=spps, entries=entries, labels=labels,
                              metric_names=metric_names, cases=fragments, numbers=numbers)
    assemble_viewer(output_dir, static_dir=static_dir, case_dirs=dict(zip(fragments, case_dirs)),
                    manifest=manifest)
    print(f"viewer: {len(cases)} cases, {directory_bytes(output_dir) / 1e6:.2f} MB in {output_dir}", flush=True)
    return manifest


if __name__ == "__main__":
    # python -m mcbench.pipeline.steps evaluate <name>  (or train <name>): mcbench.nn.train's command line
    # with the methods registry, e.g. to re-evaluate committed weights on the validation crops.
    import sys

    from mcbench.nn.train import main

    sys.exit(main(load_method=learned_method, load_data=training_data))


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
    table = read_table(metrics_csv, columns=("scene", "spp", "candidate", "metric", "value"))
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

