"""One job per test case: its methods, its entries' evaluations, and what they have already made.

A study's work on a case (a scene at one spp) is one job, :func:`run_case` (rule ``run_case``,
``workflow/rules/methods.smk``): the case's methods in dependency order, then each entry (the
noisy input and every candidate) evaluated against the reference into its metric values and its
viewer images, then the case's metrics table, viewer folder and record. The rule is the same
whatever exists under ``results/``; the job itself decides, item by item, what is already made:

* a method's output (``outputs/<scene>/spp<N>/<method>.exr`` and its timing record ``.json``) is
  kept when both record its *key* (:func:`method_key`): the SHA-256 of its module, parameters,
  its inputs' keys, its weights' SHA-256 and the render's content checksum. An edit of one
  method's parameters changes its key and those of the combiners that read it, nothing else.
* an entry's metric values (``metrics/<scene>/spp<N>/values/<entry>.json``) are kept per metric
  when the image's identity, the reference's content checksum and the metric code's digest are
  those they were computed from. A method's image is identified by its method key
  (``key:<key>``: the same output whether or not it is on disk, and whenever it is made again),
  the noisy input by the render's content checksum (:func:`mcbench.pipeline.evaluation.read_metric_values`): an added metric
  is the only one computed.
* an entry's viewer images (``viewer_entries/<scene>/spp<N>/<entry>/``) are kept when their record
  names the same image, reference, weight inputs and error maps (:func:`viewer_key`).
* which outputs stay on disk (the case's ``keep_outputs``, config ``keep_outputs``): with ``read``
  only those another method reads (:func:`kept_methods`: the bases, and a combiner another
  combiner reads). Any other output is evaluated and removed; its timing record stays, and so
  do its metric values and viewer images while its key does (an edit that stops a combiner
  reading it, or starts one reading it, changes nothing of its evaluation). It is made again
  only when its entry needs an evaluation it lacks (an added metric, a changed error map), a
  method comes to read it, or its key changes; an output made again with its recorded key keeps
  its first timing record. With ``all`` every output stays. A kept output is written
  Zstandard-compressed (lossless, :data:`KEPT_OUTPUT_COMPRESSION`), one the case removes
  uncompressed (it is read once, by its evaluation).

Snakemake reruns a case's job when its plan changes (the rule's params: the case's methods and
their settings, the entries, the metrics), when its render, reference or a learned method's
weights are newer than its outputs, or when an output is missing; the job then makes only what
is out of date, so a method added to a finished study costs that method's work and the case's
assembly. The case record (``cases/<scene>/spp<N>.json``) says what the job made and what it
kept, and lists the timing records of the case's methods (rule ``gather_timings`` reads them)
and the wall and CPU seconds of the job's phases (``seconds``: making methods' outputs, evaluating
the entries, assembling; ``benchmarks/dag_overhead.py`` counts the evaluation as compute).

A content checksum is the ``mcbench.crc32`` header attribute every EXR of the harness carries
(:mod:`mcbench.io.exr`; read from the header, without decoding pixels), or the file's SHA-256
for an EXR written elsewhere.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

from mcbench import METRICS_COLUMNS, BenchError
from mcbench.io.exr import content_checksum
from mcbench.io.tables import read_json, write_csv, write_json

__all__ = ["CASE_RECORD_VERSION", "KEPT_OUTPUT_COMPRESSION", "method_key", "viewer_key", "kept_methods", "run_case", "ensure_case_outputs",
           "case_timing_paths", "gather_case_timings"]

CASE_RECORD_VERSION = 1

#: The compression of the method outputs a case keeps (:func:`kept_methods`): lossless Zstandard,
#: 0.79 of a denoised image's uncompressed bytes, read in 1.6x the time (ZIP: 0.97 and 2.7x;
#: ``benchmarks/exr_compression.py``, docs/measurements.md). A removed output is read once, by its
#: evaluation, and is written uncompressed.
KEPT_OUTPUT_COMPRESSION = "zstd"


def _digest(value) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()


def method_key(*, module: str, params: dict, input_keys: list[str], weights_sha256: str, render: str) -> str:
    """The key of one method's output in one case: SHA-256 of its module, parameters, the keys of
    its inputs (in order), its weights' SHA-256 ("" for a method without weights) and the
    render's content checksum (:func:`mcbench.io.exr.content_checksum`)."""
    return _digest({"module": module, "params": params, "inputs": list(input_keys),
                    "weights_sha256": weights_sha256, "render": render})


def viewer_key(*, image: str, reference: str, weight_inputs: list[str], maps: list[str]) -> str:
    """The key of an entry's viewer images: its image's and the reference's content checksums, the
    names of the inputs whose weight maps it draws and of the metrics whose error maps it draws
    (with their code digests, :func:`mcbench.pipeline.evaluation.metric_code_digest`)."""
    return _digest({"image": image, "reference": reference, "weight_inputs": list(weight_inputs), "maps": list(maps)})


