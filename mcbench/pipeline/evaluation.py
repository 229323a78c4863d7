"""The work behind ``workflow/rules/metrics.smk``: each entry's errors against its reference (the
metrics declared by the plugins of ``metrics/``, resolved through :mod:`mcbench.pipeline.registry`),
and the gathered metrics and timings tables (refused unless every case is whole).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING

from mcbench import METRICS_COLUMNS, NOISY, BenchError
from mcbench.io.buffers import Denoised, RenderBuffers
from mcbench.io.exr import check_finite, check_resolution, read_layers
from mcbench.io.tables import read_json, read_table, write_csv

if TYPE_CHECKING:  # pandas is imported inside the steps that build tables
    import pandas as pd

    from mcbench.contracts.metric import MetricSpec


def read_case_metrics(path: str, *, entries: list[str], metric_names: list[str],
                      case: tuple[str, int] | None = None) -> pd.DataFrame:
    """One per-case metrics CSV, refused (naming the file) unless it is whole: every entry
    and metric once with a finite value, and only the case ``(scene, spp)`` when given."""
    from mcbench.analysis.ranking import check_complete

    frame = read_table(path, columns=METRICS_COLUMNS)
    check_complete(frame, entries=entries, metric_names=metric_names,
                   cases=None if case is None else [case], source=path)
    if case is not None and len(frame.groupby(["scene", "spp"])) != 1:
        raise BenchError(f"{path}: holds more cases than ({case[0]}, {case[1]})")
    return frame


def gather_tables(paths: list[str], output_path: str, *, entries: list[str], metric_names: list[str],
                  cases: list[tuple[str, int]]) -> pd.DataFrame:
    """Concatenate the per-case CSVs (``paths[i]`` holds ``cases[i]``) into one tidy table, after
    checking each is complete (:func:`read_case_metrics`): no table is ranked over lost rows."""
    import pandas as pd

    if len(paths) != len(cases):
        raise BenchError(f"{output_path}: {len(paths)} case files for {len(cases)} cases")
    frames = [read_case_metrics(path, entries=entries, metric_names=metric_names, case=case)
              for path, case in zip(paths, cases)]
    frame = pd.concat(frames, ignore_index=True)
    write_csv(output_path, frame)
    return frame


#: The fields of a method's timing record (written by mcbench.pipeline.method_runs.run_methods) and their types.
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


#: An entry's viewer fragment in its folder (mcbench.pipeline.evaluation.evaluate_entry_values).
ENTRY_RECORD = "entry.json"


def evaluate_entry(scene: str, spp: int, entry: str, image_path: str, reference_path: str,
                   metrics: list[str], *, metrics_path: str | None = None, viewer_dir: str | None = None,
                   weight_inputs: list[str] = (), values_path: str | None = None) -> pd.DataFrame:
    """Errors of one entry of a test case against the reference as a tidy table (columns scene,
    spp, entry, metric, value: one row per metric of ``metrics``, in that order), written to
    ``metrics_path`` when given; the values and images of :func:`evaluate_entry_values`."""
    import pandas as pd

    values, _ = evaluate_entry_values(scene, spp, entry, image_path, reference_path, metrics, viewer_dir=viewer_dir,
                                      weight_inputs=weight_inputs, values_path=values_path)
    frame = pd.DataFrame([{"scene": scene, "spp": int(spp), "entry": entry, "metric": metric, "value": value}
                          for metric, value in values.items()], columns=list(METRICS_COLUMNS))
    if metrics_path is not None:
        write_csv(metrics_path, frame)
    return frame


def evaluate_entry_values(scene: str, spp: int, entry: str, image_path: str, reference_path: str,
                          metrics: list[str], *, viewer_dir: str | None = None, weight_inputs: list[str] = (),
                          values_path: str | None = None, viewer_key: str | None = None,
                          checksums: dict | None = None) -> tuple[dict[str, float], list[str]]:
    """The metric values of one entry of a test case (the noisy input ``NOISY``, read from its
    render, or a candidate's output EXR) against the reference, ``({metric: value}`` in the order
    of ``metrics``, the metrics computed here), and with ``viewer_dir`` the entry's viewer images.
    Each metric is the declaration of ``metrics/<name>.py`` (:func:`mcbench.pipeline.registry.load_metric`),
    computed by :func:`entry_metrics`.

    With ``values_path``: the entry's metric values already computed for these very files (any
    metric list) are kept there (:func:`read_metric_values`), so a metric added to the config is
    the only one computed; a value is reused only when the image's and the reference's content
    checksums (:func:`mcbench.io.exr.content_checksum`, or ``checksums``: ``{"image", "reference"}``
    already read) and its metric's code digest (:func:`metric_code_digest`) are those it was
    computed from. The image and reference are decoded only when something is computed.

    With ``viewer_dir``: the entry's images (:func:`mcbench.analysis.viewer_images.write_entry_images`:
    tone-mapped at each exposure, the error map of each metric that declares one, and for a
    candidate whose inputs ``weight_inputs`` names and whose EXR holds ``weights_filtered_{i}``,
    its weight maps) with their fragment, CRC-32s and ``viewer_key`` as :data:`ENTRY_RECORD`; the
    noisy entry's folder also holds the reference's images. A metric declaring ``value_and_map``
    gives its value and its map from one evaluation. The reference and the image are read through
    :func:`mcbench.io.file_cache.cached_read` (a warm worker reads them once per case).
    """
    from mcbench.io.exr import content_checksum
    from mcbench.pipeline.registry import load_metrics

    specs = load_metrics(metrics)
    known, sources, codes = {}, None, {}
    if values_path is not None:
        checksums = checksums or {"image": content_checksum(image_path), "reference": content_checksum(reference_path)}
        sources = {"image": checksums["image"], "reference": checksums["reference"]}
        codes = {name: metric_code_digest(name) for name in metrics}
        known = read_metric_values(values_path, sources, codes)
    missing = [metric for metric in metrics if metric not in known]
    if not missing and viewer_dir is None:
        return {metric: known[metric] for metric in metrics}, []
    image, weights, reference, reference_variance = _read_entry(
        entry, image_path, reference_path, variance=any(specs[metric].reads_reference_variance for metric in missing),
        weight_inputs=weight_inputs)
    computed, maps = entry_metrics({name: specs[name] for name in metrics}, image, reference, reference_variance,
                                   values=missing, maps=viewer_dir is not None)
    values = {**known, **computed}
    if values_path is not None and computed:
        _keep_metric_values(values_path, sources, {name: codes[name] for name in computed}, computed)
    if viewer_dir is not None:
        _write_entry_viewer(Path(viewer_dir), scene, spp, entry, image, reference, weights, maps, viewer_key)
    return {metric: values[metric] for metric in metrics}, missing


def entry_metrics(specs: dict[str, MetricSpec], image, reference, reference_variance=None, *,
                  values=None, maps: bool = False) -> tuple[dict[str, float], dict[str, tuple]]:
    """One entry's metric values and error maps: ``({name: value}, {name: (ColourScale, (H, W)
    map)})``, both in the order of ``specs`` ({name: declaration}); values of the metrics named in
    ``values`` (default: all), maps (with ``maps``) of every metric that declares one. A metric
    reading the reference's variance gets ``reference_variance``; a metric with ``value_and_map``
    whose value and map are both wanted is evaluated once."""
    wanted = list(specs) if values is None else list(values)
    computed, drawn = {}, {}
    for name, spec in specs.items():
        wants_value, wants_map = name in wanted, maps and spec.error_map is not None
        if wants_value and wants_map and spec.value_and_map is not None:
            values_map, value = spec.value_and_map(image, reference)
        else:
            values_map = spec.error_map(image, reference) if wants_map else None
            if wants_value:
                value = (spec.value(image, reference, reference_variance) if spec.reads_reference_variance
                         else spec.value(image, reference))
        if wants_value:
            computed[name] = float(value)
        if wants_map:
            drawn[name] = (spec.map_scale, values_map)
    return computed, drawn


def _read_entry(entry: str, image_path: str, reference_path: str, *, variance: bool, weight_inputs) -> tuple:
    """``(image, weight maps or None, reference colour, reference variance or None)`` of an entry,
    through :func:`mcbench.io.file_cache.cached_read`; refused, naming the image, when its shape
    is not the reference's."""
    from mcbench.io.file_cache import cached_read

    names = ("color", "variance") if variance else ("color",)

    def read_reference(path):
        layers = read_layers(path, list(names))
        check_finite(path, layers)
        check_resolution(path, layers["color"].shape)
        return layers

    reference_layers = cached_read(reference_path, read_reference, key=("reference", names))
    reference = reference_layers["color"]
    weights = None
    if entry == NOISY:
        image = cached_read(image_path, lambda p: RenderBuffers.load(p, layers=("color",)), key=("render", ("color",))).color
    else:
        denoised = cached_read(image_path, lambda p: Denoised.load(p, extras=True), key=("denoised",))
        image = denoised.full
        extras = denoised.extras or {}
        if weight_inputs and all(f"weights_filtered_{i}" in extras for i in range(len(weight_inputs))):
            weights = [(name, extras[f"weights_filtered_{i}"]) for i, name in enumerate(weight_inputs)]
    if image.shape != reference.shape:
        raise BenchError(f"{image_path}: shape {image.shape} does not match reference "
                         f"{reference_path} of shape {reference.shape}")
    return image, weights, reference, reference_layers.get("variance")


