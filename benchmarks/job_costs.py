"""Fit the per-rule job costs of ``mcbench.pipeline.resources`` to finished runs' ``benchmark:`` records.

    python benchmarks/job_costs.py RESULTS [RESULTS ...] [--write workflow/resources/job_costs.yaml]

Each RESULTS is a finished run's ``results/`` folder (runs at two or more resolutions, e.g. the
default config's and the smoke config's, so that the per-pixel terms can be told from the
constant ones). From each it reads:

* every ``benchmark:`` record (``results/benchmarks/**.tsv``: wall ``s``, peak ``max_rss`` MB)
  and the rule that wrote it (by folder: ``render_noisy/``, ``render_reference/`` ->
  ``render_reference_chunk``, ``methods/`` -> ``run_method``, ``batches/*_methods`` ->
  ``run_case_methods`` (``batches/*_combiners`` -> ``run_combiners`` and ``batches/*_learned_denoisers``
  -> ``run_learned_denoisers`` in runs that batched them separately), ``metrics/``
  -> ``case_metrics``, ``viewer/`` -> ``viewer_case``, ``viewer.tsv`` -> ``viewer``, ``oracle/``
  -> ``oracle_study``, ``training/example_*`` -> ``training_example``, ``training/correlated_*``
  -> ``training_correlated``, ``training/train_*`` -> ``train_network``);
* each job's size: pixels from the ``resolution`` metadata of the case's noisy render (training
  and oracle jobs: from their own outputs' metadata where present), spp (renders: the render's
  ``spp``; reference chunks: the merged reference's ``spp / chunks``), and for batch, metric and
  viewer jobs the number of methods of the case (its timing records in ``results/outputs``).

``train_network/<network>``: the seconds of the committed training record
(``methods/weights/<network>.json``) and the peak RSS that ``benchmarks/training_memory.py``
measured (``--training-rss network=MiB``).

Prints per rule the records, the measured maximum wall seconds and RSS, the fitted
:class:`mcbench.pipeline.resources.JobCost` and the request it gives at the measured sizes; with
``--write`` stores the fit (atomically) with a header naming the command and the runs.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import defaultdict
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcbench.io.exr import read_metadata  # noqa: E402
from mcbench.pipeline.resources import estimate_job, fit_job_cost, job_request, write_job_costs  # noqa: E402
from mcbench.io.weights import is_learned_method  # noqa: E402
from methods import load_method  # noqa: E402

_CASE = re.compile(r"^(?P<scene>.+)_spp(?P<spp>\d+)(?:_(?P<rest>.+))?$")
_CHUNK = re.compile(r"^(?P<scene>.+)_chunk(?P<chunk>\d+)$")


def _pixels(resolution: str) -> int:
    width, height = (int(v) for v in str(resolution).split("x"))
    return width * height


def case_sizes(results: Path) -> tuple[dict, dict, dict]:
    """``(pixels per scene, reference chunk spp per scene, method counts per case)``; a case's
    counts are ``{"all", "combiners", "learned_denoisers"}`` from its timing records."""
    pixels, chunk_spp = {}, {}
    for render in (results / "renders").rglob("*.exr"):
        meta = read_metadata(render)
        pixels[meta.get("scene", render.parent.name)] = _pixels(meta["resolution"])
    for reference in (results / "references").glob("*.exr"):
        meta = read_metadata(reference)
        chunk_spp[reference.stem] = int(meta["spp"]) // max(int(meta.get("chunks", 1)), 1)
    learned = {}
    counts = defaultdict(lambda: defaultdict(int))
    for record in (results / "outputs").rglob("*.json"):
        timing = json.loads(record.read_text())
        case = (timing["scene"], int(timing["spp"]))
        counts[case]["all"] += 1
        if timing["kind"] == "combiner":
            counts[case]["combiners"] += 1
        else:
            module = timing["module"]
            if module not in learned:
                learned[module] = is_learned_method(load_method(module))
            counts[case]["learned_denoisers" if learned[module] else "denoisers"] += 1
    return pixels, chunk_spp, counts


def job_rows(results: Path) -> list[dict]:
    """One row per benchmark record: rule, pixels, entries, spp, seconds, rss_mb."""
    benchmarks = results / "benchmarks"
    pixels, chunk_spp, counts = case_sizes(results)
    rows = []
    for record in sorted(benchmarks.rglob("*.tsv")):
        table = pd.read_csv(record, sep="\t")
        if table.empty:
            continue
        seconds, rss = float(table["s"].iloc[-1]), float(table["max_rss"].iloc[-1])
        relative = record.relative_to(benchmarks)
        folder, stem = (relative.parts[0] if len(relative.parts) > 1 else ""), record.stem
        row = None
        case = _CASE.match(stem)
        if folder == "render_noisy" and case:
            row = ("render_noisy", pixels.get(case["scene"]), 1, int(case["spp"]))
        elif folder == "render_reference" and _CHUNK.match(stem):
            scene = _CHUNK.match(stem)["scene"]
            row = ("render_reference_chunk", pixels.get(scene), 1, chunk_spp.get(scene))
        elif folder == "methods" and case:
            timing = results / "outputs" / case["scene"] / f"spp{case['spp']}" / f"{case['rest']}.json"
            module = json.loads(timing.read_text())["module"] if timing.exists() else None
            row = ("run_method", pixels.get(case["scene"]), 1, 0)
            if module:      # the method's own fit besides the rule's
                rows.append({"rule": f"run_method/{module}", "pixels": row[1], "entries": 1, "spp": 0,
                             "seconds": seconds, "rss_mb": rss, "run": str(results)})
        elif folder in ("metrics", "viewer") and case:
            key = (case["scene"], int(case["spp"]))
            rule = {"metrics": "case_metrics", "viewer": "viewer_case"}[folder]
            row = (rule, pixels.get(case["scene"]), counts[key]["all"] + 1, 0)      # + the noisy input
        elif folder == "batches" and case and case["rest"] == "methods":
            key = (case["scene"], int(case["spp"]))
            row = ("run_case_methods", pixels.get(case["scene"]), counts[key]["all"], 0)
        elif folder == "batches" and case and case["rest"] in ("combiners", "learned_denoisers"):
            key = (case["scene"], int(case["spp"]))      # records of runs before run_case_methods
            row = (f"run_{case['rest']}", pixels.get(case["scene"]), counts[key][case["rest"]], 0)
        elif folder == "" and stem == "viewer":
            row = ("viewer", max(pixels.values(), default=0), sum(c["all"] + 1 for c in counts.values()), 0)
        elif folder == "oracle":
            row = ("oracle_study", pixels.get(stem), 1, 0)
        elif folder == "progressive":
            row = ("progressive_curve", pixels.get(stem), 1, 0)
        elif folder == "training":
            rule = ("training_example" if stem.startswith("example_") else
                    "training_correlated" if stem.startswith("correlated_") else
                    "train_network" if stem.startswith("train_") else None)
            row = (rule, 0, 1, 0) if rule else None
        if row is None or row[1] is None or row[3] is None:
            continue
        rule, px, entries, spp = row
        rows.append({"rule": rule, "pixels": px, "entries": entries, "spp": spp,
                     "seconds": seconds, "rss_mb": rss, "run": str(results)})
    return rows


def training_rows(weights: Path, rss: dict[str, float]) -> list[dict]:
    """``train_network/<network>`` rows: the training seconds of each committed training record
    (``methods/weights/<network>.json``) with the peak RSS measured by
    ``benchmarks/training_memory.py`` (``--training-rss network=MiB``; networks without one are
    left out)."""
    rows = []
    for record in sorted(weights.glob("*.json")):
        network = record.stem
        if network not in rss:
            continue
        seconds = float(json.loads(record.read_text()).get("seconds", 0.0))
        rows.append({"rule": f"train_network/{network}", "pixels": 0, "entries": 1, "spp": 0,
                     "seconds": seconds, "rss_mb": rss[network], "run": str(record)})
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("results", nargs="+", type=Path)
    parser.add_argument("--write", type=Path, default=None, help="store the fit here (YAML)")
    parser.add_argument("--weights", type=Path, default=Path(__file__).resolve().parents[1] / "methods" / "weights",
                        help="folder of the committed training records (train_network's seconds)")
    parser.add_argument("--training-rss", nargs="*", default=[], metavar="NETWORK=MIB",
                        help="peak RSS of training each network (benchmarks/training_memory.py)")
    args = parser.parse_args(argv)
    rss = {item.split("=", 1)[0]: float(item.split("=", 1)[1]) for item in args.training_rss}
    rows = [row for results in args.results for row in job_rows(results)] + training_rows(args.weights, rss)
    if not rows:
        raise SystemExit(f"no benchmark records under {', '.join(map(str, args.results))}")
    table = pd.DataFrame(rows)
    costs, typical = {}, {}
    print(f"{'rule':24s} {'jobs':>5s} {'max s':>8s} {'max MB':>8s}   fitted request at the largest measured job")
    for rule, group in table.groupby("rule"):
        cost = fit_job_cost(group.to_dict("records"), min_records=1)
        costs[rule] = cost
        typical[rule] = fit_job_cost(group.to_dict("records"), statistic="mean", min_records=1)
        largest = group.sort_values(["pixels", "entries", "spp"]).iloc[-1]
        estimate = estimate_job(cost, pixels=int(largest.pixels), entries=int(largest.entries), spp=int(largest.spp))
        request = job_request(*estimate)
        print(f"{rule:24s} {len(group):5d} {group.seconds.max():8.1f} {group.rss_mb.max():8.0f}   "
              f"est. {estimate[0]:7.1f} s {estimate[1]:6.0f} MB -> mem_mb {request['mem_mb']}, "
              f"runtime {request['runtime']} min")
    if args.write:
        runs = ", ".join(f"{results} ({len(table[table.run == str(results)])} records)" for results in args.results)
        write_job_costs({"rules": costs, "typical": typical}, args.write, header=(
            "Per-rule job costs (mcbench.pipeline.resources: the model, the margins, the floors).\n"
            "Generated, do not edit: fitted to the benchmark: records of finished runs by\n"
            f"  python benchmarks/job_costs.py {' '.join(map(str, args.results))} --write {args.write}"
            + (f" --training-rss {' '.join(args.training_rss)}" if args.training_rss else "") + "\n"
            f"runs: {runs}\n"
            "rules: fitted to the largest job of each size (requests); typical: to the mean job\n"
            "(CPU-hour estimates). Rules without records (tables, figures, merges) take the floors."))
        print(f"wrote {args.write}")


if __name__ == "__main__":
    main()