def _stored_method_key(exr: str, timing: str) -> str | None:
    """The key both files of a method's output record, or None (either missing, unreadable, or
    the two disagree: a run killed between them)."""
    from mcbench.io.exr import read_metadata

    if not (Path(exr).exists() and Path(timing).exists()):
        return None
    try:
        from_timing = read_json(timing).get("key")
        from_exr = read_metadata(exr).get("key")
    except (OSError, ValueError, BenchError):
        return None
    return from_timing if from_timing is not None and from_timing == from_exr else None


def _stored_viewer_key(folder: str) -> str | None:
    from mcbench.pipeline.evaluation import ENTRY_RECORD

    path = Path(folder) / ENTRY_RECORD
    if not path.exists():
        return None
    try:
        return read_json(path).get("key")
    except (OSError, ValueError, BenchError):
        return None


def kept_methods(methods: list[dict], keep: str) -> set[str]:
    """The names of the ``methods`` (a case job's, each with ``name`` and ``inputs``) whose outputs
    the case keeps on disk: every one with ``keep`` ``"all"``, with ``"read"`` those that another
    method takes as an input."""
    if keep not in ("read", "all"):
        raise BenchError(f"keep_outputs is {keep!r}; expected 'read' or 'all'")
    if keep == "all":
        return {method["name"] for method in methods}
    return {name for method in methods for name in method["inputs"]}


def _method_keys(case: dict, render: str) -> dict[str, str]:
    """Each method's key (:func:`method_key`), in the case's dependency order."""
    from mcbench.io.weights import file_sha256
    from mcbench.pipeline.study_plan import weights_digest

    keys: dict[str, str] = {}
    for method in case["methods"]:
        unknown = [name for name in method["inputs"] if name not in keys]
        if unknown:
            raise BenchError(f"method '{method['name']}' of case ({case['scene']}, {case['spp']}) reads {unknown}, "
                             "which the case does not make before it (the plan's dependency order is broken)")
        read = method.get("weights_read", [method["weights"]] if method.get("weights") else [])
        weights = weights_digest(read, {path: file_sha256(path) for path in read})
        keys[method["name"]] = method_key(module=method["module"], params=method["params"],
                                          input_keys=[keys[name] for name in method["inputs"]],
                                          weights_sha256=weights, render=render)
    return keys


def _recorded_key(timing: str) -> str | None:
    """The key a method's timing record holds, or None (missing or unreadable)."""
    try:
        return read_json(timing).get("key") if Path(timing).exists() else None
    except (OSError, ValueError, BenchError):
        return None


def _run_stale(case: dict, keys: dict[str, str], names: list[str], kept: set[str], *, threads: int) -> None:
    """Run the case's methods ``names`` (in the case's dependency order) into their files: those
    the case keeps (``kept``, :func:`kept_methods`) compressed with :data:`KEPT_OUTPUT_COMPRESSION`,
    the others uncompressed."""
    from mcbench.pipeline.method_runs import run_methods

    by_name = {method["name"]: method for method in case["methods"]}
    chosen = [m for m in case["methods"] if m["name"] in set(names)]
    if chosen:
        run_methods([{"name": m["name"], "module": m["module"], "params": m["params"], "key": keys[m["name"]],
                      "weights": m.get("weights"), "input_paths": [by_name[i]["exr"] for i in m["inputs"]],
                      "exr": m["exr"], "timing": m["timing"],
                      "compression": KEPT_OUTPUT_COMPRESSION if m["name"] in kept else "none"}
                     for m in chosen], case["render"], scene=case["scene"], spp=int(case["spp"]), threads=threads)


def _remake_outputs(case: dict, keys: dict[str, str], names: list[str], kept: set[str], *,
                    threads: int) -> None:
    """Make again the outputs of ``names`` whose timing records hold their current keys (outputs a
    case removed), keeping those records as they are: the timing measured when the output was
    first made stays the one the tables read."""
    by_name = {method["name"]: method for method in case["methods"]}
    records = {name: read_json(by_name[name]["timing"]) for name in names
               if _recorded_key(by_name[name]["timing"]) == keys[name]}
    _run_stale(case, keys, names, kept, threads=threads)
    for name, record in records.items():
        write_json(by_name[name]["timing"], record)