def _write_entry_viewer(folder: Path, scene: str, spp: int, entry: str, image, reference, weights, maps: dict,
                        key: str | None) -> None:
    """An entry's viewer images (``maps``: its error maps, :func:`entry_metrics`) and its record
    (:data:`ENTRY_RECORD`: fragment, CRC-32s, key)."""
    from mcbench.analysis.viewer_images import REFERENCE, case_files, merge_fragments, write_entry_images
    from mcbench.io.checksums import crc32_hex
    from mcbench.io.tables import write_json

    folder.mkdir(parents=True, exist_ok=True)
    fragments = [write_entry_images(folder, REFERENCE, reference, reference=reference)] if entry == NOISY else []
    fragments.append(write_entry_images(folder, entry, image, reference=reference, weights=weights, error_maps=maps))
    fragment = merge_fragments(fragments)
    checksums = {name: crc32_hex((folder / name).read_bytes()) for name in sorted(case_files(fragment))}
    write_json(folder / ENTRY_RECORD, {"scene": scene, "spp": int(spp), "entry": entry, **fragment,
                                       "files_crc32": checksums, **({"key": key} if key else {})})


@functools.lru_cache(maxsize=None)
def metric_code_digest(name: str) -> str:
    """A digest of what computes the values of metric ``name``: the source of its plugin
    ``metrics/<name>.py``, of :mod:`mcbench.analysis.metrics` and :mod:`mcbench.analysis.hdr_flip`
    and the versions of NumPy, SciPy and scikit-image. A kept value computed by other code is not
    reused (:func:`read_metric_values`)."""
    import hashlib
    from importlib import metadata

    import mcbench.analysis.hdr_flip as hdr_flip_module
    import mcbench.analysis.metrics as metrics_module
    from mcbench.pipeline.registry import metric_source

    versions = []
    for package in ("numpy", "scipy", "scikit-image"):
        try:
            versions.append(f"{package}=={metadata.version(package)}")
        except metadata.PackageNotFoundError:
            versions.append(f"{package}==none")
    source = (metric_source(name) + Path(metrics_module.__file__).read_bytes()
              + Path(hdr_flip_module.__file__).read_bytes())
    return hashlib.sha256(source + "\n".join(versions).encode()).hexdigest()[:16]


