"""The work behind ``workflow/rules/metrics.smk``: each case's errors against its reference, and
the gathered metrics and timings tables (refused unless every case is whole).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import time


from mcbench import NOISY, BenchError
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.exr import check_finite, check_resolution, read_layers, write_layers
from mcbench.io.tables import read_json, read_table, write_csv
from mcbench.analysis.metrics import METRICS, REFERENCE_METRICS

if TYPE_CHECKING:  # pandas is imported inside the steps that build tables
    import pandas as pd


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
    check_resolution(reference_path, reference["color"].shape)
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

    frame = read_table(path, columns=("scene", "spp", "candidate", "metric", "value"))
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


#: The fields of a method's timing record (written by mcbench.pipeline.methods.run_methods) and their types.
TIMING_FIELDS = {"scene": str, "spp": int, "method": str, "module": str, "kind": str, "seconds": float,
                 "width": int, "height": int, "threads": int, "machine": str}


def timing_record(path: str) -> dict:
    """One timing record, refused (naming the file) unless it holds every field of
    :data:`TIMING_FIELDS` with its type: whole numbers for counts (positive sizes and threads),
    a finite, non-negative number of seconds."""
    import math

    record = read_json(path)
    for key, kind in TIMING_FIELDS.items():
        value = record.get(key)
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
        if kind is str:
            good = isinstance(value, str)
        elif kind is int:
            good = numeric and float(value).is_integer() and (value >= 0 if key == "spp" else value > 0)
        else:
            good = numeric and math.isfinite(value) and value >= 0
        if not good:
            raise BenchError(f"{path}: timing record has {key}={value!r}; expected "
                             f"{'a non-negative number' if kind is float else kind.__name__}")
    return record


def gather_timings(paths: list[str], output_path: str) -> pd.DataFrame:
    """Collect the per-job timing JSONs into ``timings.csv`` (one row per method run)."""
    import pandas as pd

    frame = pd.DataFrame([timing_record(p) for p in paths])
    columns = ["scene", "spp", "method", "module", "kind", "seconds", "width", "height", "threads", "machine"]
    frame = frame[[c for c in columns if c in frame.columns]].sort_values(["method", "scene", "spp"])
    write_csv(output_path, frame)
    return frame