def run_case(case: dict, *, threads: int = 1) -> dict:
    """Make what one case lacks and assemble it; return the case record.

    ``case`` (:meth:`mcbench.pipeline.study_plan.StudyPlan.case_job`, JSON-able):
    ``scene``, ``spp``, ``render``, ``reference`` (paths), ``metrics`` (metric names),
    ``methods``: ``[{name, module, params, inputs, weights, weights_read, exr, timing}]`` in
    dependency order (``inputs``: method names; ``weights``: the weights file a learned method is
    handed, else None; ``weights_read``: the weights files it reads, which its key's digest covers),
    ``entries``: ``[{entry, image, values, viewer, weight_inputs}]`` (the noisy input first),
    ``outputs``: ``{metrics, viewer, record}`` (the case's metrics CSV, viewer folder, record),
    ``keep_outputs``: ``read`` (default) or ``all`` (module docstring).
    """
    scene, spp = case["scene"], int(case["spp"])
    clock = _PhaseClock()
    keys = _method_keys(case, content_checksum(case["render"]))
    kept = kept_methods(case["methods"], case.get("keep_outputs", "read"))
    current = {m["name"] for m in case["methods"] if _stored_method_key(m["exr"], m["timing"]) == keys[m["name"]]}
    stale = [m["name"] for m in case["methods"] if m["name"] in kept and m["name"] not in current]
    recorded = {m["name"] for m in case["methods"] if _recorded_key(m["timing"]) == keys[m["name"]]}
    stale += [m["name"] for m in case["methods"] if m["name"] not in kept and m["name"] not in recorded]
    _remake_outputs(case, keys, stale, kept, threads=threads)
    identities = _entry_identities(case, keys)
    removed = {name for name in keys if name not in kept and name not in current and name not in stale}
    wanted = _entries_to_evaluate(case, identities, removed) if removed else []
    _remake_outputs(case, keys, wanted, kept, threads=threads)     # removed outputs an evaluation needs again
    clock.lap("methods")
    evaluated = _evaluate_case(case, identities)
    clock.lap("evaluation")
    for method in case["methods"]:
        if method["name"] not in kept:
            Path(method["exr"]).unlink(missing_ok=True)
    _assemble_case(case, evaluated)
    clock.lap("assembly")
    made = [m["name"] for m in case["methods"] if m["name"] in set(stale) | set(wanted)]
    record = {"version": CASE_RECORD_VERSION, "scene": scene, "spp": spp,
              "made": {"methods": made,
                       "metrics": [e for e, done in evaluated.items() if done["metrics"]],
                       "viewer": [e for e, done in evaluated.items() if done["viewer"]]},
              "methods": {m["name"]: {"key": keys[m["name"]], "exr": m["exr"], "timing": m["timing"],
                                      "kept": m["name"] in kept}
                          for m in case["methods"]},
              "seconds": clock.laps}
    write_json(case["outputs"]["record"], record)
    return record


class _PhaseClock:
    """Wall and CPU seconds of a job's phases, in ``laps``: ``{phase: {"wall", "cpu"}}`` (CPU:
    the process's, all its threads)."""

    def __init__(self):
        self._wall, self._cpu = time.perf_counter(), time.process_time()
        self.laps: dict[str, dict[str, float]] = {}

    def lap(self, phase: str) -> None:
        wall, cpu = time.perf_counter(), time.process_time()
        self.laps[phase] = {"wall": wall - self._wall, "cpu": cpu - self._cpu}
        self._wall, self._cpu = wall, cpu


def ensure_case_outputs(case: dict, names: list[str], *, threads: int = 1) -> list[str]:
    """Make the outputs of the case's methods ``names`` that are not on disk with their current
    key (and the inputs they read), and keep them; return the names made. For readers of
    outputs a case removed (``keep_outputs: read``), e.g. the export of a case for programs
    outside the harness. Evaluations and the timing records of outputs made again are not touched."""
    keys = _method_keys(case, content_checksum(case["render"]))
    by_name = {method["name"]: method for method in case["methods"]}
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise BenchError(f"case ({case['scene']}, {case['spp']}) has no method(s) {unknown}")
    needed, todo = set(), list(names)
    while todo:
        name = todo.pop()
        if name not in needed:
            needed.add(name)
            todo.extend(by_name[name]["inputs"])
    made = [m["name"] for m in case["methods"]
            if m["name"] in needed and _stored_method_key(m["exr"], m["timing"]) != keys[m["name"]]]
    _remake_outputs(case, keys, made, kept_methods(case["methods"], case.get("keep_outputs", "read")),
                    threads=threads)
    return made


def _entry_identities(case: dict, keys: dict[str, str]) -> dict[str, str]:
    """What identifies each entry's image in its evaluations' keys: ``key:<method key>`` for a
    method's output (whether the case keeps it or not: a method made again with its key computes
    its image again from the same code, parameters, inputs, weights and render, while its file's
    checksum also covers the seconds it recorded), the content
    checksum of the image otherwise (the render)."""
    return {item["entry"]: (f"key:{keys[item['entry']]}" if item["entry"] in keys
                            else content_checksum(item["image"]))
            for item in case["entries"]}