def _metric_record(path: str | Path, sources: dict) -> tuple[dict, dict]:
    """``(values, code digests)`` of a values record computed from ``sources`` (the image's and
    the reference's content checksums), each {metric: ...}; empty when the record is missing,
    damaged or of other files."""
    import math

    try:
        record = read_json(path)
    except (OSError, ValueError, BenchError):
        return {}, {}
    if not isinstance(record, dict) or any(record.get(key) != value for key, value in sources.items()):
        return {}, {}
    values, codes = record.get("values"), record.get("code")
    if not (isinstance(values, dict) and isinstance(codes, dict)):
        return {}, {}
    values = {str(metric): float(value) for metric, value in values.items()
              if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
              and isinstance(codes.get(metric), str)}
    return values, {metric: codes[metric] for metric in values}


def read_metric_values(path: str | Path, sources: dict, codes: dict[str, str]) -> dict[str, float]:
    """The metric values kept in ``path`` ({metric: value}) of the metrics of ``codes`` ({metric:
    code digest}) computed from ``sources`` (the image's and reference's content checksums) by
    that very code; a missing, damaged or stale record or value is recomputed, never trusted (a
    wrong number would reach the tables)."""
    values, kept_codes = _metric_record(path, sources)
    return {metric: value for metric, value in values.items()
            if metric in codes and kept_codes[metric] == codes[metric]}


def _keep_metric_values(path: str | Path, sources: dict, codes: dict[str, str], values: dict[str, float]) -> None:
    """Add ``values`` (computed by the code of ``codes``) to the values record ``path`` of the files
    ``sources``, keeping the other metrics' values it holds for the same files."""
    from mcbench.io.tables import write_json

    kept, kept_codes = _metric_record(path, sources)
    write_json(path, {**sources, "code": {**kept_codes, **codes}, "values": {**kept, **values}})