def _maps(case: dict) -> list[str]:
    from mcbench.pipeline.evaluation import metric_code_digest
    from mcbench.pipeline.registry import load_metrics

    return [f"{name}:{metric_code_digest(name)}" for name, spec in load_metrics(case["metrics"]).items()
            if spec.error_map is not None]


def _entries_to_evaluate(case: dict, identities: dict[str, str], names: set[str]) -> list[str]:
    """The entries among ``names`` whose metric values or viewer images are not all kept for their image."""
    from mcbench.pipeline.evaluation import metric_code_digest, read_metric_values

    reference, maps = content_checksum(case["reference"]), _maps(case)
    codes = {name: metric_code_digest(name) for name in case["metrics"]}
    wanted = []
    for item in (item for item in case["entries"] if item["entry"] in names):
        image = identities[item["entry"]]
        key = viewer_key(image=image, reference=reference, weight_inputs=item.get("weight_inputs") or [], maps=maps)
        known = read_metric_values(item["values"], {"image": image, "reference": reference}, codes)
        if _stored_viewer_key(item["viewer"]) != key or any(metric not in known for metric in case["metrics"]):
            wanted.append(item["entry"])
    return wanted


def _evaluate_case(case: dict, identities: dict[str, str]) -> dict[str, dict]:
    """Each entry's metric values and viewer images, made where not kept; per entry, which it
    made (``{"metrics": [names computed], "viewer": bool}``) and its metric values
    (``"values"``, in the order of the case's metrics). ``identities``: :func:`_entry_identities`."""
    from mcbench.pipeline.evaluation import evaluate_entry_values

    scene, spp = case["scene"], int(case["spp"])
    reference, maps = content_checksum(case["reference"]), _maps(case)
    done = {}
    for item in case["entries"]:
        image = identities[item["entry"]]
        key = viewer_key(image=image, reference=reference, weight_inputs=item.get("weight_inputs") or [], maps=maps)
        make_viewer = _stored_viewer_key(item["viewer"]) != key
        values, computed = evaluate_entry_values(
            scene, spp, item["entry"], item["image"], case["reference"], list(case["metrics"]),
            values_path=item["values"], viewer_dir=item["viewer"] if make_viewer else None,
            weight_inputs=item.get("weight_inputs") or (), viewer_key=key,
            checksums={"image": image, "reference": reference})
        done[item["entry"]] = {"metrics": computed, "viewer": make_viewer, "values": values}
    return done


def _assemble_case(case: dict, evaluated: dict[str, dict]) -> None:
    """The case's metrics CSV (rows scene, spp, entry, metric, value: the entries in the
    case's order, each with its metrics in the config's order) and its viewer folder
    (:func:`mcbench.pipeline.viewer.assemble_viewer_case`)."""
    import pandas as pd

    from mcbench.pipeline.viewer import assemble_viewer_case

    scene, spp = case["scene"], int(case["spp"])
    rows = [{"scene": scene, "spp": spp, "entry": entry, "metric": metric, "value": value}
            for entry, made in evaluated.items() for metric, value in made["values"].items()]
    write_csv(case["outputs"]["metrics"], pd.DataFrame(rows, columns=list(METRICS_COLUMNS)))
    assemble_viewer_case({item["entry"]: item["viewer"] for item in case["entries"]}, case["outputs"]["viewer"],
                         scene=scene, spp=spp)


def case_timing_paths(record_path: str | Path) -> list[str]:
    """The timing records of a case's methods, from its case record (:func:`run_case`), each
    checked to be there; ``BenchError`` naming the record otherwise."""
    record = read_json(record_path)
    if record.get("version") != CASE_RECORD_VERSION or not isinstance(record.get("methods"), dict):
        raise BenchError(f"{record_path}: not a case record of version {CASE_RECORD_VERSION}; rerun its case")
    paths = [str(method.get("timing")) for method in record["methods"].values()]
    missing = [path for path in paths if not Path(path).exists()]
    if missing:
        raise BenchError(f"{record_path}: the case's timing record(s) {missing} are missing; rerun its case "
                         f"(snakemake -f {record_path})")
    return paths



def gather_case_timings(record_paths: list[str], output_path: str):
    """``timings.csv`` (:func:`mcbench.pipeline.evaluation.gather_timings`) from the timing records
    the case records list (:func:`case_timing_paths`)."""
    from mcbench.pipeline.evaluation import gather_timings

    return gather_timings([path for record in record_paths for path in case_timing_paths(record)], output_path)
